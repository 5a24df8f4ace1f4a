/* Timer1 in fast PWM with TOP = ICR1 (WGM 14), started before ICR1 is set, as libpololu-avr's OrangutanServos starts
 * it: clk/8 and ICR1 = 9999 give a period of 8 * 10000 cycles, 250 Hz at 20 MHz (ATmega328P datasheet 15.9.3), with a
 * compare match A (OCR1A = 5000) and an input-capture flag at TOP in each. Shows the matches ("m") and the captures
 * ("c") counted over 400 ms (tests/test_board.py). */
#include <avr/interrupt.h>
#include <avr/io.h>

#include "board3pi.h"

static volatile uint16_t matches, captures;

ISR(TIMER1_COMPA_vect) { matches++; }
ISR(TIMER1_CAPT_vect) { captures++; }

int main(void) {
  uint16_t m, c;
  lcd_init();
  TCCR1A = 1 << WGM11;
  TCCR1B = (1 << WGM13) | (1 << WGM12) | (1 << CS11); /* the clock runs before TOP is set */
  ICR1 = 9999;
  OCR1A = 5000;
  TIMSK1 = (1 << OCIE1A) | (1 << ICIE1);
  sei();
  delay_ms(400);
  cli();
  m = matches, c = captures;
  lcd_print("m");
  lcd_print_uint(m);
  lcd_goto(0, 1);
  lcd_print("c");
  lcd_print_uint(c);
  for (;;) {
  }
}
