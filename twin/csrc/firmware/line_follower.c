/* Line-follower firmware; see line_follower.h. Python reference: line_sensor.reference, twin.model.control. */
#include "line_follower.h"

#include <math.h>

void lf_reset(lf_state *s, int32_t mode) {
  /* keeps the calibration: the robot is calibrated once, then placed on the start line */
  s->position = 0;
  s->last_position = 0;
  s->line_seen = 0;
  s->mode = mode;
  s->tick = 0;
  s->call_reads = 0; /* a calibration call under way is dropped */
  s->e = 0;
  s->e_prev = 0;
  s->integral = 0;
  s->v = 0;
  s->omega = 0;
  s->duty_left = 0;
  s->duty_right = 0;
}

void lf_calibrate_reset(lf_state *s, uint16_t timeout_us) {
  int32_t i;
  for (i = 0; i < LF_MAX_SENSORS; i++) {
    s->cal_min[i] = timeout_us;
    s->cal_max[i] = 0;
    s->value[i] = 0;
    s->call_min[i] = s->call_max[i] = 0;
  }
  s->call_reads = 0;
}

/* Pololu's calibration rule (libpololu-avr, PololuQTRSensors.cpp, calibrateOnOrOff): a call takes LF_CAL_READS
 * readings; per sensor, the calibrated maximum rises to the call's smallest reading and the calibrated minimum falls
 * to its largest, so one noise spike never widens the range. Each calibration tick is one call: its callers take
 * LF_CAL_READS - 1 readings before lf_step takes the last (the C callback at the tick's pose, the MCU's program one
 * read after another); a call cut short by lf_reset is dropped. */
void lf_calibrate_update(lf_state *s, const uint16_t *raw, int32_t count) {
  int32_t i;
  for (i = 0; i < count; i++) {
    if (s->call_reads == 0 || raw[i] > s->call_max[i]) s->call_max[i] = raw[i];
    if (s->call_reads == 0 || raw[i] < s->call_min[i]) s->call_min[i] = raw[i];
  }
  if (++s->call_reads < LF_CAL_READS) return;
  for (i = 0; i < count; i++) {
    if (s->call_min[i] > s->cal_max[i]) s->cal_max[i] = s->call_min[i];
    if (s->call_max[i] < s->cal_min[i]) s->cal_min[i] = s->call_max[i];
  }
  s->call_reads = 0;
}

/* Eq. 8, as QTRSensors::readCalibrated: (raw - min) * 1000 / (max - min), clipped to 0..1000. */
void lf_read_calibrated(const lf_state *s, const uint16_t *raw, uint16_t *out, int32_t count) {
  int32_t i;
  for (i = 0; i < count; i++) {
    int32_t denominator = (int32_t)s->cal_max[i] - (int32_t)s->cal_min[i];
    int32_t value = 0;
    if (denominator > 0) value = ((int32_t)raw[i] - (int32_t)s->cal_min[i]) * 1000 / denominator;
    if (value < 0) value = 0;
    if (value > 1000) value = 1000;
    out[i] = (uint16_t)value;
  }
}

/* Eq. 9's weighted average, as QTRSensors::readLine (dark line on light ground). */
int32_t lf_read_line(lf_state *s, const uint16_t *calibrated, int32_t count) {
  uint32_t avg = 0, sum = 0;
  int32_t i, on_line = 0;
  for (i = 0; i < count; i++) {
    uint32_t value = calibrated[i];
    if (value > LF_LINE_THRESHOLD) on_line = 1;
    if (value > LF_NOISE_THRESHOLD) {
      avg += value * (uint32_t)(i * 1000);
      sum += value;
    }
  }
  s->line_seen = on_line;
  if (!on_line) /* lost: report the end on the side the line was last seen */
    return s->last_position < (count - 1) * 1000 / 2 ? 0 : (count - 1) * 1000;
  s->last_position = (int32_t)(avg / sum);
  return s->last_position;
}

/* Eq. 9: the line's bearing from the centre of rotation. The paper's /100000 is its 10 mm pitch; here the
 * pitch is a parameter. Sensor 0 is the leftmost, so e > 0 is a line to the left, which a CCW turn follows. */
lf_real lf_line_angle(int32_t position, int32_t count, lf_real pitch_m, lf_real sensor_distance_m) {
  lf_real lateral_m = (lf_real)((count - 1) * 500 - position) * pitch_m / 1000.0;
  return atan2(lateral_m, sensor_distance_m);
}

