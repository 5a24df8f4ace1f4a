/* The FMU's parameters, by model-space address: each one written where the twin writes it.
 *
 * Model fields as twin.core.digital_twin.apply_fields and motors.actuator.write_fields write them (friction of the
 * tyres and the floor, timestep, impratio, the gearmotor fields of both motors and their wheels' dry friction, the voltage limit); the sensor model,
 * the firmware's parameters and the battery voltage into the head as twin.core.closed_loop.setup writes them. The
 * values are checked here against the ranges of the model space (the exporter copies them into the table), since
 * an FMU's caller is not the twin's Python.
 */
#include <math.h>

#include "fmu_twin.h"

int32_t lf_fmu_check_param(const lf_fmu_param *p, double v) {
  if (!isfinite(v) || v < p->lo || v > p->hi || (p->lo_open && v == p->lo)) return 0;
  if (p->what == LF_P_CONTROL_CAL_SWEEPS && v != floor(v)) return 0;
  return 1;
}

void lf_fmu_apply_gain(lf_sim *s, int32_t what, double v) {
  lf_params *c = &s->firmware;
  switch (what) {
    case LF_P_CONTROL_V_MAX: c->v_max = v; break;
    case LF_P_CONTROL_KB: c->k_b = v; break;
    case LF_P_CONTROL_KP: c->k_p = v; break;
    case LF_P_CONTROL_KI: c->k_i = v; break;
    case LF_P_CONTROL_KD: c->k_d = v; break;
    case LF_P_CONTROL_ACCEL_MAX: c->accel_max = v; break;
    case LF_P_CONTROL_INTEGRAL_LIMIT: c->integral_limit = v; break;
    default: break;
  }
}

/* A gearmotor's fields (motors.actuator.write_fields), keeping the gear's sign. v: R_M, L_M, K, b_M, J_rotor, gear,
 * efficiency, friction. actuator_user holds R_M and the wheel joint's own dry friction (motors.actuator). */
static void write_motor(mjModel *m, int32_t a, const double *v) {
  double *user = m->actuator_user + a * m->nuser_actuator;
  int32_t dof = m->jnt_dofadr[m->actuator_trnid[2 * a]];
  m->actuator_gainprm[a * mjNGAIN + 0] = v[6] * v[2] / v[0];         /* η K / R */
  m->actuator_biasprm[a * mjNBIAS + 2] = -v[6] * v[2] * v[2] / v[0]; /* -η K² / R */
  m->actuator_dynprm[a * mjNDYN + 0] = v[1] / v[0];                  /* L_M / R_M */
  user[0] = v[0];
  m->actuator_gear[a * 6] = (m->actuator_gear[a * 6] < 0 ? -1.0 : 1.0) * v[5];
  m->actuator_armature[a] = v[4];
  m->actuator_damping[a] = v[3];
  m->dof_frictionloss[dof] = user[1] + v[5] * v[6] * v[7]; /* + G η τ0 */
}

/* motor.supply_voltage is the battery's open-circuit voltage (twin.model.power) */
static void set_power(lf_power *p, int32_t what, double v) {
  switch (what) {
    case LF_P_MOTOR_SUPPLY_VOLTAGE: p->battery_v = v; break;
    case LF_P_POWER_SOURCE_RESISTANCE: p->source_ohm = v; break;
    case LF_P_POWER_REGULATOR_VOLTAGE: p->regulator_v = v; break;
    case LF_P_POWER_REGULATOR_MIN_INPUT: p->regulator_min_input_v = v; break;
    default: break;
  }
}

static void set_timing(lf_timing *t, int32_t what, double v) {
  switch (what) {
    case LF_P_TIMING_RELEASE: t->release_us = v; break;
    case LF_P_TIMING_COMPUTE: t->compute_us = v; break;
    case LF_P_TIMING_COMPUTE_CENTRED: t->compute_centred_us = v; break;
    case LF_P_TIMING_COMPUTE_LOST: t->compute_lost_us = v; break;
    case LF_P_TIMING_COMPUTE_CALIBRATE: t->compute_calibrate_us = v; break;
    case LF_P_TIMING_PWM_COUNTS: t->pwm_counts = v; break;
    default: break;
  }
}

static void set_sensor(lf_sim *s, int32_t what, double v) {
  lf_sensor_model *r = &s->sensor;
  switch (what) {
    case LF_P_SENSOR_APERTURE: r->aperture_m = v; break;
    case LF_P_SENSOR_HALF_ANGLE: r->half_angle_rad = v; break;
    case LF_P_SENSOR_FALLOFF_HEIGHT: r->falloff_height_m = v; break;
    case LF_P_SENSOR_T_UNIT: r->t_unit_us = v; break;
    case LF_P_SENSOR_TIMEOUT: r->timeout_us = v; break;
    case LF_P_SENSOR_NOISE: r->noise_rel = v; break;
    default: break;
  }
}

