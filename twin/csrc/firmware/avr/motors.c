#include "motors.h"

#include <avr/io.h>

void motors_init(void) {
  TCCR0A = TCCR2A = 0xF3; /* COMxA = COMxB = 11 (inverted: set on compare match, clear at BOTTOM), WGM 3: fast PWM */
  TCCR0B = TCCR2B = 0x02; /* clock F_CPU / 8: a 256-count PWM period of 102.4 us */
  OCR0A = OCR0B = OCR2A = OCR2B = 0;
  DDRD |= _BV(PD3) | _BV(PD5) | _BV(PD6);
  DDRB |= _BV(PB3);
}

/* Compare value for a duty: the line is driven for OCR of the 256 counts of a period, so OCR = 256 |duty|, up to 255
 * (full duty drives 255/256 of the time; Pololu's library maps 255 to full, which drives every duty 0.4 % short). */
static uint8_t speed_of(lf_real duty) {
  lf_real counts = (duty < 0 ? -duty : duty) * 256.0 + 0.5;
  if (!(counts < 255.0)) return 255; /* also NaN: the firmware never commands one, but saturate, not wrap */
  return (uint8_t)counts;
}

void motors_set(lf_real left, lf_real right) {
  uint8_t l = speed_of(left), r = speed_of(right);
  if (left < 0) OCR0B = 0, OCR0A = l; /* reverse: line A pulses, line B held */
  else OCR0A = 0, OCR0B = l;          /* forward */
  if (right < 0) OCR2B = 0, OCR2A = r;
  else OCR2A = 0, OCR2B = r;
}