/* Eqs. 10-11 once per period: v = v_max - K_B |e| (not below 0, ramped up at accel_max),
 * omega = K_P e + K_I int(e dt) + K_D de/dt (rectangle rule, integral clamped, no derivative kick). */
void lf_control(lf_state *s, const lf_params *p, lf_real e) {
  lf_real v_target = p->v_max - p->k_b * fabs(e);
  lf_real v_ramp = s->v + p->accel_max * p->dt_s;
  lf_real derivative = s->tick == 0 ? 0.0 : (e - s->e_prev) / p->dt_s;
  if (v_target < 0) v_target = 0;
  s->integral += e * p->dt_s;
  if (s->integral > p->integral_limit) s->integral = p->integral_limit;
  if (s->integral < -p->integral_limit) s->integral = -p->integral_limit;
  s->e = e;
  s->v = v_target < v_ramp ? v_target : v_ramp;
  s->omega = p->k_p * e + p->k_i * s->integral + p->k_d * derivative;
  s->e_prev = e;
}

static lf_real clip_unit(lf_real x) { return x > 1.0 ? 1.0 : (x < -1.0 ? -1.0 : x); }

/* (v, omega) -> wheel speeds (Eqs. 1-2 inverted) -> PWM duty of the no-load speed. Saturation gives up
 * forward speed before turn rate: both wheels shift together so the faster one sits at full duty. */
void lf_wheel_duties(const lf_params *p, lf_real v, lf_real omega, lf_real *left, lf_real *right) {
  lf_real scale = 1.0 / (p->wheel_radius_m * p->wheel_speed_max);
  lf_real l = (v - omega * p->half_track_m) * scale;
  lf_real r = (v + omega * p->half_track_m) * scale;
  lf_real hi = l > r ? l : r;
  lf_real lo;
  if (hi > 1.0) {
    l -= hi - 1.0;
    r -= hi - 1.0;
  }
  lo = l < r ? l : r;
  if (lo < -1.0) {
    l += -1.0 - lo;
    r += -1.0 - lo;
  }
  *left = clip_unit(l);
  *right = clip_unit(r);
}

static uint32_t quarter_ticks(const lf_params *p) {
  lf_real omega = p->cal_duty * p->wheel_speed_max * p->wheel_radius_m / p->half_track_m;
  lf_real ticks = p->cal_sweep_rad / (omega * p->dt_s);
  /* saturate before converting: a float beyond uint32 (or NaN) has no defined conversion */
  if (!(ticks < (lf_real)LF_QUARTER_TICKS_MAX)) return LF_QUARTER_TICKS_MAX;
  return ticks < 1.0 ? 1u : (uint32_t)(ticks + 0.5);
}

/* Length of the calibration turn: each sweep is a quarter right, a half left, a quarter right. Saturates at
 * LF_TICKS_MAX rather than wrapping to a short turn. */
uint32_t lf_calibration_ticks(const lf_params *p) {
  uint32_t cycle = 4u * quarter_ticks(p); /* at most 2^31 */
  uint32_t sweeps;
  if (p->cal_sweeps <= 0) return 0;
  sweeps = (uint32_t)p->cal_sweeps;
  return sweeps > LF_TICKS_MAX / cycle ? LF_TICKS_MAX : cycle * sweeps;
}

/* Turn direction at a calibration tick: +1 left (CCW), -1 right, 0 when done (Pololu's example pattern). */
int32_t lf_calibration_direction(const lf_params *p, uint32_t tick) {
  uint32_t q = quarter_ticks(p), phase;
  if (tick >= lf_calibration_ticks(p)) return 0;
  phase = (tick % (4u * q)) / q;
  return (phase == 1 || phase == 2) ? 1 : -1;
}

void lf_step(lf_state *s, const lf_params *p, const uint16_t *raw) {
  lf_read_calibrated(s, raw, s->value, p->count);
  if (s->mode == LF_CALIBRATE) {
    int32_t direction = lf_calibration_direction(p, s->tick);
    lf_calibrate_update(s, raw, p->count);
    s->duty_left = -direction * p->cal_duty;
    s->duty_right = direction * p->cal_duty;
    if (direction == 0) s->mode = LF_IDLE;
  } else if (s->mode == LF_RUN) {
    s->position = lf_read_line(s, s->value, p->count);
    lf_control(s, p, lf_line_angle(s->position, p->count, p->pitch_m, p->sensor_distance_m));
    lf_wheel_duties(p, s->v, s->omega, &s->duty_left, &s->duty_right);
  } else {
    s->duty_left = 0;
    s->duty_right = 0;
  }
  if (s->tick < LF_TICKS_MAX) s->tick++;
}