static void set_control(lf_sim *s, int32_t what, double v) {
  lf_params *c = &s->firmware;
  switch (what) {
    case LF_P_CONTROL_DT: c->dt_s = v; break;
    case LF_P_CONTROL_FULL_SPEED: c->wheel_speed_max = v; break;
    case LF_P_CONTROL_CAL_DUTY: c->cal_duty = v; break;
    case LF_P_CONTROL_CAL_SWEEP: c->cal_sweep_rad = v; break;
    case LF_P_CONTROL_CAL_SWEEPS: c->cal_sweeps = (int32_t)v; break;
    default: lf_fmu_apply_gain(s, what, v); break;
  }
}

int32_t lf_fmu_apply(lf_fmu *f, lf_sim *s) {
  const lf_fmu_config *c = f->config;
  mjModel *m = f->m;
  double motor[8]; /* R_M, L_M, K, b_M, J_rotor, gear, efficiency, friction */
  int32_t k, nmotor = 0, i;
  double steps;
  for (k = 0; k < c->nparam; k++) {
    int32_t what = c->params[k].what;
    double v = f->param[k];
    if (what >= LF_P_MOTOR_R_M && what <= LF_P_MOTOR_FRICTION) {
      motor[what - LF_P_MOTOR_R_M] = v;
      nmotor++;
    } else if (what == LF_P_MOTION_MU) {
      for (i = 0; i < c->ntyre; i++) m->geom_friction[3 * c->tyre_geom[i]] = v;
    } else if (what == LF_P_MOTION_FLOOR_MU) {
      m->geom_friction[3 * c->floor_geom] = v;
    } else if (what == LF_P_MOTION_CASTER_MU) {
      for (i = 0; i < c->ncaster; i++) m->geom_friction[3 * c->caster_geom[i]] = v;
    } else if (what == LF_P_MOTION_TIMESTEP) {
      m->opt.timestep = v;
      s->timestep = v;
    } else if (what == LF_P_MOTION_IMPRATIO) {
      m->opt.impratio = v;
    } else if (what == LF_P_MOTOR_SUPPLY_VOLTAGE ||
               (what >= LF_P_POWER_SOURCE_RESISTANCE && what <= LF_P_POWER_REGULATOR_MIN_INPUT)) {
      set_power(&s->power, what, v);
    } else if (what >= LF_P_SENSOR_APERTURE && what <= LF_P_SENSOR_NOISE) {
      set_sensor(s, what, v);
    } else if (what >= LF_P_TIMING_RELEASE && what <= LF_P_TIMING_PWM_COUNTS) {
      set_timing(&s->timing, what, v);
    } else if (what == LF_P_LAP_TIMEOUT) {
      f->limits.timeout_s = v;
    } else {
      set_control(s, what, v);
    }
  }
  /* duty 1 gives the regulator's voltage, or the battery's (twin.model.power.Power.nominal_v); the control clamps there */
  s->supply_voltage = s->power.regulator_v > 0.0 ? s->power.regulator_v : s->power.battery_v;
  s->terminal_min_v = s->power.battery_v;
  m->actuator_ctrlrange[2 * s->actuator_left] = m->actuator_ctrlrange[2 * s->actuator_right] = -s->supply_voltage;
  m->actuator_ctrlrange[2 * s->actuator_left + 1] = m->actuator_ctrlrange[2 * s->actuator_right + 1] = s->supply_voltage;
  if (nmotor == 8) {
    if ((motor[1] > 0) != (m->actuator_actnum[s->actuator_left] > 0)) {
      lf_fmu_log(f, LF_FMU_ERROR, "motor.L_M: switching between zero and non-zero inductance changes the model's "
                 "structure; export the FMU again with the value you want");
      return 0;
    }
    write_motor(m, s->actuator_left, motor);
    write_motor(m, s->actuator_right, motor);
  }
  /* control.dt must be a whole number of physics steps, as twin.core.DigitalTwin.control_params requires */
  steps = s->firmware.dt_s / s->timestep;
  if (fabs(steps - round(steps)) > 1e-9 || round(steps) < 1) {
    lf_fmu_log(f, LF_FMU_ERROR, "control.dt: %g s is not a whole number of physics steps (motion.timestep %g s)",
               s->firmware.dt_s, s->timestep);
    return 0;
  }
  f->steps_per_tick = (int32_t)round(steps);
  return 1;
}
