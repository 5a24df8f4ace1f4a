/* Drives both motors at LEFT and RIGHT (-255..255) after a short pause, for ever (tests/test_board.py). */
#include "board3pi.h"

int main(void) {
  delay_ms(100);
  motors_set(LEFT, RIGHT);
  for (;;) {
  }
}
