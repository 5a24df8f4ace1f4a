/* A controller outside the firmware; see external_control.h. */
#include "external_control.h"

double lf_sense(const mjModel *m, const mjData *d, lf_sim *s) {
  double height0 = 0.0;
  lf_read_sensors(m, d, s, &height0);
  lf_read_calibrated(&s->fw, s->raw, s->fw.value, s->nsensor);
  s->fw.position = lf_read_line(&s->fw, s->fw.value, s->nsensor);
  s->fw.e = lf_line_angle(s->fw.position, s->nsensor, s->firmware.pitch_m, s->firmware.sensor_distance_m);
  return height0;
}

void lf_sense_record(const mjModel *m, const mjData *d, lf_sim *s, double height0) {
  s->ticks++;
  if (s->fw.tick < LF_TICKS_MAX) s->fw.tick++;
  lf_write_record(m, d, s, s->fw.mode, height0, d->ctrl[s->actuator_left], d->ctrl[s->actuator_right]);
}

int32_t lf_external_step(const mjModel *m, mjData *d, lf_sim *s, double *height0) {
  if (!lf_ready(m, s)) return -1;
  lf_integrate_energy(m, d, s);
  if (!lf_tick_due(d, s)) return 0;
  *height0 = lf_sense(m, d, s);
  return 1;
}

void lf_external_command(const mjModel *m, const mjData *d, lf_sim *s, double u_left_v, double u_right_v,
                         double height0) {
  lf_decide(d, s, u_left_v / s->supply_voltage, u_right_v / s->supply_voltage, lf_read_time_us(s, 1),
            s->timing.compute_us); /* the controller's own compute: the general path's time */
  s->ticks++;
  if (s->fw.tick < LF_TICKS_MAX) s->fw.tick++;
  lf_write_record(m, d, s, s->fw.mode, height0, u_left_v, u_right_v);
}

void lf_external_drive(const mjModel *m, mjData *d, lf_sim *s) {
  if (s->error == LF_OK) lf_drive(m, d, s, d->ctrl + s->actuator_left, d->ctrl + s->actuator_right);
}
