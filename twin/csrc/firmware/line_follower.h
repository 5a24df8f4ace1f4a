/* Line-follower firmware: sensor processing (paper Eqs. 8-9) and control (Eqs. 10-11).
 *
 * Portable C99 for the robot's 8-bit MCU and for the digital twin alike: no MuJoCo types, no malloc,
 * fixed-size arrays, one state struct. The sensor side copies Pololu's QTRSensors library
 * (calibrate / readCalibrated / readLine) in integer arithmetic, so the twin computes what the robot does.
 *
 * Units: lengths [m], angles [rad], time [s], raw sensor readings [us] of RC discharge time (QTR-RC),
 * calibrated readings 0..1000, line position 0..(count-1)*1000, motor commands as PWM duty in [-1, 1].
 */
#ifndef LINE_FOLLOWER_H
#define LINE_FOLLOWER_H

#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

#define LF_MAX_SENSORS 16
#define LF_CAL_READS 10 /* readings per calibration call, as Pololu's QTRSensors::calibrate takes */
#define LF_NOISE_THRESHOLD 50 /* readLine: calibrated values above this are averaged */
#define LF_LINE_THRESHOLD 200 /* readLine: the line is seen if any value exceeds this */
/* Tick counts saturate instead of wrapping: a quarter sweep at most 2^29 ticks (exact in float and double, and
 * four of them fit a uint32), a calibration turn and the tick counter at most UINT32_MAX. */
#define LF_QUARTER_TICKS_MAX ((uint32_t)536870912UL)
#define LF_TICKS_MAX UINT32_MAX

typedef double lf_real; /* avr-gcc's double is 32-bit: the same source is single precision on the MCU */

enum lf_mode { LF_IDLE = 0, LF_CALIBRATE = 1, LF_RUN = 2 };

/* What the firmware is told: the robot's geometry, the control gains and the loop period. */
typedef struct {
  int32_t count;              /* number of sensors, 2..LF_MAX_SENSORS */
  lf_real pitch_m;            /* sensor spacing [m] */
  lf_real sensor_distance_m;  /* S: centre of rotation to the sensor array [m] */
  lf_real v_max;              /* Eq. 10: top forward speed [m/s] */
  lf_real k_b;                /* Eq. 10: speed reduction per unit |e| [m/s/rad] */
  lf_real k_p;                /* Eq. 11: [1/s] */
  lf_real k_i;                /* Eq. 11: [1/s^2] */
  lf_real k_d;                /* Eq. 11: [-] */
  lf_real dt_s;               /* control period [s] */
  lf_real wheel_radius_m;     /* R [m] */
  lf_real half_track_m;       /* L [m] */
  lf_real wheel_speed_max;    /* wheel speed at full duty, no load [rad/s] */
  lf_real accel_max;          /* forward-speed ramp limit [m/s^2]: a full-duty launch spins the wheels */
  lf_real integral_limit;     /* anti-windup bound on the integral of e [rad*s] */
  lf_real cal_duty;           /* wheel duty of the in-place calibration turn [-] */
  lf_real cal_sweep_rad;      /* nominal half-angle of each calibration sweep [rad] */
  int32_t cal_sweeps;         /* calibration sweeps (right, left twice, right) */
} lf_params;

/* Everything the firmware remembers between loop iterations. */
typedef struct {
  uint16_t cal_min[LF_MAX_SENSORS]; /* Eq. 8: s_i,min, starts at the RC timeout */
  uint16_t cal_max[LF_MAX_SENSORS]; /* Eq. 8: s_i,max, starts at 0 */
  uint16_t value[LF_MAX_SENSORS];   /* last calibrated readings s_i, 0..1000 */
  int32_t position;                 /* last readLine result */
  int32_t last_position;            /* readLine memory: side the line was last seen on */
  int32_t line_seen;                /* last readLine saw the line (1) or reported an end (0) */
  int32_t mode;                     /* enum lf_mode */
  uint32_t tick;                    /* loop iterations in the current mode, saturating at LF_TICKS_MAX */
  lf_real e;                        /* Eq. 9: line angle [rad], > 0 when the line is to the left */
  lf_real e_prev;                   /* e of the previous RUN tick [rad] */
  lf_real integral;                 /* integral of e dt [rad*s] */
  lf_real v;                        /* forward-speed command after the ramp [m/s] */
  lf_real omega;                    /* Eq. 11 turn-rate command [rad/s] */
  lf_real duty_left, duty_right;    /* motor commands [-1, 1] */
  uint16_t call_min[LF_MAX_SENSORS]; /* the calibration call under way: its smallest reading per sensor */
  uint16_t call_max[LF_MAX_SENSORS]; /* and its largest */
  int32_t call_reads;               /* its readings so far, 0..LF_CAL_READS - 1 */
} lf_state;

void lf_reset(lf_state *s, int32_t mode);
void lf_calibrate_reset(lf_state *s, uint16_t timeout_us);
void lf_calibrate_update(lf_state *s, const uint16_t *raw, int32_t count);
void lf_read_calibrated(const lf_state *s, const uint16_t *raw, uint16_t *out, int32_t count);
int32_t lf_read_line(lf_state *s, const uint16_t *calibrated, int32_t count);
lf_real lf_line_angle(int32_t position, int32_t count, lf_real pitch_m, lf_real sensor_distance_m);
void lf_control(lf_state *s, const lf_params *p, lf_real e);
void lf_wheel_duties(const lf_params *p, lf_real v, lf_real omega, lf_real *left, lf_real *right);
uint32_t lf_calibration_ticks(const lf_params *p);
int32_t lf_calibration_direction(const lf_params *p, uint32_t tick);

/* One loop iteration on fresh raw readings: calibrate (turning in place) or follow the line.
 * Leaves the motor commands in s->duty_left / s->duty_right. */
void lf_step(lf_state *s, const lf_params *p, const uint16_t *raw);

#ifdef __cplusplus
}
#endif
#endif
