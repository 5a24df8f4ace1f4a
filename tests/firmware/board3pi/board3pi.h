/* Test programs for the twin's model of the Pololu 3pi's board (tests/test_board.py): a small driver of the board's
 * registers written for these tests, driving the lines the way libpololu-avr does (the same pins, timers, modes and
 * protocols; none of its code), so that the board model is checked on what a 3pi program does to the MCU:
 *   LCD      HD44780 in 4-bit mode on DB4..DB7 = PB1, PB4, PB5, PD7, RS PD2, R/W PB0, E PD4; the busy flag polled;
 *            the lines shared with the buttons are restored after each byte
 *   buttons  A, B, C on PB1, PB4, PB5 with pull-ups, pressed = low
 *   motors   Timer0 (left: OC0A PD6, OC0B PD5) and Timer2 (right: OC2A PB3, OC2B PD3), inverted fast PWM at F_CPU/8/256
 *   sensors  QTR-RC on PC0..PC4: charged 10 us, released, timed on Timer2's count (0.4 us) up to a timeout; emitters PC5
 *   ADC      AVCC reference; ADC6 = 2/3 of the battery, ADC7 = the trimmer
 *   buzzer   Timer1 phase-correct PWM with TOP = OCR1A (WGM 11) on OC1B = PB2; the overflow interrupt times the note
 * (Pololu 3pi Robot User's Guide, section 9; ATmega328P datasheet.) */
#ifndef BOARD3PI_H
#define BOARD3PI_H

#include <stdint.h>

#define BUTTON_A (1 << 1)
#define BUTTON_B (1 << 4)
#define BUTTON_C (1 << 5)

void lcd_init(void);
void lcd_command(uint8_t c);
void lcd_data(uint8_t c);
void lcd_clear(void);
void lcd_goto(uint8_t col, uint8_t row);
void lcd_print(const char *s);
void lcd_print_uint(uint16_t v);
uint8_t buttons_down(void);            /* BUTTON_* bits held now */
void motors_set(int16_t left, int16_t right); /* -255..255 */
void sensors_read(uint16_t *values, uint16_t timeout); /* five readings in Timer2 counts (0.4 us) */
uint16_t adc_read(uint8_t channel);    /* 0..1023 */
void buzzer_play(uint16_t hz, uint16_t ms); /* returns at once; buzzer_playing() until the note ends */
uint8_t buzzer_playing(void);
void delay_ms(uint16_t ms);

#endif
