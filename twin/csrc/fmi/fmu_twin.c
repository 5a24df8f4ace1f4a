/* The twin as a Co-Simulation FMU: one instance's life; see fmu_twin.h.
 *
 * The phases are twin.core.closed_loop's, in C: the calibration turn from the start keyframe with a fresh head
 * (setup), (calibration ticks + 2) control periods long; then the start keyframe again with a fresh head that keeps
 * the turn's calibration and noise generator, in the run phase (start_phase). A calibration that leaves a sensor
 * less than LapLimits.min_calibration_range_us of range, or a turn longer than calibration_timeout_s, fails the lap
 * as twin.core.calibration says. The lap then runs from the start time of the co-simulation.
 */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../sim/external_control.h"
#include "fmu_twin.h"

void lf_set_ray(void *fn); /* mujoco_glue.c */

#define SEED_SALT 0x5DEECE66Dull /* twin.core.closed_loop.SEED_SALT */

void lf_fmu_log(lf_fmu *f, int32_t status, const char *fmt, ...) {
  char text[640], *c;
  va_list ap;
  if (!f->log) return;
  va_start(ap, fmt);
  vsnprintf(text, sizeof(text), fmt, ap);
  va_end(ap);
  for (c = text; *c; c++) /* FMI loggers read the message as a format */
    if (*c == '%') *c = '#';
  f->log(f->log_env, status, status >= LF_FMU_ERROR ? "logStatusError" : status == LF_FMU_WARNING ? "logStatusWarning"
                                                                                                      : "logEvents",
         text);
}

static char *join(const char *dir, const char *name) {
  size_t n = strlen(dir);
  char *path = malloc(n + strlen(name) + 2);
  if (!path) return 0;
  strcpy(path, dir);
  if (n && dir[n - 1] != '/') strcat(path, "/");
  strcat(path, name);
  return path;
}

static int32_t read_head(const char *path, lf_sim *head) {
  FILE *file = fopen(path, "rb");
  int32_t ok;
  if (!file) return 0;
  ok = fread(head, sizeof(*head), 1, file) == 1 && fgetc(file) == EOF;
  fclose(file);
  return ok;
}

lf_fmu *lf_fmu_new(const lf_fmu_config *config, const char *resource_dir, lf_fmu_logger log, void *log_env) {
  lf_fmu *f = calloc(1, sizeof(lf_fmu));
  char *model = join(resource_dir, "twin.mjb"), *head = join(resource_dir, "head.bin");
  if (!f || !model || !head) goto fail;
  f->config = config, f->log = log, f->log_env = log_env;
  f->param = calloc((size_t)config->nparam + 1, sizeof(double));
  f->m0 = f->param ? mj_loadModel(model, 0) : 0;
  if (!f->m0) {
    lf_fmu_log(f, LF_FMU_FATAL, "cannot load the model %s", model);
    goto fail;
  }
  if (!read_head(head, &f->head0) || f->head0.layout_version != LF_LAYOUT_VERSION || lf_check(f->m0, &f->head0)) {
    lf_fmu_log(f, LF_FMU_FATAL, "%s is not a head for this library and model: export the FMU again", head);
    goto fail;
  }
  f->m = mj_copyModel(0, f->m0);
  f->d = f->m ? mj_makeData(f->m) : 0;
  if (!f->d) goto fail;
  lf_set_ray((void *)mj_ray);
  lf_fmu_reset(f);
  free(model), free(head);
  return f;
fail:
  free(model), free(head);
  lf_fmu_free(f);
  return 0;
}

void lf_fmu_free(lf_fmu *f) {
  if (!f) return;
  if (f->d) mj_deleteData(f->d);
  if (f->m) mj_deleteModel(f->m);
  if (f->m0) mj_deleteModel(f->m0);
  free(f->param);
  free(f);
}

static lf_sim *head_of(lf_fmu *f) { return (lf_sim *)f->d->userdata; }

void lf_fmu_reset(lf_fmu *f) {
  const lf_fmu_config *c = f->config;
  int32_t k;
  mj_copyModel(f->m, f->m0);
  for (k = 0; k < c->nparam; k++) f->param[k] = c->params[k].start;
  f->seed = c->seed;
  f->voltage[0] = f->voltage[1] = 0.0;
  f->limits = c->limits;
  f->frozen = 0, f->steps = 0, f->consumed = 0, f->t0 = f->time = 0.0;
  memset(&f->out, 0, sizeof(f->out));
  mj_resetDataKeyframe(f->m, f->d, c->start_key); /* an unmarked head: nothing steps it yet */
  lf_judge_start(&f->judge, 0.0, &f->limits);
}

