/* The lockstep of the MCU with MuJoCo. Per physics step of h seconds (lf_avr_lockstep):
 *   1. mj_step1: positions and velocities of the current state;
 *   2. the MCU runs to the step's end: a sensor line it releases falls when the sensor physics says (avr_sensors.c),
 *      and the drive its motor lines give is integrated (avr_motors.c);
 *   3. each motor's voltage is the supply times its mean drive over the step;
 *   4. the board's step: the LCD's screen kept if the program has been quiet, the LEDs shown (avr_lcd.c,
 *      avr_board.c); the trace: the ticks the twin's firmware finished, from its RAM (avr_trace.c), or for any other
 *      program the physics every trace_every steps (avr_board.c); then mj_step2 with those voltages.
 * The MCU's clock never runs ahead of the physics by more than one instruction or one sleep: what it does at
 * cycle c happens when the physics is at the step holding c.
 *
 * Any program ends the lap as stalled (LF_STALLED) when the MCU stops (sleeps with interrupts off) or crashes. For
 * the twin's own firmware a watchdog on simulated time also does when no tick completes, a sensor line is never
 * released, or no motor compare value is written; any other program may wait as long as it likes (Python's time
 * limits end such a run). */
#include <stdio.h>

#include "avr_glue.h"

/* Connect the twin: from now on, sensor releases read this simulation's physics. */
void lf_avr_attach(lf_avr *a, const mjModel *m, mjData *d, lf_sim *s, double stall_s) {
  int i;
  a->m = m, a->d = d, a->s = s;
  a->nsensor = s->nsensor < LF_BOARD_MAX_SENSORS ? s->nsensor : LF_BOARD_MAX_SENSORS;
  a->stall_cycles = (uint64_t)(stall_s * a->f_cpu);
  for (i = 0; i < LF_BOARD_MAX_SENSORS; i++) a->released[i] = a->avr->cycle, a->reads[i] = 0;
  a->pwm_written = a->tick_cycle = a->drive_since = a->avr->cycle;
  a->busy_tick_start = a->busy;
}

/* MuJoCo's time 0 is now (the robot was put on the start line). */
void lf_avr_zero_time(lf_avr *a) { a->zero_cycle = a->avr->cycle; }

/* MuJoCo's time 0 is the twin firmware's next control tick (its Timer1 compare comes every period_s), so that its lap
 * begins with a tick as the C loop's does; until then the MCU runs with the physics held at time 0. Without a tick
 * seen yet, time 0 is now. The buttons in `pressed` are held from time 0 on, not now: a tick already under way
 * read its sensors before the robot was put on the start line, and seeing the start button at its end it would run
 * its first control step on those stale readings (a kick of K_P times the old pose's error, 27 rad/s on the circle
 * with tuned gains). */
void lf_avr_zero_time_at_tick(lf_avr *a, double period_s, int32_t pressed) {
  uint64_t now = a->avr->cycle, period = cycles_of(a, period_s);
  a->zero_cycle = now;
  if (a->timing_tick && period && now > a->timing_tick)
    a->zero_cycle = a->timing_tick + period * ((now - a->timing_tick + period - 1) / period);
  a->press_at_zero = pressed, a->press_pending = 1;
}

static int stalled(lf_avr *a, const char *why) {
  snprintf(a->message, sizeof a->message, "%s", why);
  return LF_STALLED;
}

/* The watchdog after a step: LF_OK, or LF_STALLED with the reason. */
static int watchdog(lf_avr *a) {
  char why[MESSAGE];
  int i;
  if (a->avr->cycle - a->tick_cycle > a->stall_cycles) {
    snprintf(why, sizeof why, "no control tick completed for %.3g s", (double)(a->avr->cycle - a->tick_cycle) / a->f_cpu);
    return stalled(a, why);
  }
  for (i = 0; i < a->nsensor; i++) {
    if (a->avr->cycle - a->released[i] > a->stall_cycles) {
      snprintf(why, sizeof why, "sensor %d's line (P%c%d) was not released for %.3g s", i, name_of[sensor_pins[i][0]],
               sensor_pins[i][1], (double)(a->avr->cycle - a->released[i]) / a->f_cpu);
      return stalled(a, why);
    }
  }
  if (a->avr->cycle - a->pwm_written > a->stall_cycles) {
    snprintf(why, sizeof why, "no motor PWM compare value was written for %.3g s",
             (double)(a->avr->cycle - a->pwm_written) / a->f_cpu);
    return stalled(a, why);
  }
  return LF_OK;
}

/* Step the physics nstep times with the MCU in lockstep (see the top of this file); returns LF_OK, or an enum
 * lf_status (LF_STALLED, or why it refuses to run) with the reason in lf_avr_message. */
int32_t lf_avr_lockstep(lf_avr *a, void *step1, void *step2, int64_t nstep) {
  typedef void (*step_fn)(const mjModel *, mjData *);
  const mjModel *m = a->m;
  mjData *d = a->d;
  lf_sim *s = a->s;
  int64_t k;
  int32_t fit;
  if (!lf_has_ray()) {
    snprintf(a->message, sizeof a->message, "mj_ray has not been handed over (lf_set_ray)");
    return LF_ERR_RAY;
  }
  fit = lf_check(m, s);
  if (fit != LF_OK) {
    snprintf(a->message, sizeof a->message, "the simulation's head does not fit its model (error %d)", fit);
    return fit;
  }
  for (k = 0; k < nstep; k++) {
    double h = m->opt.timestep, power;
    uint64_t end = a->zero_cycle + (uint64_t)((d->time + h) * a->f_cpu + 0.5);
    uint64_t from;
    int verdict;
    ((step_fn)step1)(m, d);
    pil_drive_begin(a);
    from = a->avr->cycle;
    while (a->avr->cycle < end) {
      uint64_t c0 = a->avr->cycle;
      int awake, state;
      if (a->press_pending && c0 >= a->zero_cycle) lf_avr_buttons(a, a->press_at_zero), a->press_pending = 0;
      awake = a->avr->state == cpu_Running;
      state = avr_run(a->avr);
      if (awake) a->busy += a->avr->cycle - c0;
      if (state == cpu_Done || state == cpu_Crashed) {
        ((step_fn)step2)(m, d);
        return stalled(a, state == cpu_Done ? "the MCU stopped (it slept with interrupts off)" : "the MCU crashed");
      }
    }
    pil_drive_end(a, from);
    pil_lcd_step(a);
    pil_board_step(a, from);
    if (traced(a)) pil_trace_ticks(a, from);
    ((step_fn)step2)(m, d);
    power = lf_motor_power(m, d, s->actuator_left) + lf_motor_power(m, d, s->actuator_right);
    s->energy_j += h * power;
    s->last_time = d->time;
    verdict = traced(a) ? watchdog(a) : LF_OK;
    if (verdict != LF_OK) return verdict;
  }
  return LF_OK;
}

const char *lf_avr_message(const lf_avr *a) { return a->message; }
