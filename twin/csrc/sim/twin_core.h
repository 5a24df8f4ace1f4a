/* The twin's closed loop in C: per-simulation layout of mjData.userdata and the control callback.
 *
 * Rays are cast with MuJoCo's mj_ray, called through a pointer that Python hands over once (lf_set_ray) from
 * the libmujoco the mujoco module has loaded: the library needs no link-time dependency on a versioned .so.
 *
 * userdata = [lf_sim | lf_record x record_capacity], all 8-byte aligned. Python (twin.core.native) mirrors these
 * structs with ctypes and checks their sizes (lf_sizes) and every field's offset (lf_layout) when the library loads.
 *
 * Python validates and C trusts the values, but not the userdata's fit to the model it is stepped with: before
 * it reads or writes anything, the callback checks the head against the mjModel it is given (mujoco_glue.c) and,
 * if they do not fit, records why in `error` and leaves that simulation alone from then on.
 */
#ifndef LF_TWIN_CORE_H
#define LF_TWIN_CORE_H

#include <stdint.h>

#include "../firmware/line_follower.h"
#include "lap_judge.h"
#include "lf_record.h"
#include "lf_status.h"
#include "sensor_physics.h"

#define LF_MAGIC 1279676025.0  /* "LFTy": marks userdata the callback owns; other models are left alone */
#define LF_LAYOUT_VERSION 11
#define LF_SIGNATURE 8 /* model sizes in lf_sim.model_signature: see model_signature() in mujoco_glue.c */


/* The code paths of a control tick's compute, which take measurably different times on the MCU (avr_timing.c): the
 * line seen off centre (the general path), the line read exactly at the centre (e = 0: the soft-float products of a
 * zero are short), the line lost (readLine reports an end without its division), a calibration tick. */
enum lf_compute_path {
  LF_PATH_GENERAL = 0, LF_PATH_CENTRED = 1, LF_PATH_LOST = 2, LF_PATH_CALIBRATE = 3, LF_COMPUTE_PATHS = 4
};

/* The path a tick took, from the state its lf_step left. */
static inline int32_t lf_compute_path(const lf_state *fw) {
  if (fw->mode != LF_RUN) return LF_PATH_CALIBRATE; /* a calibration tick, or its last (which leaves LF_IDLE) */
  if (!fw->line_seen) return LF_PATH_LOST;
  return fw->e == 0 ? LF_PATH_CENTRED : LF_PATH_GENERAL;
}

/* The robot's timing: when the duties a control tick decides reach the motors. On the robot the tick releases the
 * QTR-RC lines (the readings' instant), the read lasts until the last line has fallen or the timeout (each line's
 * decay is its raw reading), then the firmware computes (for as long as its code path takes) and writes the PWM
 * compare values, whole timer counts. Defaults are measured on the emulated MCU (twin/csrc/pil/avr_timing.c;
 * twin.model.timing). */
typedef struct {
  double release_us;             /* the tick to the lines' release [us] */
  double compute_us;             /* the read's end to the PWM write [us], the compute's general path (the line seen
                                    off centre; an external controller's tick) */
  double compute_centred_us;     /* the same when the line reads exactly at the centre (e = 0) [us] */
  double compute_lost_us;        /* the same when the line is lost [us] */
  double compute_calibrate_us;   /* the same in a calibration tick [us] */
  double pwm_counts;             /* the PWM period in timer counts: a duty is a whole number of counts, at most one
                                    short of the period (0: any duty) */
} lf_timing;

/* The motor driver's supply (twin.model.power): a battery, open-circuit battery_v behind source_ohm (internal
 * resistance, contacts, wiring), feeds the H-bridges directly, or through a boost regulator that holds regulator_v
 * while the battery's terminal voltage stays at or above regulator_min_input_v and shuts off for the rest of the
 * run below it (the 3pi: its MCU's 5 V comes from the boosted rail too). */
