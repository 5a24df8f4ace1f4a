/* A controller FMU of the INTO-CPS kind for the tests (FMI 2.0 Co-Simulation), built by tests/fmu_helpers.py with gcc
 * against fmpy's FMI 2 headers. It has the variables of LFRController_Standalone.fmu in the INTO-CPS example
 * github.com/INTO-CPS-Association/example-line_follower_robot (FMUs/, its modelDescription.xml: value references 0
 * backwardRotate, 1 forwardRotate, 2 forwardSpeed (parameters), 3 lfLeftVal, 4 lfRightVal (8-bit readings, 255
 * white), 5 servoLeftVal, 6 servoRightVal (servo commands in [-1, 1], the right servo mirrored), 7 total_energy_used
 * (an input it does not use)) and the bang-bang law of its Models/LFRController/Controller.vdmrt, written anew: a
 * reading below 150 is the line; both on it: forward at forwardSpeed (servoLeftVal = forwardSpeed, servoRightVal =
 * -forwardSpeed); only lfRightVal on it: servoLeftVal = backwardRotate, servoRightVal = -forwardRotate; only lfLeftVal:
 * the mirror image; neither: keep the last command. Like that FMU, it takes its parameters as 0 unless a master sets
 * them, whatever start values its modelDescription declares (backwardRotate 1, forwardRotate 5, forwardSpeed 4). The
 * law runs once per doStep. */
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"

#define LFR_GUID "{adb6056a-0f07-4642-8ed3-b77b0de5f196}"
#define LINE_BELOW 150.0 /* a reading below this is the (black) line */

enum { BACKWARD_ROTATE, FORWARD_ROTATE, FORWARD_SPEED, LEFT_VAL, RIGHT_VAL, SERVO_LEFT, SERVO_RIGHT, ENERGY, NVAR };

typedef struct {
  double v[NVAR];
} lfr;

fmi2Component fmi2Instantiate(fmi2String name, fmi2Type type, fmi2String guid, fmi2String res,
                              const fmi2CallbackFunctions *f, fmi2Boolean visible, fmi2Boolean logging) {
  (void)name, (void)res, (void)f, (void)visible, (void)logging;
  if (type != fmi2CoSimulation || strcmp(guid, LFR_GUID) != 0) return 0;
  return calloc(1, sizeof(lfr)); /* every variable 0: the declared start values are not applied */
}
void fmi2FreeInstance(fmi2Component c) { free(c); }
fmi2Status fmi2Reset(fmi2Component c) { memset(c, 0, sizeof(lfr)); return fmi2OK; }

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Real v[]) {
  lfr *k = c;
  size_t i;
  for (i = 0; i < n; i++) {
    if (vr[i] >= NVAR) return fmi2Error;
    v[i] = k->v[vr[i]];
  }
  return fmi2OK;
}
fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Real v[]) {
  lfr *k = c;
  size_t i;
  for (i = 0; i < n; i++) {
    if (vr[i] >= NVAR || vr[i] == SERVO_LEFT || vr[i] == SERVO_RIGHT) return fmi2Error;
    k->v[vr[i]] = v[i];
  }
  return fmi2OK;
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean no) {
  lfr *k = c;
  int left_on = k->v[LEFT_VAL] < LINE_BELOW, right_on = k->v[RIGHT_VAL] < LINE_BELOW;
  int left_off = k->v[LEFT_VAL] > LINE_BELOW, right_off = k->v[RIGHT_VAL] > LINE_BELOW;
  (void)t, (void)h, (void)no;
  if (left_on && right_on) {
    k->v[SERVO_LEFT] = k->v[FORWARD_SPEED], k->v[SERVO_RIGHT] = -k->v[FORWARD_SPEED];
  } else if (right_on && left_off) {
    k->v[SERVO_LEFT] = k->v[BACKWARD_ROTATE], k->v[SERVO_RIGHT] = -k->v[FORWARD_ROTATE];
  } else if (right_off && left_on) {
    k->v[SERVO_LEFT] = k->v[FORWARD_ROTATE], k->v[SERVO_RIGHT] = -k->v[BACKWARD_ROTATE];
  }
  return fmi2OK;
}
