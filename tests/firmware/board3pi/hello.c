/* Writes two screens, then the battery and trimmer readings; never drives (tests/test_board.py). */
#include "board3pi.h"

int main(void) {
  uint16_t battery_mv, trimmer;
  lcd_init();
  lcd_print("Hello");
  lcd_goto(0, 1);
  lcd_print("twin 3pi");
  delay_ms(300);
  battery_mv = (uint16_t)((uint32_t)adc_read(6) * 5000 / 1023 * 3 / 2); /* ADC6 sees 2/3 of the battery */
  trimmer = adc_read(7);
  lcd_clear();
  lcd_print_uint(battery_mv);
  lcd_print("mV");
  lcd_goto(0, 1);
  lcd_print("t");
  lcd_print_uint(trimmer);
  for (;;) {
  }
}
