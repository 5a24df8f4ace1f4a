/* Faulty versions of the robot's program, for the processor-in-the-loop watchdog (tests/test_pil.py). Built with
 * -DFAULT=n and the real drivers; each keeps the globals the twin traces, so only the fault ends its lap:
 *   1 hangs in a busy loop before its first tick     2 never releases its sensor lines (drives them high for good)
 *   3 never writes its motors' PWM after start-up    4 halts (sleeps with interrupts off) */
#include <avr/interrupt.h>
#include <avr/io.h>
#include <avr/sleep.h>

#include "avr/config.h"
#include "avr/motors.h"
#include "avr/qtr_rc.h"
#include "line_follower.h"

lf_state fw_state;
uint16_t fw_raw_us[LF_MAX_SENSORS];
int32_t fw_tick_mode;
volatile uint32_t fw_ticks_done;
volatile uint16_t fw_overruns;
static volatile uint8_t tick_due;
static uint16_t period;

ISR(TIMER1_COMPA_vect) {
  OCR1A += period;
  tick_due = 1;
}

int main(void) {
  lf_config c;
  uint8_t i;
  motors_init();
  if (!config_load(&c)) for (;;) {}
  qtr_init((uint8_t)c.params.count);
  lf_calibrate_reset(&fw_state, c.timeout_us);
  lf_reset(&fw_state, LF_CALIBRATE);
  period = (uint16_t)(c.params.dt_s * 2.5e6 + 0.5);
  TCCR1B = _BV(CS11);
  OCR1A = (uint16_t)(TCNT1 + period);
  TIMSK1 = _BV(OCIE1A);
  sei();
#if FAULT == 1
  for (;;) {}
#elif FAULT == 4
  cli();
  sleep_enable();
  sleep_cpu();
#endif
  for (;;) {
    while (!tick_due) {}
    tick_due = 0;
#if FAULT == 2
    PORTC |= 0x1F, PORTB |= 0x01, PORTD |= 0x14;
    DDRC |= 0x1F, DDRB |= 0x01, DDRD |= 0x14;
    for (i = 0; i < c.params.count; i++) fw_raw_us[i] = c.timeout_us;
#else
    (void)i;
    qtr_read(fw_raw_us, (uint8_t)c.params.count, c.timeout_us);
#endif
    fw_tick_mode = fw_state.mode;
    lf_step(&fw_state, &c.params, fw_raw_us);
#if FAULT != 3
    motors_set(fw_state.duty_left, fw_state.duty_right);
#endif
    fw_ticks_done++;
  }
}
