/* QTR-RC reflectance sensors read on GPIO, as Pololu's QTRSensors library does (RC mode): charge each sensor's
 * capacitor by driving its line high for 10 us, release it, and time how long the line takes to fall. */
#ifndef LF_QTR_RC_H
#define LF_QTR_RC_H

#include <stdint.h>

/* Largest read timeout: Timer1's 16-bit count at 0.4 us per count. */
#define LF_QTR_TIMEOUT_MAX_US 26000u

void qtr_init(uint8_t count);
/* raw_us[i]: discharge time of sensor i [us], timeout_us where the line has not fallen by then. */
void qtr_read(uint16_t *raw_us, uint8_t count, uint16_t timeout_us);

#endif
