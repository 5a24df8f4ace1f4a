/* The mjcb_control callback: sensors -> firmware -> motor voltages, at the firmware's period.
 *
 * Sensors are read only at control ticks: one mj_ray per sensor along its site's z axis (8 rays every 5 ms
 * rather than rangefinder sensors on every physics step, which cost a fifth of the step), then the footprint
 * over the floor texture held in the model, then the response.
 * Everything per simulation lives in d->userdata, which mujoco.batch saves with each simulation's state;
 * so many simulations with different gains and seeds run on a thread pool with no Python per step.
 */
#include <math.h>
#include <string.h>

#include <mujoco/mujoco.h>

#include "twin_core.h"

typedef mjtNum (*lf_ray_fn)(const mjModel *, const mjData *, const mjtNum *, const mjtNum *, const mjtByte *,
                           mjtBool, int, int *, mjtNum *);
static lf_ray_fn ray_fn = 0;

/* Hand over mj_ray; until then the callback leaves every simulation alone. */
void lf_set_ray(void *fn) { ray_fn = (lf_ray_fn)fn; }

int32_t lf_has_ray(void) { return ray_fn != 0; }

/* The warning whose counter the callback raises to stop a decided lap: mujoco.batch.Batch.rollout (mjb_rollout) stops
 * a simulation whose warning counters rise, the one way to end one simulation inside a batch call. MuJoCo raises this
 * one only for a non-finite control, which the firmware never writes (its duties are finite and clamped). */
#define LF_STOP_WARNING mjWARN_BADCTRL

#define SIM_WORDS ((int64_t)((sizeof(lf_sim) + sizeof(mjtNum) - 1) / sizeof(mjtNum)))
#define RECORD_WORDS ((int64_t)(sizeof(lf_record) / sizeof(mjtNum)))

static lf_sim *sim_of(const mjModel *m, mjData *d) {
  if (m->nuserdata < SIM_WORDS) return 0;
  if (d->userdata[0] != LF_MAGIC) return 0;
  return (lf_sim *)d->userdata;
}

/* The model's sizes that a head is written for, in the order of twin.core.native.SIGNATURE. */
static void model_signature(const mjModel *m, int64_t *out) {
  out[0] = m->nbody;
  out[1] = m->nsite;
  out[2] = m->ntex;
  out[3] = m->ntexdata;
  out[4] = m->nu;
  out[5] = m->na;
  out[6] = m->nv;
  out[7] = m->nnumericdata;
}

static int in_range(int64_t id, int64_t n) { return id >= 0 && id < n; }

/* Whether a head fits the model it is stepped with: LF_OK, or the first misfit. Every index the callback uses
 * comes from the head, so each is checked here (a few dozen comparisons, against ~10 us of physics per step). */
int32_t lf_check(const mjModel *m, const lf_sim *s) {
  int64_t signature[LF_SIGNATURE];
  int32_t i;
  if (s->layout_version != LF_LAYOUT_VERSION) return LF_ERR_LAYOUT;
  model_signature(m, signature);
  for (i = 0; i < LF_SIGNATURE; i++)
    if (signature[i] != s->model_signature[i]) return LF_ERR_MODEL;
  if (s->record_capacity < 1 || SIM_WORDS + (int64_t)s->record_capacity * RECORD_WORDS > m->nuserdata)
    return LF_ERR_CAPACITY;
  if (s->nsensor < 1 || s->nsensor > LF_MAX_SENSORS || s->firmware.count != s->nsensor) return LF_ERR_SENSORS;
  for (i = 0; i < s->nsensor; i++)
    if (!in_range(s->sensor_site[i], m->nsite)) return LF_ERR_ID;
  if (!in_range(s->axle_site, m->nsite) || !in_range(s->sensor_body, m->nbody) || !in_range(s->root_body, m->nbody) ||
      !in_range(s->texture_id, m->ntex) || !in_range(s->actuator_left, m->nu) || !in_range(s->actuator_right, m->nu) ||
      !in_range(s->dof_left, m->nv) || !in_range(s->dof_right, m->nv))
    return LF_ERR_ID;
  if (m->nuser_actuator < 1) return LF_ERR_ID; /* lf_motor_power reads R_M from actuator_user (motors.actuator) */
  /* x, y, arc length per vertex, then the track length; two vertices at least, or the segment walk divides by 0 */
  if (s->centre_count < 2 || s->centre_adr < 0 ||
      (int64_t)s->centre_adr + 3 * (int64_t)s->centre_count + 1 > m->nnumericdata)
    return LF_ERR_CENTRE;
  if (s->records_written < 0) return LF_ERR_STATE; /* its slot is records_written % record_capacity */
  return LF_OK;
}

