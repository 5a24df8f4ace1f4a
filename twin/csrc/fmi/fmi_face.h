/* What the FMI 2 and FMI 3 faces share: the calling sequence of a Co-Simulation FMU without event mode, as both
 * standards' state machines give it (instantiated, initialisation mode, step mode, terminated; broken after a failed
 * initialisation), and one variable's value by value reference. States are bits and each call names the states it
 * is allowed in, as the Modelica Reference FMUs check their calls (src/fmi2Functions.c, MASK_*). Each face keeps an lf_face as its instance's first
 * member and adds its own callbacks and types. */
#ifndef LF_FMI_FACE_H
#define LF_FMI_FACE_H

#include "fmu_twin.h"

enum { LF_INSTANTIATED = 1, LF_INITIALISATION = 2, LF_STEPPING = 4, LF_TERMINATED = 8, LF_BROKEN = 16 };
#define LF_ANY_STATE (LF_INSTANTIATED | LF_INITIALISATION | LF_STEPPING | LF_TERMINATED | LF_BROKEN)
#define LF_SETTABLE (LF_INSTANTIATED | LF_INITIALISATION | LF_STEPPING)

typedef struct {
  lf_fmu *twin;
  int32_t state, logging;
  double start; /* the start time given when initialisation was entered (FMI 2: at fmi2SetupExperiment) */
} lf_face;

/* The call is allowed in one of the states of `mask`; else it is logged and 0 returned. */
int32_t lf_face_allowed(lf_face *c, int32_t mask, const char *function);
/* Each returns an lf_fmu_status (FMI 2 and 3 share the values of OK, warning and error). */
int32_t lf_face_enter_initialisation(lf_face *c, const char *function);
int32_t lf_face_exit_initialisation(lf_face *c, const char *function);
int32_t lf_face_terminate(lf_face *c, const char *function);
int32_t lf_face_reset(lf_face *c);
int32_t lf_face_do_step(lf_face *c, double t, double h, const char *function);
/* One variable: get (state any but none) or set (instantiated, initialisation or step mode). */
int32_t lf_face_get(lf_face *c, uint32_t vr, int32_t type, double *real, int64_t *integer, uint64_t *u64,
                    const char *function);
int32_t lf_face_set(lf_face *c, uint32_t vr, int32_t type, double real, int64_t integer, uint64_t u64,
                    const char *function);
/* Log that a function is not supported; returns the error status. */
int32_t lf_face_unsupported(lf_face *c, const char *what);

#endif
