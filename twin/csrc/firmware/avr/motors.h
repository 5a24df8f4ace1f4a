/* The 3pi's two motors on Timer0 (left) and Timer2 (right), as Pololu's OrangutanMotors drives them. */
#ifndef LF_MOTORS_H
#define LF_MOTORS_H

#include "../line_follower.h"

void motors_init(void);
/* duty in [-1, 1], > 0 forward; |duty| is rounded to the 8-bit PWM's 1/256 steps, at most 255/256 */
void motors_set(lf_real left, lf_real right);

#endif