/* A gearmotor's back-EMF K w_m [V] and winding resistance [ohm]: K = -biasprm[2] / gainprm[0], w_m the actuator's
 * velocity (its gear is the gearbox's), R_M from actuator_user[0] (motors.actuator). */
static double back_emf(const mjModel *m, const mjData *d, int32_t a, double *r_ohm) {
  *r_ohm = m->actuator_user[a * m->nuser_actuator];
  return -m->actuator_biasprm[a * mjNBIAS + 2] / m->actuator_gainprm[a * mjNGAIN + 0] * d->actuator_velocity[a];
}

/* Electrical power drawn by a gearmotor (motors.actuator), u i (the driver returns nothing to the battery): i = (v -
 * K w_m) / R_M with v the winding voltage (the lagged control with L_M > 0, else the clamped control). */
double lf_motor_power(const mjModel *m, const mjData *d, int32_t a) {
  double u = d->ctrl[a], v, r, emf;
  if (m->actuator_ctrllimited[a]) u = fmin(fmax(u, m->actuator_ctrlrange[2 * a]), m->actuator_ctrlrange[2 * a + 1]);
  v = m->actuator_actnum[a] > 0 ? d->act[m->actuator_actadr[a]] : u;
  emf = back_emf(m, d, a, &r);
  return fmax(0.0, u * ((v - emf) / r));
}

/* The texture as the sensors read it. */
static lf_texture texture_of(const mjModel *m, const lf_sim *s) {
  lf_texture tex;
  int32_t t = s->texture_id;
  tex.data = m->tex_data + m->tex_adr[t];
  tex.width = m->tex_width[t];
  tex.height = m->tex_height[t];
  tex.nchannel = m->tex_nchannel[t];
  tex.origin_x = s->texture_origin_x;
  tex.origin_y = s->texture_origin_y;
  tex.metres_per_pixel = s->texture_metres_per_pixel;
  return tex;
}

/* Where sensor i's site will be ahead_s seconds from now if its body moves as it moves now [m] (MuJoCo's cvel: the
 * body's angular and linear velocity at its tree's centre of mass, world frame; valid from mj_step1 or the control
 * callback on). */
static void site_ahead(const mjModel *m, const mjData *d, const lf_sim *s, int32_t i, double ahead_s, mjtNum *out) {
  const mjtNum *w = d->cvel + 6 * s->sensor_body, *v = w + 3;
  const mjtNum *com = d->subtree_com + 3 * m->body_rootid[s->sensor_body];
  const mjtNum *p = d->site_xpos + 3 * s->sensor_site[i];
  double rx = p[0] - com[0], ry = p[1] - com[1], rz = p[2] - com[2];
  out[0] = p[0] + (v[0] + w[1] * rz - w[2] * ry) * ahead_s; /* v + w x r */
  out[1] = p[1] + (v[1] + w[2] * rx - w[0] * rz) * ahead_s;
  out[2] = p[2] + (v[2] + w[0] * ry - w[1] * rx) * ahead_s;
}

/* Prefetch the texels each sensor's footprint will read at the next tick, where the sensor will be if it moves as it
 * moves now, with a margin for what the prediction misses. Only a hint to the cache (a prefetch reads nothing and
 * never faults), so no result depends on it; it takes the footprint's waits on main memory off the tick (perf:
 * lf_footprint_reflectance 4.9 % of a lap's samples before, 3.1 % after, plus 0.8 % for the prefetch). */
#define LF_PREFETCH_MARGIN_M 0.001
static void prefetch_next_tick(const mjModel *m, const mjData *d, const lf_sim *s, double height_m, double tan_half) {
  const lf_texture tex = texture_of(m, s);
  const double radius = s->sensor.aperture_m + height_m * tan_half + LF_PREFETCH_MARGIN_M;
  mjtNum next[3];
  int32_t i;
  for (i = 0; i < s->nsensor; i++) {
    site_ahead(m, d, s, i, s->firmware.dt_s, next);
    lf_footprint_prefetch(&tex, next[0], next[1], radius);
  }
}