/* closed_loop.setup then start_phase: the start line, a fresh head with the parameters, at the start of a phase. */
static lf_sim *new_phase(lf_fmu *f, int32_t mode) {
  lf_sim *s = head_of(f);
  mj_resetDataKeyframe(f->m, f->d, f->config->start_key);
  memset(f->d->userdata, 0, sizeof(mjtNum) * (size_t)f->m->nuserdata);
  *s = f->head;
  s->magic = 0.0; /* stepped by its owner: a control callback of the host leaves it alone */
  s->error = LF_OK;
  s->seed = f->seed * SEED_SALT + 1;
  s->rng = lf_noise_base(s->seed, mode);
  s->reads = 0;
  lf_calibrate_reset(&s->fw, (uint16_t)(int32_t)s->sensor.timeout_us);
  lf_reset(&s->fw, mode);
  s->ticks = s->records_written = 0;
  s->segment = -1;
  s->phase_start_time = s->last_time = s->energy_j = s->offset_abs_sum_m = s->offset_abs_max_m = 0.0;
  f->consumed = 0;
  return s;
}

/* One mj_step with the loop where MuJoCo calls the control callback (after mj_step1's position and velocity
 * stages): the same arithmetic as mj_step with lf_control_callback. Returns 0 if the physics diverged (MuJoCo then
 * resets the data, head included) or the state is not finite. */
static int32_t physics_step(lf_fmu *f, lf_sim *s, int32_t firmware) {
  mjData *d = f->d;
  int32_t i;
  mj_step1(f->m, d);
  if (firmware) lf_loop(f->m, d, s);
  else if (lf_ready(f->m, s)) lf_integrate_energy(f->m, d, s);
  mj_step2(f->m, d);
  if (s->layout_version != LF_LAYOUT_VERSION) return 0;
  for (i = 0; i < f->m->nq; i++)
    if (!isfinite(d->qpos[i])) return 0;
  return 1;
}

static void stop(lf_fmu *f, int32_t status, const char *why) {
  lf_judge_fail(&f->judge, status, f->d->time, f->out.energy_j);
  f->frozen = 1;
  lf_fmu_log(f, LF_FMU_WARNING, "the lap ended at %g s of simulated time: %s; the physics stops here", f->d->time, why);
}

/* Feed the judge the trace records written since the last call. */
static void feed(lf_fmu *f, lf_sim *s) {
  for (; f->consumed < s->records_written; f->consumed++) {
    f->out = *((const lf_record *)(s + 1) + f->consumed % s->record_capacity);
    lf_judge_feed(&f->judge, &f->out);
  }
}

/* Step n physics steps, judging the records of the run phase; 0 if the lap's physics stopped. */
static int32_t run(lf_fmu *f, lf_sim *s, int64_t n, int32_t firmware, int32_t judged) {
  int64_t k;
  for (k = 0; k < n && !f->frozen; k++) {
    if (!physics_step(f, s, firmware)) stop(f, LF_LAP_DIVERGED, "the physics produced a non-finite state");
    else if (s->error != LF_OK) stop(f, LF_LAP_REFUSED, "the C loop refused the head (export the FMU again)");
    else if (judged) feed(f, s);
  }
  return !f->frozen;
}

/* The calibration turn, then the start line with its calibration: closed_loop._calibrate and _start_laps. */
static int32_t calibrate(lf_fmu *f) {
  const lf_fmu_config *c = f->config;
  uint32_t ticks = lf_calibration_ticks(&f->head.firmware);
  uint16_t lo[LF_MAX_SENSORS], hi[LF_MAX_SENSORS];
  double span = 1e300;
  int32_t i, n = f->head.nsensor;
  lf_sim *s;
  if ((double)ticks * f->head.firmware.dt_s > c->calibration_timeout_s) {
    new_phase(f, LF_RUN);
    lf_judge_fail(&f->judge, LF_LAP_CALIBRATION, 0.0, 0.0);
    lf_fmu_log(f, LF_FMU_WARNING, "the calibration turn would take %g s (limit %g s): the lap fails",
               (double)ticks * f->head.firmware.dt_s, c->calibration_timeout_s);
    return 1;
  }
  s = new_phase(f, LF_CALIBRATE);
  if (!run(f, s, ((int64_t)ticks + 2) * f->steps_per_tick, 1, 0)) return 1;
  if (s->fw.mode != LF_IDLE) {
    lf_fmu_log(f, LF_FMU_ERROR, "the calibration turn did not finish");
    return 0;
  }
  memcpy(lo, s->fw.cal_min, sizeof(lo));
  memcpy(hi, s->fw.cal_max, sizeof(hi));
  s = new_phase(f, LF_RUN);
  memcpy(s->fw.cal_min, lo, sizeof(lo));
  memcpy(s->fw.cal_max, hi, sizeof(hi));
  for (i = 0; i < n; i++) span = fmin(span, (double)hi[i] - (double)lo[i]);
  if (span < c->min_calibration_range_us) {
    lf_judge_fail(&f->judge, LF_LAP_CALIBRATION, 0.0, 0.0);
    lf_fmu_log(f, LF_FMU_WARNING, "a sensor spans only %g us after the calibration turn (needs %g): the lap fails",
               span, c->min_calibration_range_us);
  }
  return 1;
}

