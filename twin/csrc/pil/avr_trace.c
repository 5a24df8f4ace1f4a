/* What the glue reads back from the MCU. A tick the twin's own firmware finished (its fw_ticks_done counter moved) is traced into
 * the head's ring from the firmware's own RAM (fw_state, fw_raw_us, fw_tick_mode, found by their ELF symbols), with
 * the CPU cycles spent awake since the previous tick. The UART's bytes are kept for Python to drain: they are the
 * robot's telemetry. */
#include <math.h>
#include <string.h>

#include <simavr/avr_uart.h>
#include <simavr/sim_io.h>
#include <simavr/sim_irq.h>

#include "avr_glue.h"

/* The firmware's lf_state, widened to the host's (doubles). */
int32_t lf_avr_state(const lf_avr *a, lf_state *out) {
  avr_lf_state st;
  if (!a->a_state) return -1;
  memcpy(&st, a->avr->data + a->a_state, sizeof st);
  memcpy(out->cal_min, st.cal_min, sizeof st.cal_min);
  memcpy(out->cal_max, st.cal_max, sizeof st.cal_max);
  memcpy(out->value, st.value, sizeof st.value);
  out->position = st.position, out->last_position = st.last_position, out->line_seen = st.line_seen;
  out->mode = st.mode, out->tick = st.tick;
  out->e = st.e, out->e_prev = st.e_prev, out->integral = st.integral, out->v = st.v, out->omega = st.omega;
  out->duty_left = st.duty_left, out->duty_right = st.duty_right;
  memcpy(out->call_min, st.call_min, sizeof st.call_min);
  memcpy(out->call_max, st.call_max, sizeof st.call_max);
  out->call_reads = st.call_reads;
  return 0;
}

/* A tick the firmware finished: trace it from its RAM, count its awake cycles. The tick's counter went up within the
 * step that began at step_from_cycle; a line released in that step belongs to the next read (a read and its
 * compute take over 1.2 ms, so the tick's own read began in an earlier step): the reading the tick holds is the
 * release before (the calibration's overrunning ticks start their next read at once). */
static void record_tick(lf_avr *a, uint64_t step_from_cycle) {
  uint16_t raw[LF_MAX_SENSORS];
  int32_t mode;
  uint64_t busy = a->busy - a->busy_tick_start;
  int i;
  a->busy_tick_start = a->busy;
  a->tick_cycle = a->avr->cycle;
  if (busy > a->status.busy_max) a->status.busy_max = busy;
  a->status.busy_sum += busy;
  a->status.busy_ticks++;
  lf_avr_state(a, &a->s->fw);
  memcpy(raw, a->avr->data + a->a_raw, sizeof raw);
  memcpy(&mode, a->avr->data + a->a_tick_mode, sizeof mode);
  for (i = 0; i < a->s->nsensor; i++) {
    double physics_us = a->released[i] >= step_from_cycle ? a->physics_prev_us[i] : a->physics_us[i];
    a->s->raw[i] = raw[i];
    if (physics_us < a->s->sensor.timeout_us) { /* how well the MCU timed a line that fell */
      double error = raw[i] - physics_us;
      if (fabs(error) > a->status.read_error_max_us) a->status.read_error_max_us = fabs(error);
      a->status.read_error_sum_us += error;
      a->status.read_errors++;
    }
  }
  a->s->ticks++;
  /* the step's mean drive at the nominal supply: the voltages commanded, as the C loop's records keep them */
  lf_write_record(a->m, a->d, a->s, mode, a->height0, a->drive_step[0] * a->s->supply_voltage,
                  a->drive_step[1] * a->s->supply_voltage);
}

void pil_trace_ticks(lf_avr *a, uint64_t step_from_cycle) {
  uint32_t ticks;
  memcpy(&ticks, a->avr->data + a->a_ticks, sizeof ticks);
  while (a->ticks_seen < (int64_t)ticks) { /* at most one per step unless the period is shorter than h */
    a->ticks_seen++;
    record_tick(a, step_from_cycle);
  }
}

void lf_avr_reset_stats(lf_avr *a) {
  a->status.busy_max = a->status.busy_sum = 0;
  a->status.busy_ticks = a->status.read_errors = 0;
  a->status.read_error_max_us = a->status.read_error_sum_us = 0.0;
  a->status.release_cycles_sum = a->status.release_cycles_max = 0;
  a->status.compute_cycles_sum = a->status.compute_cycles_max = a->status.compute_cycles_min = 0;
  a->status.timed_ticks = 0;
}

void lf_avr_status_of(const lf_avr *a, lf_avr_status *status) {
  *status = a->status;
  status->cycle = a->avr->cycle;
  status->ticks = a->ticks_seen;
  status->awake = a->busy;
}

static void on_uart(struct avr_irq_t *irq, uint32_t value, void *param) {
  lf_avr *a = (lf_avr *)param;
  (void)irq;
  if (a->uart_len < UART_KEEP) a->uart[a->uart_len++] = (char)value;
  else a->status.uart_lost++;
}

/* The UART's bytes come to us, not to simavr's console. */
void pil_connect_uart(lf_avr *a) {
  uint32_t flags = 0;
  avr_ioctl(a->avr, AVR_IOCTL_UART_GET_FLAGS('0'), &flags);
  flags &= ~(uint32_t)(AVR_UART_FLAG_STDIO | AVR_UART_FLAG_POLL_SLEEP);
  avr_ioctl(a->avr, AVR_IOCTL_UART_SET_FLAGS('0'), &flags);
  avr_irq_register_notify(avr_io_getirq(a->avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUTPUT), on_uart, a);
}

/* Hand Python the UART bytes received since the last call (at most cap). */
int32_t lf_avr_uart(lf_avr *a, char *out, int32_t cap) {
  int32_t n = a->uart_len < cap ? a->uart_len : cap;
  memcpy(out, a->uart, (size_t)n);
  memmove(a->uart, a->uart + n, (size_t)(a->uart_len - n));
  a->uart_len -= n;
  return n;
}
