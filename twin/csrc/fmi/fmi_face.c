/* What the FMI 2 and FMI 3 faces share; see fmi_face.h. */
#include "fmi_face.h"

int32_t lf_face_allowed(lf_face *c, int32_t mask, const char *function) {
  if (!c) return 0;
  if (c->state & mask) return 1;
  lf_fmu_log(c->twin, LF_FMU_ERROR, "%s: not allowed in this state of the FMU", function);
  return 0;
}

int32_t lf_face_enter_initialisation(lf_face *c, const char *function) {
  if (!lf_face_allowed(c, LF_INSTANTIATED, function)) return LF_FMU_ERROR;
  c->state = LF_INITIALISATION;
  return LF_FMU_OK;
}

int32_t lf_face_exit_initialisation(lf_face *c, const char *function) {
  if (!lf_face_allowed(c, LF_INITIALISATION, function)) return LF_FMU_ERROR;
  if (lf_fmu_initialise(c->twin, c->start) != LF_FMU_OK) {
    c->state = LF_BROKEN;
    return LF_FMU_ERROR;
  }
  c->state = LF_STEPPING;
  return LF_FMU_OK;
}

int32_t lf_face_terminate(lf_face *c, const char *function) {
  if (!lf_face_allowed(c, LF_STEPPING, function)) return LF_FMU_ERROR;
  c->state = LF_TERMINATED;
  return LF_FMU_OK;
}

int32_t lf_face_reset(lf_face *c) {
  if (!c) return LF_FMU_ERROR;
  lf_fmu_reset(c->twin);
  c->state = LF_INSTANTIATED;
  c->start = 0.0;
  return LF_FMU_OK;
}

int32_t lf_face_do_step(lf_face *c, double t, double h, const char *function) {
  if (!lf_face_allowed(c, LF_STEPPING, function)) return LF_FMU_ERROR;
  return lf_fmu_do_step(c->twin, t, h);
}

int32_t lf_face_get(lf_face *c, uint32_t vr, int32_t type, double *real, int64_t *integer, uint64_t *u64,
                    const char *function) {
  if (!lf_fmu_get(c->twin, vr, type, real, integer, u64)) {
    lf_fmu_log(c->twin, LF_FMU_ERROR, "%s: value reference %u is not a variable of this type", function, vr);
    return 0;
  }
  return 1;
}

int32_t lf_face_set(lf_face *c, uint32_t vr, int32_t type, double real, int64_t integer, uint64_t u64,
                    const char *function) {
  (void)function; /* lf_fmu_set names the variable in its messages */
  return lf_fmu_set(c->twin, vr, type, real, integer, u64, c->state == LF_STEPPING);
}

int32_t lf_face_unsupported(lf_face *c, const char *what) {
  if (c) lf_fmu_log(c->twin, LF_FMU_ERROR, "%s: not supported by this FMU", what);
  return LF_FMU_ERROR;
}
