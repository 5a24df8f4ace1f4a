/* The robot's reaction time, as the twin's own firmware shows it on the MCU: per control tick, the cycles from the
 * tick (Timer1's compare A interrupt raised) to the release of the sensor lines (the readings' instant), and from the
 * end of the read (the last line's fall, or the timeout) to the first motor compare write (the new duties), the
 * latter also per code path the tick took (lf_compute_path). The C loop's timing model (timing.release,
 * timing.compute*: twin/csrc/sim/mujoco_glue.c) takes its defaults from these. A
 * tick is counted only when all three events came in that order within it; any other program's ticks are ignored. */
#include <simavr/sim_interrupts.h>

#include "avr_glue.h"

#define TICK_VECTOR 11 /* TIMER1_COMPA_vect_num (avr/iom328p.h): the firmware's control tick (avr/main.c) */

enum { WAIT_TICK, WAIT_RELEASE, WAIT_WRITE };

static void on_tick(struct avr_irq_t *irq, uint32_t value, void *param) {
  lf_avr *a = (lf_avr *)param;
  (void)irq;
  if (!value) return; /* the vector's pending line falls when the interrupt is taken */
  a->timing_tick = a->avr->cycle;
  a->timing_phase = WAIT_RELEASE;
}

void pil_connect_timing(lf_avr *a) {
  avr_irq_register_notify(avr_get_interrupt_irq(a->avr, TICK_VECTOR), on_tick, a);
}

/* Sensor lines released, one of which falls read_us later: the first release after a tick is the readings' instant;
 * the read ends when the last line released before the write has fallen (a calibration tick reads ten times). */
void pil_timing_release(lf_avr *a, double read_us) {
  uint64_t end = a->avr->cycle + cycles_of(a, read_us * 1e-6);
  if (a->timing_phase == WAIT_RELEASE) {
    a->timing_release = a->avr->cycle;
    a->timing_read_end = end;
    a->timing_phase = WAIT_WRITE;
  } else if (a->timing_phase == WAIT_WRITE && end > a->timing_read_end) {
    a->timing_read_end = end;
  }
}

void pil_timing_written(lf_avr *a) {
  lf_avr_status *st = &a->status;
  uint64_t release, compute;
  lf_state fw;
  int32_t path;
  if (a->timing_phase != WAIT_WRITE || a->avr->cycle < a->timing_read_end) return;
  a->timing_phase = WAIT_TICK;
  release = a->timing_release - a->timing_tick;
  compute = a->avr->cycle - a->timing_read_end;
  st->release_cycles_sum += release;
  if (release > st->release_cycles_max) st->release_cycles_max = release;
  st->compute_cycles_sum += compute;
  if (compute > st->compute_cycles_max) st->compute_cycles_max = compute;
  if (!st->timed_ticks || compute < st->compute_cycles_min) st->compute_cycles_min = compute;
  st->timed_ticks++;
  /* the tick's code path, from the state it just computed (lf_step has run when the duties are written) */
  if (lf_avr_state(a, &fw) == 0) {
    path = lf_compute_path(&fw);
    st->compute_path_cycles_sum[path] += compute;
    st->compute_path_ticks[path]++;
  }
}