typedef struct {
  double battery_v;              /* open-circuit battery voltage [V] */
  double source_ohm;             /* resistance between the cells and the H-bridges [ohm] */
  double regulator_v;            /* boost regulator output [V]; 0: no regulator */
  double regulator_min_input_v;  /* the regulator's lowest input [V] */
} lf_power;

/* Per-simulation configuration (written by Python) and state (advanced by the callback). */
typedef struct {
  double magic;
  int32_t layout_version;
  int32_t error;                 /* enum lf_status: set by the callback when it refuses the simulation */
  int64_t model_signature[LF_SIGNATURE]; /* the model's sizes when Python wrote the head */
  int32_t nsensor;
  int32_t sensor_site[LF_MAX_SENSORS]; /* site of each sensor; its z axis is the ray */
  int32_t sensor_body;           /* the sensor mount: its own geoms never block a ray */
  int32_t texture_id;
  int32_t actuator_left, actuator_right;
  int32_t dof_left, dof_right;   /* wheel joint dof addresses (encoders) */
  int32_t axle_site;             /* site at the centre of rotation */
  int32_t root_body;             /* the robot's free body (heading) */
  int32_t record_capacity;
  int32_t centre_adr;            /* numeric_data address of the centre line: x, y, arc length per vertex */
  int32_t centre_count;          /* vertices of the closed centre line */
  double texture_origin_x, texture_origin_y, texture_metres_per_pixel;
  double supply_voltage;         /* PWM duty 1 -> this voltage with no load: the regulator's, or the battery's [V] */
  double timestep;               /* physics step [s], for the control-tick comparison */
  lf_sensor_model sensor;
  lf_params firmware;
  uint64_t seed;
  /* state */
  uint64_t rng;                  /* the phase's noise base (lf_noise_base): reading k of sensor i draws
                                    lf_reading_noise(rng, k, i) */
  int64_t ticks;                 /* control ticks since the phase started */
  int64_t records_written;       /* total; record k lives in slot k % record_capacity */
  int64_t segment;               /* centre-line segment nearest the robot at the last tick, -1: search all */
  double phase_start_time;       /* time of the phase's first tick [s] */
  double last_time;              /* time of the last callback, for the energy integral [s] */
  double energy_j;               /* electrical energy drawn by both motors [J] */
  double offset_abs_sum_m, offset_abs_max_m; /* running cross-track statistics of the phase [m] */
  lf_state fw;
  uint16_t raw[LF_MAX_SENSORS];
  /* the lap's judge in C (lap_judge.h), fed every record of a judged phase: Python starts it with the lap
   * (judge_on 1); when it decides, or a record passes deadline_s, the callback raises a warning counter
   * (LF_STOP_WARNING, mujoco_glue.c), which ends the simulation's mujoco.batch rollout at that step (Python's judge
   * decides the same from the same records) */
  int32_t judge_on;
  int32_t stop_raised;            /* the callback raised the stop signal (once) */
  double deadline_s;              /* simulated time past which the lap may stop undecided [s] (inf: never) */
  lf_judge judge;
  /* the robot's timing (lf_timing): the motors run on duty_now until apply_time_s, then on duty_next */
  lf_timing timing;
  double duty_now[2], duty_next[2]; /* left, right: PWM duty in [-1, 1] */
  double apply_time_s;            /* when duty_next takes effect [s]; the next tick takes it in any case */
  int32_t pending;                /* duty_next is waiting for apply_time_s */
  int32_t pad;
  int64_t reads;                  /* readings of every sensor taken in this phase (a calibration tick takes ten) */
  lf_power power;                 /* the supply (lf_bus_voltage) */
  double terminal_min_v;          /* the lowest battery terminal voltage of the run [V] */
  int32_t power_off;              /* the regulator shut off: the motors get nothing for the rest of the run */
  int32_t pad_power;
} lf_sim;

/* One field of a mirrored struct, for Python's load-time check: "struct.field", offsetof and sizeof [bytes]. */
typedef struct {
  const char *name;
  int64_t offset, size;
} lf_field;
/* A row of such a table (offsetof: include <stddef.h>); LF_FIELD names it "type.field". */
#define LF_FIELD_NAMED(name, type, field) {name, (int64_t)offsetof(type, field), (int64_t)sizeof(((type *)0)->field)}
#define LF_FIELD(type, field) LF_FIELD_NAMED(#type "." #field, type, field)

