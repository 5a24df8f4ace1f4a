/* A left-hand-on-the-wall line-maze solver: follow a segment until an intersection, a dead end or the finish spot,
 * then turn left if it can, else go straight, else right, else back (tests/test_board.py). Readings are raw Timer2
 * counts: white ground ~100, the line ~1500 (two seconds' worth of 0.4 us counts is the timeout). */
#include "board3pi.h"

#define DARK(v) ((v) > 700)

static uint16_t s[5];

static uint8_t follow(void) { /* returns 1 at an intersection or a dead end */
  for (;;) {
    int32_t sum = 0, weighted = 0, error;
    uint8_t i;
    sensors_read(s, 2000);
    if (!DARK(s[1]) && !DARK(s[2]) && !DARK(s[3])) return 1;
    if (DARK(s[0]) || DARK(s[4])) return 1;
    for (i = 0; i < 5; i++) {
      int32_t dark = s[i] > 150 ? s[i] - 150 : 0;
      sum += dark;
      weighted += dark * (int32_t)i * 1000;
    }
    error = sum ? weighted / sum - 2000 : 0;
    if (error > 60 * 20) error = 60 * 20;
    if (error < -60 * 20) error = -60 * 20;
    motors_set((int16_t)(60 + error / 20), (int16_t)(60 - error / 20));
  }
}

static void turn(char dir) {
  if (dir == 'L') motors_set(-80, 80), delay_ms(200);
  if (dir == 'R') motors_set(80, -80), delay_ms(200);
  if (dir == 'B') motors_set(80, -80), delay_ms(400);
}

int main(void) {
  lcd_init();
  lcd_print("Press B");
  while (!(buttons_down() & BUTTON_B)) delay_ms(20);
  while (buttons_down() & BUTTON_B) delay_ms(20);
  delay_ms(500);
  for (;;) {
    uint8_t left, right, straight;
    follow();
    motors_set(50, 50);
    delay_ms(50);
    sensors_read(s, 2000);
    left = DARK(s[0]), right = DARK(s[4]);
    motors_set(40, 40);
    delay_ms(200);
    sensors_read(s, 2000);
    straight = DARK(s[1]) || DARK(s[2]) || DARK(s[3]);
    if (DARK(s[1]) && DARK(s[2]) && DARK(s[3])) break; /* the finish spot */
    turn(left ? 'L' : straight ? 'S' : right ? 'R' : 'B');
  }
  motors_set(0, 0);
  lcd_clear();
  lcd_print("Finish!");
  buzzer_play(880, 300);
  for (;;) {
  }
}
