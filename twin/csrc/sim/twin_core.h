/* The twin's closed loop in C: per-simulation layout of mjData.userdata and the control callback.
 *
 * userdata = [lf_sim | lf_record x record_capacity], all 8-byte aligned. Python (twin.core) mirrors these
 * structs with ctypes and checks their sizes against lf_sizes() when the library loads.
 */
#ifndef LF_TWIN_CORE_H
#define LF_TWIN_CORE_H

#include <stdint.h>

#include "../firmware/line_follower.h"
#include "sensor_physics.h"

#define LF_MAGIC 1279676025.0  /* "LFTy": marks userdata the callback owns; other models are left alone */
#define LF_LAYOUT_VERSION 1
#define LF_RECORD_FIXED 16

/* One line of the trace, written at every control tick. */
typedef struct {
  double time_s;            /* simulated time of the tick [s] */
  double x_m, y_m, yaw_rad; /* centre of rotation (axle midpoint) and heading */
  double e_rad;             /* Eq. 9 line angle */
  double v_mps, omega_radps;/* Eqs. 10-11 commands after the ramp */
  double u_left_v, u_right_v; /* motor voltages [V] */
  double wheel_left_radps, wheel_right_radps; /* encoder wheel speeds [rad/s] */
  double position;          /* readLine 0..(count-1)*1000 */
  double line_seen;         /* 1 if any calibrated value > 200 */
  double mode;              /* enum lf_mode before the tick */
  double energy_j;          /* electrical energy drawn by both motors so far [J] */
  double height_m;          /* sensor 0 height above the floor [m] */
  double raw_us[LF_MAX_SENSORS];       /* raw RC readings */
  double calibrated[LF_MAX_SENSORS];   /* Eq. 8 values 0..1000 */
} lf_record;

/* Per-simulation configuration (written by Python) and state (advanced by the callback). */
typedef struct {
  double magic;
  int32_t layout_version;
  int32_t nsensor;
  int32_t sensor_adr[LF_MAX_SENSORS]; /* sensordata address of each rangefinder: dist, point xyz */
  int32_t texture_id;
  int32_t actuator_left, actuator_right;
  int32_t dof_left, dof_right;   /* wheel joint dof addresses (encoders) */
  int32_t axle_site;             /* site at the centre of rotation */
  int32_t root_body;             /* the robot's free body (heading) */
  int32_t record_capacity;
  double texture_origin_x, texture_origin_y, texture_metres_per_pixel;
  double supply_voltage;         /* PWM duty 1 -> this voltage [V] */
  double timestep;               /* physics step [s], for the control-tick comparison */
  lf_sensor_model sensor;
  lf_params firmware;
  uint64_t seed;
  /* state */
  uint64_t rng;
  int64_t ticks;                 /* control ticks since the phase started */
  int64_t records_written;       /* total; record k lives in slot k % record_capacity */
  double phase_start_time;       /* time of the phase's first tick [s] */
  double last_time;              /* time of the last callback, for the energy integral [s] */
  double energy_j;               /* electrical energy drawn by both motors [J] */
  lf_state fw;
  uint16_t raw[LF_MAX_SENSORS];
} lf_sim;

#endif