/* What sensor i sees ahead_s seconds from now, its site moved as it moves now (the light path only, no noise): its
 * reflectance and its height [m] above what the ray hits (0 and 0 when nothing is under it). tan_half:
 * tan(s->sensor.half_angle_rad), the footprint's growth with height (lf_footprint_radius), computed once a tick. The
 * ray keeps its direction: a sensor's axis turns only with the chassis' roll and pitch, which stay near zero. */
static void sense(const mjModel *m, const mjData *d, const lf_sim *s, int32_t i, double ahead_s, double tan_half,
                  double *reflectance, double *height) {
  /* the world only (groups 0-1: the floor, obstacles); the robot's own geoms (2: visual, 3: collision) never block */
  static const mjtByte groups[mjNGROUP] = {1, 1, 0, 0, 0, 0};
  const lf_texture tex = texture_of(m, s);
  const mjtNum *xmat = d->site_xmat + 9 * s->sensor_site[i];
  mjtNum origin[3], dir[3], normal[3];
  int geom = -1;
  if (ahead_s > 0.0) site_ahead(m, d, s, i, ahead_s, origin);
  else memcpy(origin, d->site_xpos + 3 * s->sensor_site[i], sizeof origin);
  dir[0] = xmat[2];
  dir[1] = xmat[5];
  dir[2] = xmat[8];
  *reflectance = 0.0;
  *height = ray_fn(m, d, origin, dir, groups, 1, s->sensor_body, &geom, normal);
  if (*height >= 0.0)
    *reflectance = lf_footprint_reflectance(&tex, origin[0] + *height * dir[0], origin[1] + *height * dir[1],
                                            s->sensor.aperture_m + *height * tan_half); /* lf_footprint_radius */
  else
    *height = 0.0; /* nothing under the sensor: no light comes back */
}

double lf_read_sensor_at(const mjModel *m, const mjData *d, lf_sim *s, int32_t i, double ahead_s, int64_t read) {
  double reflectance, height;
  sense(m, d, s, i, ahead_s, tan(s->sensor.half_angle_rad), &reflectance, &height);
  s->raw[i] = lf_raw_reading(&s->sensor, reflectance, height, lf_reading_noise(s->rng, read, i));
  return height;
}

/* `reads` readings of every sensor at this pose into s->raw, the calibration taking all but the last (Pololu's
   calibrate reads ten times per call); the light path is traced once, each reading draws its own noise. Returns
   sensor 0's height [m]. ahead_s, tan_half: as for sense. */
static double read_sensors(const mjModel *m, const mjData *d, lf_sim *s, int32_t reads, double ahead_s,
                           double tan_half) {
  double reflectance[LF_MAX_SENSORS], height[LF_MAX_SENSORS];
  int32_t i, k;
  for (i = 0; i < s->nsensor; i++) sense(m, d, s, i, ahead_s, tan_half, reflectance + i, height + i);
  for (k = 0; k < reads; k++) {
    if (k > 0) lf_calibrate_update(&s->fw, s->raw, s->nsensor);
    for (i = 0; i < s->nsensor; i++)
      s->raw[i] = lf_raw_reading(&s->sensor, reflectance[i], height[i], lf_reading_noise(s->rng, s->reads, i));
    s->reads++;
  }
  return height[0];
}

void lf_read_sensors(const mjModel *m, const mjData *d, lf_sim *s, double *height0) {
  *height0 = read_sensors(m, d, s, 1, s->timing.release_us * 1e-6, tan(s->sensor.half_angle_rad)); /* at the release */
}

/* Squared distance from (x, y) to segment i (vertex i to i+1, closing the loop); t: where along it [0, 1]. */
static double segment_distance2(const double *c, int32_t n, int64_t i, double x, double y, double *t) {
  const double *a = c + 3 * i, *b = c + 3 * ((i + 1) % n);
  double dx = b[0] - a[0], dy = b[1] - a[1], ex, ey;
  double f = ((x - a[0]) * dx + (y - a[1]) * dy) / (dx * dx + dy * dy);
  f = f < 0.0 ? 0.0 : (f > 1.0 ? 1.0 : f);
  *t = f;
  ex = x - (a[0] + f * dx);
  ey = y - (a[1] + f * dy);
  return ex * ex + ey * ey;
}

