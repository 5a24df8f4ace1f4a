/* The register-level driver of board3pi.h. */
#include "board3pi.h"

#include <avr/interrupt.h>
#include <avr/io.h>
#include <util/delay.h>

#define LCD_B_MASK ((1 << 1) | (1 << 4) | (1 << 5)) /* DB4..DB6 on port B */
#define LCD_D7 (1 << 7)
#define LCD_RS (1 << 2) /* PD2 */
#define LCD_RW (1 << 0) /* PB0 */
#define LCD_E (1 << 4)  /* PD4 */

void delay_ms(uint16_t ms) {
  while (ms--) _delay_ms(1);
}

static void lcd_pulse(void) {
  PORTD |= LCD_E;
  _delay_us(1);
  PORTD &= ~LCD_E;
  _delay_us(1);
}

static void lcd_wait(void) {
  uint8_t ddrd = DDRD, busy;
  uint16_t guard = 0;
  DDRD &= ~LCD_D7;
  PORTD &= ~LCD_RS;
  PORTB |= LCD_RW;
  do {
    PORTD |= LCD_E;
    _delay_us(1);
    busy = PIND & LCD_D7;
    PORTD &= ~LCD_E;
    _delay_us(1);
    lcd_pulse(); /* the low nibble, unread */
  } while (busy && ++guard < 5000);
  DDRD = ddrd;
}

static void lcd_nibble(uint8_t n) {
  PORTB = (PORTB & ~LCD_B_MASK) | ((n & 1) << 1) | ((n & 6) << 3);
  PORTD = (PORTD & ~LCD_D7) | ((n & 8) << 4);
  lcd_pulse();
}

static void lcd_send(uint8_t byte, uint8_t rs, uint8_t nibbles) {
  uint8_t ddrb, portb, ddrd, portd;
  lcd_wait();
  ddrb = DDRB, portb = PORTB, ddrd = DDRD, portd = PORTD;
  PORTB &= ~LCD_RW;
  if (rs) PORTD |= LCD_RS;
  else PORTD &= ~LCD_RS;
  DDRB |= LCD_B_MASK;
  DDRD |= LCD_D7;
  if (nibbles == 2) lcd_nibble(byte >> 4);
  lcd_nibble(byte & 0x0f);
  DDRB = ddrb, PORTB = portb, DDRD = ddrd, PORTD = portd; /* the buttons and the green LED share these lines */
}

void lcd_command(uint8_t c) { lcd_send(c, 0, 2); }
void lcd_data(uint8_t c) { lcd_send(c, 1, 2); }

void lcd_init(void) {
  DDRD |= LCD_RS | LCD_E;
  DDRB |= LCD_RW;
  delay_ms(30);
  lcd_send(0x3, 0, 1); /* 8-bit function set, three times, then 4-bit */
  delay_ms(5);
  lcd_send(0x3, 0, 1);
  delay_ms(1);
  lcd_send(0x3, 0, 1);
  delay_ms(1);
  lcd_send(0x2, 0, 1);
  lcd_command(0x28); /* 4-bit, 2 lines */
  lcd_command(0x08);
  lcd_command(0x01);
  lcd_command(0x06);
  lcd_command(0x0c); /* display on */
}

void lcd_clear(void) { lcd_command(0x01); }
void lcd_goto(uint8_t col, uint8_t row) { lcd_command(0x80 | (row ? 0x40 : 0) | col); }

void lcd_print(const char *s) {
  while (*s) lcd_data((uint8_t)*s++);
}

void lcd_print_uint(uint16_t v) {
  char digits[6];
  uint8_t n = 0;
  do digits[n++] = (char)('0' + v % 10), v /= 10;
  while (v);
  while (n) lcd_data((uint8_t)digits[--n]);
}

uint8_t buttons_down(void) {
  DDRB &= ~(BUTTON_A | BUTTON_B | BUTTON_C);
  PORTB |= BUTTON_A | BUTTON_B | BUTTON_C;
  _delay_us(5);
  return (uint8_t)(~PINB & (BUTTON_A | BUTTON_B | BUTTON_C));
}

static void motors_init(void) {
  static uint8_t done;
  if (done) return;
  done = 1;
  TCCR0A = TCCR2A = 0xF3; /* inverted fast PWM on both outputs */
  TCCR0B = TCCR2B = 0x02; /* F_CPU / 8 */
  OCR0A = OCR0B = OCR2A = OCR2B = 0;
  DDRD |= (1 << 3) | (1 << 5) | (1 << 6);
  DDRB |= (1 << 3);
}

void motors_set(int16_t left, int16_t right) {
  uint8_t l = (uint8_t)(left < 0 ? (left < -255 ? 255 : -left) : (left > 255 ? 255 : left));
  uint8_t r = (uint8_t)(right < 0 ? (right < -255 ? 255 : -right) : (right > 255 ? 255 : right));
  motors_init();
  if (left < 0) OCR0B = 0, OCR0A = l;
  else OCR0A = 0, OCR0B = l;
  if (right < 0) OCR2B = 0, OCR2A = r;
  else OCR2A = 0, OCR2B = r;
}

void sensors_read(uint16_t *values, uint16_t timeout) {
  uint8_t i, last, now;
  uint16_t time = 0;
  motors_init(); /* Timer2 counts at 2.5 MHz */
  DDRC |= 1 << 5, PORTC |= 1 << 5; /* emitters on */
  _delay_us(200);
  for (i = 0; i < 5; i++) values[i] = 0;
  DDRC |= 0x1f, PORTC |= 0x1f;
  _delay_us(10);
  DDRC &= ~0x1f, PORTC &= ~0x1f;
  last = TCNT2;
  while (time < timeout) {
    now = TCNT2;
    time += (uint8_t)(now - last);
    last = now;
    for (i = 0; i < 5; i++)
      if (!values[i] && !(PINC & (1 << i))) values[i] = time ? time : 1;
  }
  for (i = 0; i < 5; i++)
    if (!values[i]) values[i] = timeout;
  PORTC &= ~(1 << 5); /* emitters off */
}

uint16_t adc_read(uint8_t channel) {
  ADMUX = 0x40 | (channel & 7); /* AVCC */
  ADCSRA = 0x87 | (1 << ADSC);
  while (ADCSRA & (1 << ADSC)) {
  }
  return ADC;
}

static volatile uint16_t overflows_left;

ISR(TIMER1_OVF_vect) {
  if (overflows_left && !--overflows_left) OCR1B = 0; /* silent */
}

void buzzer_play(uint16_t hz, uint16_t ms) {
  uint16_t top = (uint16_t)(10000000UL / hz); /* phase correct at F_CPU: f = F_CPU / (2 TOP) */
  DDRB |= 1 << 2;
  TIMSK1 = 0;
  TCCR1A = 0x23; /* OC1B non-inverting, WGM11:10 = 3 */
  TCCR1B = 0x11; /* WGM13 = 1: WGM 11, TOP = OCR1A; F_CPU / 1 */
  OCR1A = top;
  OCR1B = top >> 1;
  overflows_left = (uint16_t)((uint32_t)ms * hz / 1000);
  TIFR1 = 0xff;
  TIMSK1 = 1 << TOIE1;
  sei();
}

uint8_t buzzer_playing(void) {
  uint16_t left;
  cli();
  left = overflows_left;
  sei();
  return left != 0;
}
