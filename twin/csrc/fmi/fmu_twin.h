/* The twin as a Co-Simulation FMU: the same C core as the lap (sensor physics, firmware, the control loop of
 * mujoco_glue.c, the lap judge) stepped by MuJoCo's library, with no Python at run time.
 *
 * One instance owns its model (loaded from resources/twin.mjb, a pristine copy kept for reset), its data and its
 * head (resources/head.bin: the lf_sim that twin.core.closed_loop.setup writes, with the exporter's values). It never
 * installs a MuJoCo callback or handler: it steps with mj_step1 / its own loop / mj_step2, and its head carries no
 * LF_MAGIC, so a control callback the host process installed (the twin's own, in Python) leaves it alone. Two
 * instances in one process share nothing but the pointer to mj_ray.
 *
 * The kinds (the exporter compiles one, LF_FMU_KIND in the generated fmu_model.h):
 *  - plant: voltages in; pose, wheel speeds, the sensor side (raw and calibrated readings, readLine position, Eq. 9
 *    angle, read at each communication point) and the lap judged at those points out;
 *  - closed loop: the firmware drives at its period inside the steps; the lap's time, status and cross-track error out.
 * Both begin with the robot's calibration turn during initialisation, then stand on the start line at the start time.
 *
 * The FMI faces (fmi2_face.c, fmi3_face.c) check the calling sequence; this file checks values and does the work.
 */
#ifndef LF_FMU_TWIN_H
#define LF_FMU_TWIN_H

#include <stddef.h>
#include <stdint.h>

#include <mujoco/mujoco.h>

#include "../sim/lap_judge.h"
#include "../sim/twin_core.h"

enum lf_fmu_kind { LF_FMU_PLANT = 1, LF_FMU_CLOSED_LOOP = 2 };
#define LF_FMU_MAX_TYRES 8 /* tyre geoms whose friction is motion.mu */
#define LF_FMU_MAX_CASTERS 8 /* caster geoms whose friction is motion.caster_mu */

/* Where a variable's value lives (lf_fmu_var.source). */
enum lf_fmu_source {
  LF_SRC_TIME = 0,   /* the communication time [s] */
  LF_SRC_INPUT = 1,  /* index 0: voltage_left, 1: voltage_right [V] */
  LF_SRC_RECORD = 2, /* index: column of the output record (lf_record read as doubles) */
  LF_SRC_LAP = 3,    /* index: enum lf_fmu_lap_value */
  LF_SRC_PARAM = 4,  /* index: row of the parameter table */
  LF_SRC_SEED = 5    /* the noise seed (uint64) */
};

enum lf_fmu_lap_value {
  LF_LAP_STATUS_VALUE = 0, /* enum lf_lap_status */
  LF_LAP_COMPLETED_VALUE = 1,
  LF_LAP_TIME_VALUE = 2,   /* [s], 0 until completed */
  LF_LAP_DISTANCE_VALUE = 3, /* unwrapped progress along the centre line [m] */
  LF_LAP_XTE_MAX_VALUE = 4,  /* [m] */
  LF_LAP_XTE_MEAN_VALUE = 5, /* [m] */
  LF_LAP_ENERGY_VALUE = 6    /* [J] drawn until the lap ended, 0 before */
};

enum lf_fmu_type { LF_REAL = 0, LF_INTEGER = 1, LF_BOOLEAN = 2, LF_UINT64 = 3 };

/* One variable; its value reference is its row in the generated table. */
typedef struct {
  const char *name;
  int32_t source, index, type;
} lf_fmu_var;

/* What a parameter changes: "LF_P_" and its model-space address in capitals (the exporter writes that name, so
 * an address this file does not know fails the export's compilation). */