void lf_locate(const double *c, int32_t n, double length, double x, double y, int64_t *seg, double *progress,
               double *offset) {
  int64_t i = *seg, j;
  double t, best, tj, dj, len, dx, dy, cross, dist;
  const double *a, *b;
  if (i < 0 || i >= n) { /* global search: once per phase */
    i = 0;
    best = segment_distance2(c, n, 0, x, y, &t);
    for (j = 1; j < n; j++) {
      dj = segment_distance2(c, n, j, x, y, &tj);
      if (dj < best) best = dj, i = j;
    }
  }
  best = segment_distance2(c, n, i, x, y, &t);
  for (;;) { /* forward while nearer */
    j = (i + 1) % n;
    dj = segment_distance2(c, n, j, x, y, &tj);
    if (!(dj < best)) break;
    i = j, best = dj, t = tj;
  }
  for (;;) { /* backward while nearer */
    j = (i + n - 1) % n;
    dj = segment_distance2(c, n, j, x, y, &tj);
    if (!(dj < best)) break;
    i = j, best = dj, t = tj;
  }
  a = c + 3 * i;
  b = c + 3 * ((i + 1) % n);
  dx = b[0] - a[0];
  dy = b[1] - a[1];
  len = (i + 1 < n ? b[2] : length) - a[2];
  dist = hypot(x - (a[0] + t * dx), y - (a[1] + t * dy));
  *progress = fmod(a[2] + t * len, length);
  cross = dx * (y - (a[1] + t * dy)) - dy * (x - (a[0] + t * dx));
  *offset = cross >= 0.0 ? dist : -dist;
  *seg = i;
}

void lf_write_record(const mjModel *m, const mjData *d, lf_sim *s, double mode, double height0, double u_left_v,
                     double u_right_v) {
  lf_record *r = (lf_record *)(s + 1) + (s->records_written % s->record_capacity);
  const mjtNum *q = d->xquat + 4 * s->root_body;
  int32_t i;
  r->time_s = d->time;
  r->x_m = d->site_xpos[3 * s->axle_site];
  r->y_m = d->site_xpos[3 * s->axle_site + 1];
  r->yaw_rad = atan2(2.0 * (q[0] * q[3] + q[1] * q[2]), 1.0 - 2.0 * (q[2] * q[2] + q[3] * q[3]));
  r->e_rad = s->fw.e;
  r->v_mps = s->fw.v;
  r->omega_radps = s->fw.omega;
  r->u_left_v = u_left_v;
  r->u_right_v = u_right_v;
  r->wheel_left_radps = d->qvel[s->dof_left];
  r->wheel_right_radps = d->qvel[s->dof_right];
  r->position = s->fw.position;
  r->line_seen = s->fw.line_seen;
  r->mode = mode;
  r->energy_j = s->energy_j;
  r->height_m = height0;
  lf_locate(m->numeric_data + s->centre_adr, s->centre_count, m->numeric_data[s->centre_adr + 3 * s->centre_count],
            r->x_m, r->y_m, &s->segment, &r->progress_m, &r->offset_m);
  s->offset_abs_sum_m += fabs(r->offset_m);
  s->offset_abs_max_m = fmax(s->offset_abs_max_m, fabs(r->offset_m));
  r->offset_abs_sum_m = s->offset_abs_sum_m;
  r->offset_abs_max_m = s->offset_abs_max_m;
  for (i = 0; i < LF_MAX_SENSORS; i++) {
    r->raw_us[i] = i < s->nsensor ? s->raw[i] : 0.0;
    r->calibrated[i] = i < s->nsensor ? s->fw.value[i] : 0.0;
  }
  s->records_written++;
}

void lf_integrate_energy(const mjModel *m, const mjData *d, lf_sim *s) {
  if (d->time > s->last_time) {
    s->energy_j += (d->time - s->last_time) *
                   (lf_motor_power(m, d, s->actuator_left) + lf_motor_power(m, d, s->actuator_right));
    s->last_time = d->time;
  }
}

int32_t lf_tick_due(const mjData *d, const lf_sim *s) {
  /* a tick is due when time reaches phase start + ticks * dt (half a step of slack for rounding) */
  double next_tick = s->phase_start_time + (double)s->ticks * s->firmware.dt_s;
  return !(d->time < next_tick - 0.5 * s->timestep);
}