static double yaw_of(const mjtNum *q) { /* as lf_write_record */
  return atan2(2.0 * (q[0] * q[3] + q[1] * q[2]), 1.0 - 2.0 * (q[2] * q[2] + q[3] * q[3]));
}

/* The outputs at a communication point. The plant reads its sensors now, writes the record and judges it; the
 * closed loop shows the state now, with the sensor side of the firmware's last tick. */
static void snapshot(lf_fmu *f) {
  lf_sim *s = head_of(f);
  const mjModel *m = f->m;
  mjData *d = f->d;
  int64_t segment;
  if (f->frozen) return;
  mj_kinematics(m, d);
  if (f->config->kind == LF_FMU_PLANT) {
    if (!lf_ready(m, s)) {
      stop(f, LF_LAP_REFUSED, "the C loop refused the head (export the FMU again)");
      return;
    }
    lf_sense_record(m, d, s, lf_sense(m, d, s));
    feed(f, s);
    return;
  }
  f->out.time_s = d->time;
  f->out.x_m = d->site_xpos[3 * s->axle_site];
  f->out.y_m = d->site_xpos[3 * s->axle_site + 1];
  f->out.yaw_rad = yaw_of(d->xquat + 4 * s->root_body);
  f->out.u_left_v = d->ctrl[s->actuator_left];
  f->out.u_right_v = d->ctrl[s->actuator_right];
  f->out.wheel_left_radps = d->qvel[s->dof_left];
  f->out.wheel_right_radps = d->qvel[s->dof_right];
  f->out.energy_j = s->energy_j;
  segment = s->segment; /* a copy: the loop's own walk is not disturbed */
  lf_locate(m->numeric_data + s->centre_adr, s->centre_count, m->numeric_data[s->centre_adr + 3 * s->centre_count],
            f->out.x_m, f->out.y_m, &segment, &f->out.progress_m, &f->out.offset_m);
}

int32_t lf_fmu_initialise(lf_fmu *f, double start_time) {
  const lf_sim *h = &f->head0;
  f->head = f->head0;
  f->limits = f->config->limits;
  mj_copyModel(f->m, f->m0);
  if (!lf_fmu_apply(f, &f->head)) return LF_FMU_ERROR;
  lf_judge_start(&f->judge, f->m->numeric_data[h->centre_adr + 3 * h->centre_count], &f->limits);
  f->t0 = f->time = start_time;
  f->steps = 0, f->frozen = 0;
  memset(&f->out, 0, sizeof(f->out));
  if (!calibrate(f)) return LF_FMU_ERROR;
  f->frozen = 0; /* a turn that diverged left the judge failed; the run phase starts on the start line anyway */
  if (f->judge.status == LF_LAP_DIVERGED) new_phase(f, LF_RUN);
  snapshot(f);
  return LF_FMU_OK;
}

int32_t lf_fmu_do_step(lf_fmu *f, double t, double h) {
  lf_sim *s = head_of(f);
  int32_t plant = f->config->kind == LF_FMU_PLANT;
  int64_t target;
  if (!(h > 0.0) || !isfinite(h)) {
    lf_fmu_log(f, LF_FMU_ERROR, "doStep: the step size must be a finite number > 0, got %g", h);
    return LF_FMU_ERROR;
  }
  if (fabs(t - f->time) > 1e-9 * fmax(1.0, fabs(t))) {
    lf_fmu_log(f, LF_FMU_ERROR, "doStep: the step starts at %.17g s, but the FMU is at %.17g s", t, f->time);
    return LF_FMU_ERROR;
  }
  /* the physics keeps its own grid: every step that ends by the communication point (to a millionth of a step) */
  target = (int64_t)floor((t + h - f->t0) / f->m->opt.timestep + 1e-6);
  if (plant && !f->frozen) {
    f->d->ctrl[s->actuator_left] = f->voltage[0];
    f->d->ctrl[s->actuator_right] = f->voltage[1];
  }
  if (target > f->steps) run(f, s, target - f->steps, !plant, 1);
  f->steps = target;
  f->time = t + h;
  snapshot(f);
  return LF_FMU_OK;
}

