/* QTR-RC read; pins in board_3pi.h. The decay is timed with Timer1 (free-running at 0.4 us per count, shared with
 * the control tick). Rather than poll the lines for up to the whole timeout (2.5 ms of a 5 ms tick at the Pololu
 * default), the CPU sleeps: a pin-change interrupt notes the count at which each line falls, and Timer1's compare
 * B ends the read at the timeout. The interrupt's latency (about 1 us) is the reading's resolution, as a polling
 * loop's pass would be. */
#include "qtr_rc.h"

#include <avr/interrupt.h>
#include <avr/io.h>
#include <avr/sleep.h>
#include <util/delay.h>

#include "../line_follower.h"
#include "board_3pi.h"

static const uint8_t pins[LF_BOARD_MAX_SENSORS][2] = LF_SENSOR_PINS;
static uint8_t mask[3];                    /* sensor lines per port: B, C, D */
static uint8_t sensors;                    /* sensors being read */
static volatile uint8_t high[3];           /* lines not yet fallen, per port */
static volatile uint8_t timed_out;
static volatile uint16_t start;            /* Timer1 count at the release */
static volatile uint16_t counts[LF_MAX_SENSORS];

void qtr_init(uint8_t count) {
  uint8_t i;
  sensors = count;
  mask[0] = mask[1] = mask[2] = 0;
  for (i = 0; i < count && i < LF_BOARD_MAX_SENSORS; i++) mask[pins[i][0]] |= (uint8_t)(1u << pins[i][1]);
  PCMSK0 = mask[0]; /* PCINT0..7 are PB0..7, PCINT8..14 PC0..6, PCINT16..23 PD0..7 */
  PCMSK1 = mask[1];
  PCMSK2 = mask[2];
  DDRC |= _BV(LF_EMITTER_BIT); /* emitters on for good: each read needs them, and the 3pi's are on a jumper */
  PORTC |= _BV(LF_EMITTER_BIT);
}

/* Note the lines that have fallen since last time. */
static void note_falls(void) {
  uint16_t elapsed = (uint16_t)(TCNT1 - start);
  uint8_t now[3], fell, i;
  now[0] = PINB & high[0];
  now[1] = PINC & high[1];
  now[2] = PIND & high[2];
  fell = (uint8_t)((now[0] ^ high[0]) | (now[1] ^ high[1]) | (now[2] ^ high[2]));
  if (!fell) return;
  for (i = 0; i < sensors; i++) {
    uint8_t port = pins[i][0], bit = (uint8_t)(1u << pins[i][1]);
    if ((high[port] & bit) && !(now[port] & bit)) counts[i] = elapsed;
  }
  high[0] = now[0];
  high[1] = now[1];
  high[2] = now[2];
}

ISR(PCINT0_vect) { note_falls(); }
ISR(PCINT1_vect, ISR_ALIASOF(PCINT0_vect));
ISR(PCINT2_vect, ISR_ALIASOF(PCINT0_vect));
ISR(TIMER1_COMPB_vect) {
  timed_out = 1;
  TIMSK1 &= (uint8_t)~_BV(OCIE1B);
}

void qtr_read(uint16_t *raw_us, uint8_t count, uint16_t timeout_us) {
  uint16_t limit = (uint16_t)(((uint32_t)timeout_us * 5u) / 2u);
  uint8_t i;
  for (i = 0; i < count; i++) counts[i] = limit;
  /* charge: drive every line high */
  PORTB |= mask[0];
  PORTC |= mask[1];
  PORTD |= mask[2];
  DDRB |= mask[0];
  DDRC |= mask[1];
  DDRD |= mask[2];
  _delay_us(10);
  /* release (inputs without pull-ups), start the clock, arm the timeout and the pin-change interrupts */
  cli();
  DDRB &= (uint8_t)~mask[0];
  DDRC &= (uint8_t)~mask[1];
  DDRD &= (uint8_t)~mask[2];
  PORTB &= (uint8_t)~mask[0];
  PORTC &= (uint8_t)~mask[1];
  PORTD &= (uint8_t)~mask[2];
  start = TCNT1;
  high[0] = mask[0];
  high[1] = mask[1];
  high[2] = mask[2];
  timed_out = 0;
  OCR1B = (uint16_t)(start + limit);
  TIFR1 = _BV(OCF1B);
  TIMSK1 |= _BV(OCIE1B);
  PCIFR = _BV(PCIF0) | _BV(PCIF1) | _BV(PCIF2);
  PCICR = _BV(PCIE0) | _BV(PCIE1) | _BV(PCIE2);
  note_falls(); /* a line that fell before the interrupts were armed */
  while ((high[0] | high[1] | high[2]) && !timed_out) { /* sleep between falls: wake-ups cannot be missed */
    sleep_enable();
    sei();
    sleep_cpu();
    sleep_disable();
    cli();
  }
  PCICR = 0;
  TIMSK1 &= (uint8_t)~_BV(OCIE1B);
  sei();
  for (i = 0; i < count; i++) raw_us[i] = (uint16_t)(((uint32_t)counts[i] * 2u) / 5u);
}
