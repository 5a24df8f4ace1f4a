/* Writes garbage on the LCD's lines (random levels and directions, E toggling, reads and writes mixed); never drives
 * (tests/test_board.py). */
#include <avr/io.h>
#include <stdint.h>

int main(void) {
  uint16_t x = 0xace1u;
  for (;;) {
    x = (uint16_t)((x >> 1) ^ (-(x & 1u) & 0xb400u)); /* 16-bit Galois LFSR */
    DDRB = (uint8_t)((DDRB & ~0x33) | (x & 0x33));
    PORTB = (uint8_t)((PORTB & ~0x33) | ((x >> 4) & 0x33));
    DDRD = (uint8_t)((DDRD & ~0x94) | ((x >> 2) & 0x94));
    PORTD = (uint8_t)((PORTD & ~0x94) | ((x >> 8) & 0x94));
  }
}