/* The fields of lf_sim, lf_record, lf_params, lf_state, lf_sensor_model and lf_texture; returns their number. */
int32_t lf_layout(const lf_field **fields);
/* Struct sizes, the MuJoCo header version, sizeof(mjtNum), LF_MAX_SENSORS, LF_LAYOUT_VERSION, LF_SIGNATURE into
 * out[0..n-1]; returns how many values there are. */
int32_t lf_sizes(int64_t *out, int32_t n);

/* Nearest point of a closed polyline (x, y, arc length per vertex) to (x, y), searched from segment *seg
 * (or over all segments if *seg < 0) by walking to neighbours while they are nearer. */
void lf_locate(const double *centre, int32_t n, double length, double x, double y, int64_t *seg, double *progress,
               double *offset);

/* Shared by the control callback and the processor-in-the-loop glue (twin/csrc/pil), which runs the firmware on an
 * emulated MCU instead of calling lf_step. mujoco.h must be included before this part. */
#ifdef mjVERSION_HEADER
int32_t lf_check(const mjModel *m, const lf_sim *s);         /* LF_OK, or why the head does not fit the model */
int32_t lf_has_ray(void);                                    /* lf_set_ray has been called */
/* Sensor i's raw reading into s->raw[i] with the noise of its read-th reading, as its site will be ahead_s seconds
 * from now if it moves as it moves now (the processor in the loop reads at a release inside the physics step);
 * returns its height [m]. */
double lf_read_sensor_at(const mjModel *m, const mjData *d, lf_sim *s, int32_t i, double ahead_s, int64_t read);
/* The trace record of this tick: u_left_v, u_right_v are the motor voltages it records [V]. */
void lf_write_record(const mjModel *m, const mjData *d, lf_sim *s, double mode, double height0, double u_left_v,
                     double u_right_v);
double lf_motor_power(const mjModel *m, const mjData *d, int32_t a); /* electrical power u i, >= 0 [W] */
/* The callback's work on a head its caller owns (an FMU steps its own head between mj_step1 and mj_step2, so that
 * a callback installed by the host process never sees it): check, energy, and at a control tick sensors, firmware,
 * motors and a trace record. lf_control_callback is this on the head in d->userdata. */
void lf_loop(const mjModel *m, mjData *d, lf_sim *s);
int32_t lf_ready(const mjModel *m, lf_sim *s);  /* lf_set_ray was called and the head fits the model (else error) */
void lf_integrate_energy(const mjModel *m, const mjData *d, lf_sim *s); /* motors' energy up to d->time */
int32_t lf_tick_due(const mjData *d, const lf_sim *s);                  /* a control tick is due at d->time */
void lf_read_sensors(const mjModel *m, const mjData *d, lf_sim *s, double *height0); /* every sensor's raw reading */
/* The robot's timing (lf_timing): how long `reads` reads of every sensor last, the slowest line's raw reading each
 * [us]; the firmware's compute time for the code path its last lf_step took [us]; a tick's duties in [-1, 1], which
 * take effect release + read_us + compute_us after d->time, at the PWM's whole counts; and every step, the voltages
 * the motors see over the step beginning at d->time [V]. */
double lf_read_time_us(const lf_sim *s, int32_t reads);
double lf_compute_time_us(const lf_sim *s);
void lf_decide(const mjData *d, lf_sim *s, double duty_left, double duty_right, double read_us, double compute_us);
void lf_drive(const mjModel *m, const mjData *d, lf_sim *s, double *u_left_v, double *u_right_v);
/* The H-bridges' supply over a step whose mean duties are duty[2] (lf_power), with the motors' back-EMF now [V]. */
double lf_bus_voltage(const mjModel *m, const mjData *d, lf_sim *s, const double duty[2]);
#endif

#endif
