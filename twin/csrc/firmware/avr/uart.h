/* Telemetry out of the USART (PD1) at 115200 baud: lines are queued and sent by the data-register-empty
 * interrupt, so the control loop never waits for the wire. */
#ifndef LF_UART_H
#define LF_UART_H

#include <stdint.h>

#define LF_UART_QUEUE 192 /* bytes: two sample lines and a header, at 115200 baud the wire drains 57 B per 5 ms */

void uart_init(void);
/* Queue a whole line, or drop it (counted in uart_dropped) if the queue cannot take all of it. */
void uart_send(const char *line, uint8_t n);
extern volatile uint16_t uart_dropped;

#endif
