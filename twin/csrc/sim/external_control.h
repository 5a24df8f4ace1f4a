/* A controller outside the firmware: a controller FMU in the twin's loop (twin.fmi), or the master of the plant FMU.
 *
 * The twin keeps the robot's sensor side (the sensor physics, then the firmware's own Eq. 8 calibration, readLine
 * and Eq. 9 line angle, as QTRSensors gives them to any program on the robot); the controller decides the motor
 * voltages. At a tick: lf_sense (or lf_external_step, which knows when a tick is due), then the caller writes d->ctrl,
 * then lf_sense_record. A controller in the twin's loop stands in for the firmware on the same robot: its commands
 * reach the motors with the robot's timing (lf_external_command at a tick, then lf_external_drive every step).
 */
#ifndef LF_EXTERNAL_CONTROL_H
#define LF_EXTERNAL_CONTROL_H

#include <mujoco/mujoco.h>

#include "twin_core.h"

/* Read every sensor now (drawing its noise) and run the firmware's sensor side into s->fw: value (calibrated),
 * position and line_seen (readLine), e (Eq. 9). Returns sensor 0's height above the floor [m]. */
double lf_sense(const mjModel *m, const mjData *d, lf_sim *s);
/* Count the tick and write its trace record (after the caller has written the motor voltages into d->ctrl). */
void lf_sense_record(const mjModel *m, const mjData *d, lf_sim *s, double height0);

/* Once per physics step, after mj_step1 (where the control callback would run): the motors' energy, and at a control
 * tick (every firmware.dt_s) lf_sense. Returns 1 at a tick (the caller then writes d->ctrl and calls
 * lf_sense_record), 0 between ticks, -1 if the head does not fit the model (s->error says why). */
int32_t lf_external_step(const mjModel *m, mjData *d, lf_sim *s, double *height0);
/* At a tick: the controller's voltages [V] (duty x supply) taken as the firmware's duties are (lf_decide: they reach the
 * motors when the robot's timing says), and the tick's record with them as the commanded voltages. */
void lf_external_command(const mjModel *m, const mjData *d, lf_sim *s, double u_left_v, double u_right_v,
                         double height0);
/* Every step, after lf_external_step: the motors' voltages over the step into d->ctrl (lf_drive). */
void lf_external_drive(const mjModel *m, mjData *d, lf_sim *s);

#endif
