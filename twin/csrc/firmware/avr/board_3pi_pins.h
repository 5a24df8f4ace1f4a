/* The 3pi's pin map as numbers, shared by the firmware (board_3pi.h) and the twin's processor-in-the-loop glue
 * (twin/csrc/pil), which must drive the same lines the firmware reads. Source and wiring: board_3pi.h. */
#ifndef LF_BOARD_3PI_PINS_H
#define LF_BOARD_3PI_PINS_H

#define LF_BOARD_MAX_SENSORS 8
#define LF_PORT_B 0
#define LF_PORT_C 1
#define LF_PORT_D 2
/* sensor i: {port, bit}, left to right: PC0..PC4, then PB0, PD2, PD4 (the LCD's control lines) */
#define LF_SENSOR_PINS \
  {{LF_PORT_C, 0}, {LF_PORT_C, 1}, {LF_PORT_C, 2}, {LF_PORT_C, 3}, {LF_PORT_C, 4}, {LF_PORT_B, 0}, {LF_PORT_D, 2}, {LF_PORT_D, 4}}
#define LF_EMITTER_PORT LF_PORT_C
#define LF_EMITTER_PIN 5  /* PC5 */
#define LF_BUTTON_B_PORT LF_PORT_B
#define LF_BUTTON_B_PIN 4 /* PB4 */

#endif