int32_t lf_ready(const mjModel *m, lf_sim *s) {
  if (s->error != LF_OK || !ray_fn) return 0;
  s->error = lf_check(m, s);
  return s->error == LF_OK; /* refused: its owner ends the lap; nothing here reads the head's indices again */
}

/* `reads` reads' duration [us]: each lasts until its last line has fallen (its raw reading, which the timeout caps),
 * as the robot's QTR-RC read waits for every line; the calibration's reads before the last are the same light path
 * with their own noise, so they are taken as long as the last. */
double lf_read_time_us(const lf_sim *s, int32_t reads) {
  double longest = 0.0;
  int32_t i;
  for (i = 0; i < s->nsensor; i++) longest = fmax(longest, (double)s->raw[i]);
  return reads * longest;
}

/* The firmware's compute time [us] for the code path its last lf_step took (enum lf_compute_path). */
double lf_compute_time_us(const lf_sim *s) {
  switch (lf_compute_path(&s->fw)) {
    case LF_PATH_CENTRED: return s->timing.compute_centred_us;
    case LF_PATH_LOST: return s->timing.compute_lost_us;
    case LF_PATH_CALIBRATE: return s->timing.compute_calibrate_us;
    default: return s->timing.compute_us;
  }
}

/* A duty as the PWM drives it: the nearest whole count of the period, at most one short of it (the robot's motors.c
 * writes OCR = 256 |duty| + 0.5, up to 255, and the timer drives OCR counts of 256). */
static double pwm_duty(const lf_timing *t, double duty) {
  double counts;
  if (!(t->pwm_counts > 0.0)) return duty;
  counts = floor(fabs(duty) * t->pwm_counts + 0.5);
  counts = fmin(counts, t->pwm_counts - 1.0);
  return copysign(counts / t->pwm_counts, duty);
}

/* The duties a tick decided wait until the robot would write them: the tick, the release, the read, the compute. A
 * duty still waiting when the next tick comes is taken first (the MCU finishes a tick before it starts the next). */
void lf_decide(const mjData *d, lf_sim *s, double duty_left, double duty_right, double read_us, double compute_us) {
  if (s->pending) s->duty_now[0] = s->duty_next[0], s->duty_now[1] = s->duty_next[1];
  s->duty_next[0] = pwm_duty(&s->timing, duty_left);
  s->duty_next[1] = pwm_duty(&s->timing, duty_right);
  s->apply_time_s = d->time + (s->timing.release_us + read_us + compute_us) * 1e-6;
  s->pending = 1;
}

/* The H-bridges' supply over a step whose mean duties are duty[2] (lf_power; reference: twin.model.power). Each motor
 * draws duty i from it, i = (duty v - e) / R, when that is positive (the driver returns nothing, as lf_motor_power).
 * Straight from the battery, v = E - R_s sum(duty i) is linear in v:
 *   v = (E + R_s sum(duty e / R)) / (1 + R_s sum(duty^2 / R)),
 * over the motors that draw (a second pass drops one that would feed the battery). Through the boost regulator the
 * output holds its voltage and the battery gives the power P at a terminal voltage t = E - R_s P / t (no loss in the
 * regulator assumed: not published), t = (E + sqrt(E^2 - 4 R_s P)) / 2; below the regulator's lowest input (or with no
 * real t: more power than the battery can give) it shuts off for the rest of the run. */
