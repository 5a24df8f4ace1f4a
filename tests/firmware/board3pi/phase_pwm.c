/* Timer1 in phase-correct PWM with TOP = ICR1 (WGM 10), clk/8, ICR1 = 10000: up 10000 counts and down 10000, a period
 * of 2 * 10000 * 8 cycles, 125 a second at 20 MHz (ATmega328P datasheet, Timer/Counter1, "Phase Correct PWM Mode").
 * OC1B (PB2, COM1B = 2: clear counting up, set counting down) at OCR1B = 2500 is high a quarter of each period, and
 * compare B matches twice a period; ICF1 comes at TOP, once (TOV1 at BOTTOM times board3pi.c's notes, so it is not
 * counted here). Counted over 400 ms with the LCD quiet (its byte writes restore PORTB), then shown screen by screen
 * (tests/test_board.py):
 *   "B<compare B interrupts>|P<PB2 pin changes>", "C<captures>|R<rises of PB2 read in the pin-change
 *   interrupt>", "U<highest TCNT1 in the compare interrupt>|D<lowest>", "W<writes to PORTB while counting>"
 * and before that two checks of the interrupt flags ("Reset and Interrupt Handling"): "L<Timer2 overflow interrupts
 * run when TOIE2 is set after the flag>|F<pin-change interrupts after the flag was cleared by writing a one, times
 * ten, plus those after it was left set>"; and after it Timer0's 8-bit phase-correct PWM (WGM 1, clk/64, TOP 255:
 * a period of 2 * 255 * 64 cycles, 612.7 Hz) with OCR0A = 64, COM0A = 2 on PD6, its pin timed by a pin-change
 * interrupt on Timer1's count (clk/8): "X<rises in 100 ms>|H<the last pulse's high time in Timer1 counts>" (high
 * for 2 * 64 * 64 cycles = 1024 counts). */
#include <avr/interrupt.h>
#include <avr/io.h>
#include <util/delay.h>

#include "board3pi.h"

static volatile uint16_t matches_b, changes, rises, captures, late, pin_irqs, tcnt_hi, tcnt_lo = 0xffff;
static volatile uint8_t writes;
static volatile uint16_t rises0, rose_at, high0;

ISR(TIMER1_COMPB_vect) {
  uint16_t n = TCNT1;
  matches_b++;
  if (n > tcnt_hi) tcnt_hi = n;
  if (n < tcnt_lo) tcnt_lo = n;
}
ISR(TIMER1_CAPT_vect) { captures++; }
ISR(TIMER2_OVF_vect) { late++; }
ISR(PCINT0_vect) {
  static uint8_t was;
  uint8_t now = PINB & (1 << PB2);
  pin_irqs++;
  if (now != was) changes++;
  if (now && !was) rises++;
  was = now;
}

ISR(PCINT2_vect) {
  uint16_t t = TCNT1;
  if (PIND & (1 << PD6)) {
    rises0++;
    rose_at = t;
  } else {
    high0 = t - rose_at;
  }
}

static void show(char a, uint16_t x, char b, uint16_t y) {
  char s[2] = {a, 0};
  lcd_clear();
  lcd_print(s);
  lcd_print_uint(x);
  lcd_goto(0, 1);
  s[0] = b;
  lcd_print(s);
  lcd_print_uint(y);
  delay_ms(200);
}

int main(void) {
  uint16_t f, g;
  lcd_init();
  /* a flag raised while its interrupt is masked runs the interrupt once it is enabled */
  TCCR2A = 0;
  TCCR2B = 1 << CS21; /* Timer2 normal mode, clk/8: an overflow every 2048 cycles */
  _delay_us(200);
  TCCR2B = 0;         /* stopped with TOV2 set */
  sei();
  TIMSK2 = 1 << TOIE2;
  _delay_us(10);
  TIMSK2 = 0;
  /* a flag cleared by writing a one to it does not interrupt; one left set does */
  DDRB |= 1 << PB2;
  PCMSK0 = 1 << PCINT2;
  PORTB |= 1 << PB2;
  PCIFR = 1 << PCIF0;
  PCICR = 1 << PCIE0;
  _delay_us(10);
  f = pin_irqs;
  PCICR = 0;
  PORTB &= ~(1 << PB2);
  PCICR = 1 << PCIE0;
  _delay_us(10);
  g = pin_irqs - f;
  show('L', late, 'F', f * 10 + g);
  /* Timer1 phase-correct, the clock started before ICR1 is set (as OrangutanServos does) */
  pin_irqs = 0;
  TCCR1A = (1 << COM1B1) | (1 << WGM11);
  TCCR1B = (1 << WGM13) | (1 << CS11);
  ICR1 = 10000;
  OCR1B = 2500;
  TIFR1 = 0xff;
  TIMSK1 = (1 << OCIE1B) | (1 << ICIE1);
  delay_ms(400);
  for (writes = 0; writes < 50; writes++) { /* a program's writes to PORTB leave the pin to the compare output */
    PORTB ^= 1 << PB0;
    _delay_us(100);
  }
  cli();
  TCCR1B = 0;
  show('B', matches_b, 'P', changes);
  show('C', captures, 'R', rises);
  show('U', tcnt_hi, 'D', tcnt_lo);
  show('W', writes, ' ', 0);
  /* Timer0, 8-bit phase-correct PWM on OC0A (PD6, the left motor's line) */
  TCCR1A = 0;
  TCCR1B = 1 << CS11; /* a free-running count at clk/8 to time the pin */
  DDRD |= 1 << PD6;
  PCMSK2 = 1 << PCINT22;
  PCICR = 1 << PCIE2;
  OCR0A = 64;
  TCCR0A = (1 << COM0A1) | (1 << WGM00);
  TCCR0B = (1 << CS01) | (1 << CS00);
  sei();
  delay_ms(100);
  cli();
  TCCR0B = 0;
  show('X', rises0, 'H', high0);
  for (;;) {
  }
}