enum lf_fmu_param_what {
  LF_P_MOTION_MU, LF_P_MOTION_FLOOR_MU, LF_P_MOTION_CASTER_MU, LF_P_MOTION_TIMESTEP, LF_P_MOTION_IMPRATIO,
  LF_P_MOTOR_R_M, LF_P_MOTOR_L_M, LF_P_MOTOR_K, LF_P_MOTOR_B_M, LF_P_MOTOR_J_ROTOR, LF_P_MOTOR_GEAR,
  LF_P_MOTOR_EFFICIENCY, LF_P_MOTOR_FRICTION,
  LF_P_MOTOR_SUPPLY_VOLTAGE,
  LF_P_SENSOR_APERTURE, LF_P_SENSOR_HALF_ANGLE, LF_P_SENSOR_FALLOFF_HEIGHT, LF_P_SENSOR_T_UNIT,
  LF_P_SENSOR_TIMEOUT, LF_P_SENSOR_NOISE,
  LF_P_CONTROL_V_MAX, LF_P_CONTROL_KB, LF_P_CONTROL_KP, LF_P_CONTROL_KI, LF_P_CONTROL_KD, LF_P_CONTROL_DT,
  LF_P_CONTROL_ACCEL_MAX, LF_P_CONTROL_FULL_SPEED, LF_P_CONTROL_INTEGRAL_LIMIT, LF_P_CONTROL_CAL_DUTY,
  LF_P_CONTROL_CAL_SWEEP, LF_P_CONTROL_CAL_SWEEPS,
  LF_P_TIMING_RELEASE, LF_P_TIMING_COMPUTE, LF_P_TIMING_COMPUTE_CENTRED, LF_P_TIMING_COMPUTE_LOST,
  LF_P_TIMING_COMPUTE_CALIBRATE, LF_P_TIMING_PWM_COUNTS,
  LF_P_POWER_SOURCE_RESISTANCE, LF_P_POWER_REGULATOR_VOLTAGE, LF_P_POWER_REGULATOR_MIN_INPUT,
  LF_P_LAP_TIMEOUT,
  LF_P_COUNT
};

typedef struct {
  const char *address;
  int32_t what;       /* enum lf_fmu_param_what */
  int32_t tunable;    /* may change between steps (the gains), else only before initialisation */
  int32_t lo_open;    /* lo itself is excluded */
  double start, lo, hi;
} lf_fmu_param;

/* What an export fixes about its model (generated into fmu_model.h). */
typedef struct {
  int32_t kind;            /* enum lf_fmu_kind */
  int32_t start_key;       /* keyframe of the start line */
  int32_t floor_geom;
  int32_t ntyre, tyre_geom[LF_FMU_MAX_TYRES];
  int32_t ncaster, caster_geom[LF_FMU_MAX_CASTERS];
  double calibration_timeout_s, min_calibration_range_us;
  lf_lap_limits limits;    /* timeout_s is the lap_timeout parameter's start */
  uint64_t seed;           /* start value */
  int32_t nvar, nparam;
  const lf_fmu_var *vars;
  const lf_fmu_param *params;
} lf_fmu_config;

typedef void (*lf_fmu_logger)(void *env, int32_t status, const char *category, const char *message);

enum lf_fmu_status { LF_FMU_OK = 0, LF_FMU_WARNING = 1, LF_FMU_DISCARD = 2, LF_FMU_ERROR = 3, LF_FMU_FATAL = 4 };

typedef struct {
  const lf_fmu_config *config;
  mjModel *m0, *m;      /* as loaded (restored at reset) and with the parameters applied */
  mjData *d;
  lf_sim head0;         /* the head as exported */
  lf_sim head;          /* head0 with the parameters applied at initialisation */
  lf_judge judge;
  lf_lap_limits limits; /* the config's, with the lap_timeout parameter */
  double *param;        /* current parameter values, in table order */
  uint64_t seed;
  double voltage[2];    /* plant inputs [V] */
  lf_record out;        /* what the outputs show */
  int64_t consumed;     /* records fed to the judge */
  int64_t steps;        /* physics steps since the start time */
  double t0, time;      /* start and current communication time [s] */
  int32_t frozen;       /* the physics diverged or the head was refused: no more steps */
  int32_t steps_per_tick;
  lf_fmu_logger log;
  void *log_env;
} lf_fmu;

lf_fmu *lf_fmu_new(const lf_fmu_config *config, const char *resource_dir, lf_fmu_logger log, void *log_env);
void lf_fmu_free(lf_fmu *f);
void lf_fmu_reset(lf_fmu *f);             /* back to the state after lf_fmu_new, parameters at their starts */
int32_t lf_fmu_initialise(lf_fmu *f, double start_time); /* apply parameters, calibrate, stand on the start line */
int32_t lf_fmu_do_step(lf_fmu *f, double t, double h);
int32_t lf_fmu_get(lf_fmu *f, uint32_t vr, int32_t type, double *real, int64_t *integer, uint64_t *u64);
int32_t lf_fmu_set(lf_fmu *f, uint32_t vr, int32_t type, double real, int64_t integer, uint64_t u64, int32_t running);
void lf_fmu_log(lf_fmu *f, int32_t status, const char *fmt, ...);

/* fmu_params.c: a value's check against its row, and every parameter written into the model and the head. */
int32_t lf_fmu_check_param(const lf_fmu_param *p, double v);
int32_t lf_fmu_apply(lf_fmu *f, lf_sim *head);
void lf_fmu_apply_gain(lf_sim *head, int32_t what, double v); /* a tunable parameter, between steps */

#endif