double lf_bus_voltage(const mjModel *m, const mjData *d, lf_sim *s, const double duty[2]) {
  const lf_power *p = &s->power;
  int32_t motor[2], draws[2] = {1, 1}, j, pass;
  double e[2], r[2], v = p->battery_v;
  if (s->power_off) return 0.0;
  motor[0] = s->actuator_left, motor[1] = s->actuator_right;
  for (j = 0; j < 2; j++) e[j] = back_emf(m, d, motor[j], &r[j]);
  if (p->regulator_v > 0.0) {
    double watts = 0.0, disc, terminal;
    for (j = 0; j < 2; j++) watts += fmax(0.0, duty[j] * (duty[j] * p->regulator_v - e[j]) / r[j]) * p->regulator_v;
    disc = p->battery_v * p->battery_v - 4.0 * p->source_ohm * watts;
    terminal = disc >= 0.0 ? 0.5 * (p->battery_v + sqrt(disc)) : 0.0;
    s->terminal_min_v = fmin(s->terminal_min_v, terminal);
    if (terminal < p->regulator_min_input_v) {
      s->power_off = 1;
      return 0.0;
    }
    return p->regulator_v;
  }
  for (pass = 0; pass < 2 && p->source_ohm > 0.0; pass++) {
    double num = p->battery_v, den = 1.0;
    int32_t dropped = 0;
    for (j = 0; j < 2; j++)
      if (draws[j]) num += p->source_ohm * duty[j] * e[j] / r[j], den += p->source_ohm * duty[j] * duty[j] / r[j];
    v = num / den;
    for (j = 0; j < 2; j++)
      if (draws[j] && duty[j] * (duty[j] * v - e[j]) < 0.0) draws[j] = 0, dropped = 1;
    if (!dropped) break;
  }
  s->terminal_min_v = fmin(s->terminal_min_v, v);
  return v;
}

/* The motors' voltages over the step beginning now: the duties in force, blended over the step in which new ones take
 * effect (their mean over the step, as a PWM the MCU rewrites mid-step drives it: twin/csrc/pil/avr_motors.c), times
 * the supply over the step (lf_bus_voltage). */
void lf_drive(const mjModel *m, const mjData *d, lf_sim *s, double *u_left_v, double *u_right_v) {
  double duty[2] = {s->duty_now[0], s->duty_now[1]}, bus;
  if (s->pending) {
    double old_share = (s->apply_time_s - d->time) / s->timestep; /* of the step still on duty_now */
    if (old_share < 1.0) {
      old_share = fmax(0.0, old_share);
      duty[0] = old_share * s->duty_now[0] + (1.0 - old_share) * s->duty_next[0];
      duty[1] = old_share * s->duty_now[1] + (1.0 - old_share) * s->duty_next[1];
      s->duty_now[0] = s->duty_next[0], s->duty_now[1] = s->duty_next[1];
      s->pending = 0;
    }
  }
  bus = lf_bus_voltage(m, d, s, duty);
  *u_left_v = duty[0] * bus;
  *u_right_v = duty[1] * bus;
}

void lf_loop(const mjModel *m, mjData *d, lf_sim *s) {
  double height0, mode, tan_half;
  int32_t reads;
  if (!lf_ready(m, s)) return;
  lf_integrate_energy(m, d, s);
  if (lf_tick_due(d, s)) {
    mode = s->fw.mode;
    tan_half = tan(s->sensor.half_angle_rad);
    /* the readings are taken when the lines are released, timing.release after the tick; a calibration call takes
       LF_CAL_READS readings at that pose, and lf_step calibrates with the last of them */
    reads = s->fw.mode == LF_CALIBRATE ? LF_CAL_READS : 1;
    height0 = read_sensors(m, d, s, reads, s->timing.release_us * 1e-6, tan_half);
    lf_step(&s->fw, &s->firmware, s->raw);
    lf_decide(d, s, s->fw.duty_left, s->fw.duty_right, lf_read_time_us(s, reads), lf_compute_time_us(s));
    s->ticks++;
    /* the record keeps the voltages the firmware commands; the motors take them when drive() says */
    lf_write_record(m, d, s, mode, height0, s->fw.duty_left * s->supply_voltage, s->fw.duty_right * s->supply_voltage);
    prefetch_next_tick(m, d, s, height0, tan_half);
    if (s->judge_on && !s->stop_raised) {
      const lf_record *r = (const lf_record *)(s + 1) + (s->records_written - 1) % s->record_capacity;
      if (lf_judge_feed(&s->judge, r) != LF_LAP_RUNNING || r->time_s > s->deadline_s) {
        s->stop_raised = 1; /* decided, or past its deadline: end the rollout after this step (mj_step ignores it) */
        d->warning[LF_STOP_WARNING].number++;
      }
    }
  }
  lf_drive(m, d, s, d->ctrl + s->actuator_left, d->ctrl + s->actuator_right);
}

void lf_control_callback(const mjModel *m, mjData *d) {
  lf_sim *s = sim_of(m, d);
  if (s) lf_loop(m, d, s);
}
