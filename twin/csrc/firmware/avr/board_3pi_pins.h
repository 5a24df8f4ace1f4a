/* The 3pi's pin map as numbers, shared by the firmware (board_3pi.h) and the twin's processor-in-the-loop glue
 * (twin/csrc/pil), which must drive the same lines the firmware reads. Source and wiring: board_3pi.h; the board's
 * other parts from Pololu's 3pi Robot User's Guide, section 9 (Pin Assignment Tables), as libpololu-avr drives them
 * (src/OrangutanLCD/OrangutanLCD.h, src/OrangutanPushbuttons/OrangutanPushbuttons.h, src/OrangutanLEDs/OrangutanLEDs.h,
 * src/OrangutanBuzzer/OrangutanBuzzer.cpp, src/OrangutanAnalog/OrangutanAnalog.cpp). */
#ifndef LF_BOARD_3PI_PINS_H
#define LF_BOARD_3PI_PINS_H

#define LF_BOARD_MAX_SENSORS 8
#define LF_PORT_B 0
#define LF_PORT_C 1
#define LF_PORT_D 2
/* sensor i: {port, bit}, left to right: PC0..PC4, then PB0, PD2, PD4 (the LCD's control lines) */
#define LF_SENSOR_PINS \
  {{LF_PORT_C, 0}, {LF_PORT_C, 1}, {LF_PORT_C, 2}, {LF_PORT_C, 3}, {LF_PORT_C, 4}, {LF_PORT_B, 0}, {LF_PORT_D, 2}, {LF_PORT_D, 4}}
#define LF_BOARD_SENSORS 5 /* the 3pi's own: PC0..PC4; more take the LCD's control lines (LCD unplugged) */
#define LF_EMITTER_PORT LF_PORT_C
#define LF_EMITTER_PIN 5  /* PC5 */
#define LF_BUTTON_B_PORT LF_PORT_B
#define LF_BUTTON_B_PIN 4 /* PB4 */

/* pushbuttons A, B, C (left to right) on PB1, PB4, PB5: pressed connects the line to ground through 1 kOhm against
 * the MCU's pull-up (User's Guide, section 5.d) */
#define LF_BUTTON_PINS {1, 4, 5}
/* the 8x2 HD44780 LCD in 4-bit mode: DB4..DB7 on PB1, PB4, PB5, PD7 (shared with buttons A, B, C and the green LED);
 * RS on PD2, R/W on PB0, E on PD4 */
#define LF_LCD_DATA_PINS {{LF_PORT_B, 1}, {LF_PORT_B, 4}, {LF_PORT_B, 5}, {LF_PORT_D, 7}}
#define LF_LCD_RS_PIN 2 /* PD2 */
#define LF_LCD_RW_PIN 0 /* PB0 */
#define LF_LCD_E_PIN 4  /* PD4 */
/* user LEDs, lit when driven high: red (left) on PD1 (also the UART's TX), green (right) on PD7 */
#define LF_LED_RED_PIN 1   /* PD1 */
#define LF_LED_GREEN_PIN 7 /* PD7 */
/* the buzzer on PB2 (OC1B): Timer1's PWM */
#define LF_BUZZER_PIN 2 /* PB2 */
/* ADC6: 2/3 of the battery voltage; ADC7: the user trimmer potentiometer (both through jumpers); AVCC = 5 V */
#define LF_ADC_BATTERY 6
#define LF_ADC_TRIMMER 7
#define LF_VCC_MV 5000

#endif
