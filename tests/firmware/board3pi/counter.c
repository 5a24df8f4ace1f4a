/* Rewrites the screen without pause, as a clock or a counter does: "pass" on the first line, the number of passes
 * on the second, never clearing and never waiting (tests/test_board.py: its screens are still seen). */
#include "board3pi.h"

int main(void) {
  uint16_t n = 0;
  lcd_init();
  for (;;) {
    lcd_goto(0, 0);
    lcd_print("pass");
    lcd_goto(0, 1);
    lcd_print_uint(n++);
  }
}
