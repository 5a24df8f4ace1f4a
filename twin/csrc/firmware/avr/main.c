/* The line follower's program for the Pololu 3pi (board_3pi.h): every control period, read the QTR-RC sensors,
 * run the portable firmware (line_follower.c: calibration turn, Eqs. 8-11) and set the motors, and send telemetry
 * (lf_wire.c) out of the UART. The period comes from a Timer1 compare interrupt; between ticks the CPU sleeps.
 *
 * Phases as on the robot: at power-up the calibration turn; then the motors brake until button B is pressed with
 * the robot on the start line; then line following.
 *
 * Globals named fw_* are what the twin's processor-in-the-loop glue (twin/csrc/pil) reads from the MCU's RAM by
 * their ELF symbols to trace each tick; the program works the same without anyone reading them.
 */
#include <avr/interrupt.h>
#include <avr/io.h>
#include <avr/sleep.h>

#include "../lf_wire.h"
#include "../line_follower.h"
#include "board_3pi.h"
#include "config.h"
#include "motors.h"
#include "qtr_rc.h"
#include "uart.h"

lf_state fw_state;
uint16_t fw_raw_us[LF_MAX_SENSORS]; /* the readings of the last tick [us] */
int32_t fw_tick_mode;               /* the mode the last tick began in (enum lf_mode) */
volatile uint32_t fw_ticks_done;    /* ticks whose motor commands are set */
volatile uint16_t fw_overruns;      /* ticks that began before the last one had finished */
static volatile uint8_t tick_due;
static uint16_t period_counts;
static lf_config config;

ISR(TIMER1_COMPA_vect) {
  OCR1A += period_counts; /* the next tick, exactly one period on: no drift from the ISR's latency */
  if (tick_due) fw_overruns++;
  tick_due = 1;
}

static void wait_for_tick(void) {
  cli();
  while (!tick_due) { /* sleep with interrupts enabled in the instruction after sei: no wake-up can be missed */
    sleep_enable();
    sei();
    sleep_cpu();
    sleep_disable();
    cli();
  }
  tick_due = 0;
  sei();
}

static void ticks_init(lf_real dt_s) {
  period_counts = (uint16_t)(dt_s * (lf_real)(F_CPU / LF_TIMER1_PRESCALE) + 0.5);
  TCCR1A = 0;
  TCCR1B = _BV(CS11); /* normal mode, F_CPU / 8 */
  OCR1A = (uint16_t)(TCNT1 + period_counts);
  TIFR1 = _BV(OCF1A);
  TIMSK1 = _BV(OCIE1A);
}

static void send(char *line, int n) { uart_send(line, (uint8_t)n); }

static void send_header(char *line) {
  send(line, lf_wire_header(line, config.params.count, (int32_t)(config.params.dt_s * 1e6 + 0.5),
                            (int32_t)config.telemetry_every));
}

static uint8_t button_b_pressed(void) { return !(PINB & _BV(LF_BUTTON_B_BIT)); }

int main(void) {
  char line[LF_WIRE_MAX];
  uint32_t ms = 0, us_part = 0, dt_us;
  uint16_t since_sample = 0;
  motors_init(); /* braked until the configuration is known good */
  if (!config_load(&config)) {
    for (;;) sleep_mode(); /* no valid configuration: stay braked (interrupts off: the CPU halts) */
  }
  dt_us = (uint32_t)(config.params.dt_s * 1e6 + 0.5);
  PORTB |= _BV(LF_BUTTON_B_BIT); /* the button's pull-up */
  qtr_init((uint8_t)config.params.count);
  uart_init();
  lf_calibrate_reset(&fw_state, config.timeout_us);
  lf_reset(&fw_state, LF_CALIBRATE);
  ticks_init(config.params.dt_s);
  set_sleep_mode(SLEEP_MODE_IDLE); /* timers and the USART keep running */
  sei();
  send_header(line);
  for (;;) {
    wait_for_tick();
    if (fw_state.mode == LF_CALIBRATE) { /* a calibration call takes LF_CAL_READS readings (Pololu's calibrate) */
      uint8_t k;
      for (k = 1; k < LF_CAL_READS; k++) {
        qtr_read(fw_raw_us, (uint8_t)config.params.count, config.timeout_us);
        lf_calibrate_update(&fw_state, fw_raw_us, config.params.count);
      }
    }
    qtr_read(fw_raw_us, (uint8_t)config.params.count, config.timeout_us); /* lf_step calibrates with the last */
    if (fw_state.mode == LF_IDLE && button_b_pressed()) {
      lf_reset(&fw_state, LF_RUN);
      ms = us_part = since_sample = 0;
      send_header(line);
      send(line, lf_wire_start(line, 0));
    }
    fw_tick_mode = fw_state.mode;
    lf_step(&fw_state, &config.params, fw_raw_us);
    motors_set(fw_state.duty_left, fw_state.duty_right);
    fw_ticks_done++;
    if (fw_tick_mode == LF_RUN) {
      if (++since_sample >= config.telemetry_every) {
        lf_real to_crad = config.params.wheel_speed_max * 100.0; /* no encoders: the commanded wheel speeds */
        since_sample = 0;
        send(line, lf_wire_sample(line, ms, fw_state.position, fw_state.line_seen,
                                  (int32_t)(fw_state.duty_left * to_crad), (int32_t)(fw_state.duty_right * to_crad)));
      }
      us_part += dt_us;
      while (us_part >= 1000) us_part -= 1000, ms++;
    }
  }
}
