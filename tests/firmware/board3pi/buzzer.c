/* Plays 440 Hz for 250 ms, a 100 ms pause, then 1000 Hz for 100 ms (tests/test_board.py). */
#include "board3pi.h"

int main(void) {
  delay_ms(50);
  buzzer_play(440, 250);
  while (buzzer_playing()) {
  }
  delay_ms(100);
  buzzer_play(1000, 100);
  while (buzzer_playing()) {
  }
  lcd_init();
  lcd_print("done");
  for (;;) {
  }
}
