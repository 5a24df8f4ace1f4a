/* A controller FMU for the tests (FMI 2.0 Co-Simulation), built by tests/fmu_builders.py with gcc against fmpy's FMI
 * headers: the firmware's own control law (Eqs. 10-11: lf_control and lf_wheel_duties of
 * twin/csrc/firmware/line_follower.c) on the line angle (or, with CTL_INPUT_POSITION, the readLine position), driving
 * motor voltages (or, with CTL_OUTPUT_SPEEDS, wheel-speed set-points). In the twin's loop it must drive exactly as
 * the firmware does. Value references: 0 the input, 1 and 2 the left and right outputs, 3 k_p (a tunable parameter).
 * controller_config.h (written by the test) gives CTL_GUID and the firmware's parameters; CTL_FAULT (1 hang, 2
 * segfault, 3 exit(0), 4 NaN out) injects one fault into the step at CTL_FAULT_TICK, for the twin's wall around
 * foreign code. */
#define _POSIX_C_SOURCE 200809L /* pause() */
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "controller_config.h"
#include "fmi2Functions.h"
#include "firmware/line_follower.h"

typedef struct {
  lf_state s;
  lf_params p;
  double in, out[2];
} ctl;

static void fill(ctl *c) {
  static const lf_params p = CTL_PARAMS;
  memset(c, 0, sizeof(*c));
  c->p = p;
  lf_reset(&c->s, LF_RUN);
}

fmi2Component fmi2Instantiate(fmi2String name, fmi2Type type, fmi2String guid, fmi2String res,
                              const fmi2CallbackFunctions *f, fmi2Boolean visible, fmi2Boolean logging) {
  ctl *c;
  (void)name, (void)res, (void)f, (void)visible, (void)logging;
  if (type != fmi2CoSimulation || strcmp(guid, CTL_GUID) != 0) return 0;
  c = malloc(sizeof(ctl));
  if (c) fill(c);
  return c;
}
void fmi2FreeInstance(fmi2Component c) { free(c); }
fmi2Status fmi2Reset(fmi2Component c) { fill(c); return fmi2OK; }

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Real v[]) {
  ctl *k = c;
  size_t i;
  for (i = 0; i < n; i++) {
    if (vr[i] == 0) v[i] = k->in;
    else if (vr[i] == 1 || vr[i] == 2) v[i] = k->out[vr[i] - 1];
    else if (vr[i] == 3) v[i] = k->p.k_p;
    else return fmi2Error;
  }
  return fmi2OK;
}
fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Real v[]) {
  ctl *k = c;
  size_t i;
  for (i = 0; i < n; i++) {
    if (vr[i] == 0) k->in = v[i];
    else if (vr[i] == 3) k->p.k_p = v[i];
    else return fmi2Error;
  }
  return fmi2OK;
}

/* One control period: the firmware's RUN branch after readLine (lf_step), on the input. */
fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean no) {
  ctl *k = c;
  lf_real left, right, e;
  (void)t, (void)h, (void)no;
#ifdef CTL_INPUT_POSITION
  e = lf_line_angle((int32_t)k->in, k->p.count, k->p.pitch_m, k->p.sensor_distance_m);
#else
  e = k->in;
#endif
  lf_control(&k->s, &k->p, e);
  lf_wheel_duties(&k->p, k->s.v, k->s.omega, &left, &right);
  if (k->s.tick < LF_TICKS_MAX) k->s.tick++;
#ifdef CTL_FAULT
  if (k->s.tick == CTL_FAULT_TICK) {
    if (CTL_FAULT == 1) for (;;) pause(); /* never returns, and burns no CPU meanwhile */
    if (CTL_FAULT == 2) *(volatile int *)0 = 1;
    if (CTL_FAULT == 3) exit(0);
    if (CTL_FAULT == 4) left = NAN;
  }
#endif
#ifdef CTL_OUTPUT_SPEEDS
  k->out[0] = left * k->p.wheel_speed_max, k->out[1] = right * k->p.wheel_speed_max;
#else
  k->out[0] = left * CTL_SUPPLY_VOLTAGE, k->out[1] = right * CTL_SUPPLY_VOLTAGE;
#endif
  return fmi2OK;
}
