/* One line of the trace, written at every control tick by the C loop (twin_core.h) and read by the lap judges (Python's
 * twin.core.lap, C's lap_judge.h). Python mirrors it as rows of float64 (twin.core.native.RECORD_FIELDS). */
#ifndef LF_RECORD_H
#define LF_RECORD_H

#include "../firmware/line_follower.h"

#define LF_RECORD_FIXED 20

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
  double progress_m;        /* arc length of the nearest centre-line point, in [0, track length) */
  double offset_m;          /* signed distance of the centre of rotation from the centre line, + left */
  double offset_abs_sum_m;  /* sum of |offset| over the phase's ticks so far (mean = sum / ticks) */
  double offset_abs_max_m;  /* largest |offset| in the phase so far */
  double raw_us[LF_MAX_SENSORS];       /* raw RC readings */
  double calibrated[LF_MAX_SENSORS];   /* Eq. 8 values 0..1000 */
} lf_record;

#endif
