/* The Pololu 3pi robot (original edition: ATmega328P at 20 MHz) as this firmware drives it.
 *
 * Pin map from Pololu's "3pi Robot User's Guide", section 9, Pin Assignment Tables (https://www.pololu.com/docs/0J21/9):
 *   motor 1 (left) control A, B  PD6 (OC0A), PD5 (OC0B)      motor 2 (right) control A, B  PB3 (OC2A), PD3 (OC2B)
 *   QTR-RC reflectance sensors, left to right  PC0..PC4       IR emitters of the sensors  PC5 (drive low: off)
 *   UART RX, TX  PD0, PD1                                     pushbuttons A, B, C  PB1, PB4, PB5 (pressed: low)
 *   LCD control RS, R/W, E  PD2, PB0, PD4
 * The 3pi carries five sensors. An array of up to eight (the twin's default robot has a QTR-8RC) takes PC0..PC4
 * for its first five and the LCD's three control lines, free with the LCD unplugged, for the rest: sensor 5 on
 * PB0, 6 on PD2, 7 on PD4, wired left to right.
 *
 * Motor drive as Pololu's OrangutanMotors (libpololu-avr, src/OrangutanMotors/OrangutanMotors.cpp): both control
 * lines of a motor on one 8-bit timer in inverted fast PWM (set on compare match, clear at BOTTOM) at
 * F_CPU / 8 / 256 = 9.8 kHz; forward drives line B's compare value with line A's at 0, reverse the other way.
 */
#ifndef LF_BOARD_3PI_H
#define LF_BOARD_3PI_H

#include <avr/io.h>

#include "board_3pi_pins.h"

#define LF_BOARD_NAME "pololu-3pi-atmega328p"
#define LF_TIMER1_PRESCALE 8u       /* Timer1 counts at F_CPU / 8 = 2.5 MHz: 0.4 us per count */
#define LF_UART_BAUD 115200UL
#define LF_EMITTER_BIT LF_EMITTER_PIN  /* on PORTC */
#define LF_BUTTON_B_BIT LF_BUTTON_B_PIN /* on PORTB: the 3pi's middle button, "press B to start" */

#endif
