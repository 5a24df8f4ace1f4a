/* A proportional line follower: shows "Press B", waits for B, then steers on the sensors' weighted position
 * (tests/test_board.py). */
#include "board3pi.h"

int main(void) {
  uint16_t s[5];
  lcd_init();
  lcd_print("Press B");
  while (!(buttons_down() & BUTTON_B)) delay_ms(20);
  while (buttons_down() & BUTTON_B) delay_ms(20);
  lcd_clear();
  lcd_print("Go!");
  for (;;) {
    int32_t sum = 0, weighted = 0, error;
    uint8_t i;
    sensors_read(s, 2000);
    for (i = 0; i < 5; i++) {
      int32_t dark = s[i] > 150 ? s[i] - 150 : 0; /* white reads ~100 counts, the line ~1500 */
      sum += dark;
      weighted += dark * (int32_t)i * 1000;
    }
    error = sum ? weighted / sum - 2000 : 0;
    motors_set((int16_t)(90 + error / 25), (int16_t)(90 - error / 25));
  }
}