static double lap_value(const lf_fmu *f, int32_t which) {
  const lf_judge *j = &f->judge;
  int32_t done = j->status != LF_LAP_RUNNING;
  switch (which) {
    case LF_LAP_STATUS_VALUE: return j->status;
    case LF_LAP_COMPLETED_VALUE: return j->status == LF_LAP_COMPLETED;
    case LF_LAP_TIME_VALUE: return j->status == LF_LAP_COMPLETED ? j->end_t : 0.0;
    case LF_LAP_DISTANCE_VALUE: return done ? fmax(0.0, j->end_u) : (j->started ? j->u_last : 0.0);
    case LF_LAP_XTE_MAX_VALUE: return j->abs_max;
    case LF_LAP_XTE_MEAN_VALUE: return j->records ? j->abs_sum / (double)j->records : 0.0;
    case LF_LAP_ENERGY_VALUE: return done ? j->end_energy : 0.0;
    default: return 0.0;
  }
}

int32_t lf_fmu_get(lf_fmu *f, uint32_t vr, int32_t type, double *real, int64_t *integer, uint64_t *u64) {
  const lf_fmu_var *v;
  double x = 0.0;
  if (vr >= (uint32_t)f->config->nvar || f->config->vars[vr].type != type) return 0;
  v = &f->config->vars[vr];
  switch (v->source) {
    case LF_SRC_TIME: x = f->time; break;
    case LF_SRC_INPUT: x = f->voltage[v->index]; break;
    case LF_SRC_RECORD: x = ((const double *)&f->out)[v->index]; break;
    case LF_SRC_LAP: x = lap_value(f, v->index); break;
    case LF_SRC_PARAM: x = f->param[v->index]; break;
    case LF_SRC_SEED:
      if (u64) *u64 = f->seed;
      if (integer) *integer = (int64_t)f->seed;
      return 1;
    default: return 0;
  }
  if (real) *real = x;
  if (integer) *integer = (int64_t)x;
  if (u64) *u64 = (uint64_t)x;
  return 1;
}

/* running: between steps (only tunable parameters and inputs may change then). */
int32_t lf_fmu_set(lf_fmu *f, uint32_t vr, int32_t type, double real, int64_t integer, uint64_t u64, int32_t running) {
  const lf_fmu_var *v;
  const lf_fmu_param *p;
  double x = type == LF_REAL ? real : (double)integer;
  if (vr >= (uint32_t)f->config->nvar || f->config->vars[vr].type != type) {
    lf_fmu_log(f, LF_FMU_ERROR, "value reference %u: no variable of this type", vr);
    return 0;
  }
  v = &f->config->vars[vr];
  if (v->source == LF_SRC_INPUT) {
    if (!isfinite(real)) {
      lf_fmu_log(f, LF_FMU_ERROR, "%s: must be a finite number, got %g", v->name, real);
      return 0;
    }
    f->voltage[v->index] = real;
    return 1;
  }
  if (v->source == LF_SRC_SEED && !running) {
    if (type != LF_UINT64 && integer < 0) {
      lf_fmu_log(f, LF_FMU_ERROR, "seed: must be >= 0, got %lld", (long long)integer);
      return 0;
    }
    f->seed = type == LF_UINT64 ? u64 : (uint64_t)integer;
    return 1;
  }
  if (v->source != LF_SRC_PARAM) {
    lf_fmu_log(f, LF_FMU_ERROR, "%s: cannot be set %s", v->name, v->source == LF_SRC_SEED ? "after initialisation" : "");
    return 0;
  }
  p = &f->config->params[v->index];
  if (!lf_fmu_check_param(p, x)) {
    lf_fmu_log(f, LF_FMU_ERROR, "%s: %g is outside %s%g, %g]%s", p->address, x, p->lo_open ? "(" : "[", p->lo, p->hi,
               p->what == LF_P_CONTROL_CAL_SWEEPS ? " or not whole" : "");
    return 0;
  }
  if (running && !p->tunable) {
    lf_fmu_log(f, LF_FMU_ERROR, "%s: a fixed parameter, set before initialisation only", p->address);
    return 0;
  }
  f->param[v->index] = x;
  if (running) {
    lf_fmu_apply_gain(&f->head, p->what, x);
    lf_fmu_apply_gain(head_of(f), p->what, x);
  }
  return 1;
}
