/* Turns on peripherals the board model does not connect (SPI, the UART's receiver, a conversion of ADC3) and the
 * UART's transmitter, then waits for ever (tests/test_board.py). */
#include <avr/io.h>

int main(void) {
  SPCR = (1 << SPE) | (1 << MSTR);
  UCSR0B = (1 << RXEN0) | (1 << TXEN0);
  ADMUX = 0x40 | 3;
  ADCSRA = (1 << ADEN) | (1 << ADSC) | 7;
  for (;;) {
  }
}
