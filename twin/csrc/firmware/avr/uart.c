#include "uart.h"

#include <avr/interrupt.h>
#include <avr/io.h>

#include "board_3pi.h"

static volatile uint8_t queue[LF_UART_QUEUE];
static volatile uint8_t head, tail; /* written by the loop, read by the interrupt; bytes in queue[tail..head) */
volatile uint16_t uart_dropped;

void uart_init(void) {
  /* double speed: UBRR = F_CPU / (8 baud) - 1 = 20.7 -> 21, 113.6 kbaud (-1.4 %, within the USART's tolerance) */
  UBRR0 = (uint16_t)((F_CPU + 4UL * LF_UART_BAUD) / (8UL * LF_UART_BAUD) - 1UL);
  UCSR0A = _BV(U2X0);
  UCSR0B = _BV(TXEN0);
  UCSR0C = _BV(UCSZ01) | _BV(UCSZ00); /* 8N1 */
}

static uint8_t free_space(void) {
  uint8_t used = (uint8_t)((head + LF_UART_QUEUE - tail) % LF_UART_QUEUE);
  return (uint8_t)(LF_UART_QUEUE - 1 - used);
}

void uart_send(const char *line, uint8_t n) {
  uint8_t i;
  if (n > free_space()) {
    uart_dropped++;
    return;
  }
  for (i = 0; i < n; i++) {
    queue[head] = (uint8_t)line[i];
    head = (uint8_t)((head + 1) % LF_UART_QUEUE);
  }
  UCSR0B |= _BV(UDRIE0);
}

ISR(USART_UDRE_vect) {
  if (tail == head) {
    UCSR0B &= (uint8_t)~_BV(UDRIE0);
    return;
  }
  UDR0 = queue[tail];
  tail = (uint8_t)((tail + 1) % LF_UART_QUEUE);
}
