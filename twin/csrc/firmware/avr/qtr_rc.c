/* QTR-RC read; pins in board_3pi.h. The decay is timed with Timer1 (free-running at 0.4 us per count, shared with
 * the control tick). Rather than poll the lines for up to the whole timeout (2.5 ms of a 5 ms tick at the Pololu
 * default), the CPU sleeps: a pin-change interrupt notes the count and the ports when lines fall, and Timer1's
 * compare B ends the read at the timeout. The interrupt's latency (a few us) is the reading's resolution, as a
 * polling loop's pass would be. */
#include "qtr_rc.h"

#include <avr/interrupt.h>
#include <avr/io.h>
#include <avr/sleep.h>
#include <util/delay.h>

#include "../line_follower.h"
#include "board_3pi.h"

static const uint8_t pins[LF_BOARD_MAX_SENSORS][2] = LF_SENSOR_PINS;
static uint8_t mask[3];  /* sensor lines per port: B, C, D */
static uint16_t start;   /* Timer1 count at the release */
/* What each pin-change interrupt saw, kept short so that lines falling close together are timed close to when
 * they fell (an interrupt that decoded the lines itself would hold the next one back by ~10 us): the count, then
 * the three ports. Every line falls once per read, so there are at most as many events as sensors. */
static volatile uint8_t events;
static volatile uint16_t event_count[LF_BOARD_MAX_SENSORS];
static volatile uint8_t event_port[LF_BOARD_MAX_SENSORS][3];
static volatile uint8_t timed_out;

void qtr_init(uint8_t count) {
  uint8_t i;
  mask[0] = mask[1] = mask[2] = 0;
  for (i = 0; i < count && i < LF_BOARD_MAX_SENSORS; i++) mask[pins[i][0]] |= (uint8_t)(1u << pins[i][1]);
  PCMSK0 = mask[0]; /* PCINT0..7 are PB0..7, PCINT8..14 PC0..6, PCINT16..23 PD0..7 */
  PCMSK1 = mask[1];
  PCMSK2 = mask[2];
  DDRC |= _BV(LF_EMITTER_BIT); /* emitters on for good: each read needs them, and the 3pi's are on a jumper */
  PORTC |= _BV(LF_EMITTER_BIT);
}

ISR(PCINT0_vect) {
  uint16_t now = TCNT1;
  uint8_t k = events;
  if (k < LF_BOARD_MAX_SENSORS) {
    event_count[k] = now;
    event_port[k][0] = PINB;
    event_port[k][1] = PINC;
    event_port[k][2] = PIND;
    events = (uint8_t)(k + 1);
  }
}
ISR(PCINT1_vect, ISR_ALIASOF(PCINT0_vect));
ISR(PCINT2_vect, ISR_ALIASOF(PCINT0_vect));
ISR(TIMER1_COMPB_vect) {
  timed_out = 1;
  TIMSK1 &= (uint8_t)~_BV(OCIE1B);
}

/* Lines of mask still high in the last event (all of them before the first). */
static uint8_t still_high(void) {
  uint8_t k = events;
  if (!k) return 1;
  k--;
  return (uint8_t)((event_port[k][0] & mask[0]) | (event_port[k][1] & mask[1]) | (event_port[k][2] & mask[2]));
}

void qtr_read(uint16_t *raw_us, uint8_t count, uint16_t timeout_us) {
  uint16_t limit = (uint16_t)(((uint32_t)timeout_us * 5u) / 2u), counts[LF_MAX_SENSORS];
  uint8_t high[3], i, k;
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
  events = 0;
  timed_out = 0;
  OCR1B = (uint16_t)(start + limit);
  TIFR1 = _BV(OCF1B);
  TIMSK1 |= _BV(OCIE1B);
  PCIFR = _BV(PCIF0) | _BV(PCIF1) | _BV(PCIF2);
  PCICR = _BV(PCIE0) | _BV(PCIE1) | _BV(PCIE2);
  /* a line that fell before the interrupts were armed: an event of its own, at the release */
  if ((PINB & mask[0]) != mask[0] || (PINC & mask[1]) != mask[1] || (PIND & mask[2]) != mask[2]) {
    event_count[0] = start, event_port[0][0] = PINB, event_port[0][1] = PINC, event_port[0][2] = PIND;
    events = 1;
  }
  while (still_high() && !timed_out && events < LF_BOARD_MAX_SENSORS) { /* sleep between falls */
    sleep_enable();
    sei();
    sleep_cpu();
    sleep_disable();
    cli();
  }
  PCICR = 0;
  TIMSK1 &= (uint8_t)~_BV(OCIE1B);
  sei();
  /* decode: a line's reading is the count of the first event that saw it low, else the timeout */
  high[0] = mask[0], high[1] = mask[1], high[2] = mask[2];
  for (i = 0; i < count; i++) counts[i] = limit;
  for (k = 0; k < events; k++) {
    uint16_t elapsed = (uint16_t)(event_count[k] - start);
    if (elapsed >= limit) break;
    for (i = 0; i < count; i++) {
      uint8_t port = pins[i][0], bit = (uint8_t)(1u << pins[i][1]);
      if ((high[port] & bit) && !(event_port[k][port] & bit)) counts[i] = elapsed, high[port] &= (uint8_t)~bit;
    }
  }
  for (i = 0; i < count; i++) { /* counts of 0.4 us to us: 2c/5 = 2q + 2r/5 for c = 5q + r, in 16 bits (a 32-bit
                                 * division costs the AVR ~600 cycles, a 16-bit one ~200) */
    uint16_t q = counts[i] / 5u, r = counts[i] % 5u;
    raw_us[i] = (uint16_t)(2u * q + (2u * r) / 5u);
  }
}
