/* Asks for button A, then C, and says what it saw (tests/test_board.py). */
#include "board3pi.h"

static void wait_for(uint8_t button, const char *prompt, const char *seen) {
  lcd_clear();
  lcd_print(prompt);
  while (!(buttons_down() & button)) delay_ms(20);
  while (buttons_down() & button) delay_ms(20);
  lcd_clear();
  lcd_print(seen);
  delay_ms(300);
}

int main(void) {
  lcd_init();
  wait_for(BUTTON_A, "Press A", "A seen");
  wait_for(BUTTON_C, "Press C", "C seen");
  lcd_clear();
  lcd_print("done");
  for (;;) {
  }
}
