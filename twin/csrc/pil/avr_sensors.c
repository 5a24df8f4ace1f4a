/* The board's QTR-RC sensor lines. The firmware drives a line high, then releases it (its DDR bit cleared): the line's
 * decay time is the twin's sensor physics for that sensor at that moment (lf_read_sensor_at, the same code and noise
 * stream as the C callback), and a simavr cycle timer pulls the line low that many microseconds later. */
#include <simavr/avr_ioport.h>
#include <simavr/sim_cycle_timers.h>
#include <simavr/sim_io.h>
#include <simavr/sim_irq.h>

#include "avr_glue.h"

static avr_cycle_count_t line_falls(avr_t *avr, avr_cycle_count_t when, void *param) {
  sensor_ref *r = (sensor_ref *)param;
  (void)when;
  avr_raise_irq(avr_io_getirq(avr, AVR_IOCTL_IOPORT_GETIRQ(name_of[sensor_pins[r->index][0]]), sensor_pins[r->index][1]), 0);
  return 0;
}

/* Whether sensor i's site has a pose (mj_step1 or mj_forward ran): mj_ray stops the process on a zero direction. */
static int kinematics_ready(const lf_avr *a, int32_t i) {
  const mjtNum *xmat = a->d->site_xmat + 9 * a->s->sensor_site[i];
  return xmat[2] * xmat[2] + xmat[5] * xmat[5] + xmat[8] * xmat[8] > 0.5;
}

/* DDR written: a sensor line that was driven high and is now an input starts to decay. */
static void on_direction(struct avr_irq_t *irq, uint32_t value, void *param) {
  lf_avr *a = (lf_avr *)param;
  int port = -1, i;
  uint8_t before;
  for (i = 0; i < 3; i++)
    if (irq == avr_io_getirq(a->avr, AVR_IOCTL_IOPORT_GETIRQ(name_of[i]), IOPORT_IRQ_DIRECTION_ALL)) port = i;
  if (port < 0) return;
  before = a->ddr_seen[port];
  a->ddr_seen[port] = (uint8_t)value;
  if (port != LF_PORT_C) pil_motor_direction(a, port, (uint8_t)value); /* a motor line may have changed direction */
  if (port == LF_PORT_D) pil_led_update(a);                              /* and an LED's line */
  for (i = 0; i < a->nsensor; i++) {
    uint8_t bit = (uint8_t)(1u << sensor_pins[i][1]);
    double raw_us;
    if (sensor_pins[i][0] != port || !(before & bit) || (value & bit)) continue;
    a->released[i] = a->board.last_release = a->avr->cycle;
    avr_cycle_timer_cancel(a->avr, line_falls, &a->refs[i]);
    if (!(reg(a, port_of[port]) & bit)) continue; /* released low: nothing was charged, the line stays low */
    if (!a->s || !kinematics_ready(a, i)) { /* no physics attached, or not yet stepped: a dark floor */
      raw_us = a->s ? a->s->sensor.timeout_us : 2500.0;
    } else {
      /* the physics is at the start of the step that holds this cycle: the sensor is read where it is now */
      double ahead_s = ((double)a->avr->cycle - (double)a->zero_cycle) / a->f_cpu - a->d->time;
      double height = lf_read_sensor_at(a->m, a->d, a->s, i, ahead_s, a->reads[i]++);
      int emitters = (reg(a, ddr_of[LF_EMITTER_PORT]) >> LF_EMITTER_PIN) & (reg(a, port_of[LF_EMITTER_PORT]) >> LF_EMITTER_PIN) & 1;
      if (i == 0) a->height0 = height;
      raw_us = emitters ? a->s->raw[i] : a->s->sensor.timeout_us; /* emitters off: no light comes back */
    }
    a->physics_prev_us[i] = a->physics_us[i];
    a->physics_us[i] = raw_us;
    pil_timing_release(a, raw_us);
    avr_cycle_timer_register(a->avr, (avr_cycle_count_t)(raw_us * a->f_cpu / 1e6 + 0.5), line_falls, &a->refs[i]);
  }
}

void pil_connect_sensors(lf_avr *a) {
  int i;
  for (i = 0; i < 3; i++)
    avr_irq_register_notify(avr_io_getirq(a->avr, AVR_IOCTL_IOPORT_GETIRQ(name_of[i]), IOPORT_IRQ_DIRECTION_ALL),
                            on_direction, a);
}
