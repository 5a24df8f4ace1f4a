/* The motors' voltages: each motor's voltage is the supply times the drive its two control lines gave over the physics
 * step, the lines' levels decoded from the timer's mode, compare values and the pins' direction (ATmega328P datasheet,
 * "Compare Output Mode, Fast PWM"), integrated over the cycles between register changes. */
#include <simavr/sim_io.h>

#include "avr_glue.h"

/* A motor's two control lines: line A on the timer's compare output A, line B on B (board_3pi.h). */
typedef struct {
  uint8_t tccra, tccrb, ocra, ocrb;
  uint8_t port_a, bit_a, port_b, bit_b; /* LF_PORT_*, pin */
} motor_lines;
static const motor_lines motors[2] = {
  {TCCR0A, TCCR0B, OCR0A, OCR0B, LF_PORT_D, 6, LF_PORT_D, 5}, /* left: PD6 (OC0A), PD5 (OC0B) */
  {TCCR2A, TCCR2B, OCR2A, OCR2B, LF_PORT_B, 3, LF_PORT_D, 3}, /* right: PB3 (OC2A), PD3 (OC2B) */
};

/* The timer counts c (0..255) of a PWM period at which a compare-output line is high, as the interval [lo, hi): the
 * datasheet's Compare Output Mode tables for fast PWM (WGM 3) and phase-correct PWM (WGM 1, counted on the way up;
 * its way down mirrors it). Other modes, and COM = 0, leave the pin to PORT; an input pin drives nothing. */
static void line_high(const lf_avr *a, const motor_lines *ml, int which, int *lo, int *hi) {
  uint8_t tccra = reg(a, ml->tccra), wgm = (uint8_t)((tccra & 3u) | ((reg(a, ml->tccrb) >> 1) & 4u));
  uint8_t com = (uint8_t)((tccra >> (which ? 4 : 6)) & 3u);
  int ocr = reg(a, which ? ml->ocrb : ml->ocra);
  uint8_t port = which ? ml->port_b : ml->port_a, bit = which ? ml->bit_b : ml->bit_a;
  *lo = 0;
  if (!(reg(a, ddr_of[port]) & (1u << bit))) {
    *hi = 0; /* an input: the driver sees no drive */
  } else if ((wgm == 3 || wgm == 1) && com >= 2 && (reg(a, ml->tccrb) & 7u)) {
    int below = wgm == 3 ? ocr + 1 : ocr; /* counts 0..OCR (fast PWM) or 0..OCR-1 (phase correct) before the match */
    if (com == 2) *hi = below;            /* non-inverting: high until the match */
    else *lo = below, *hi = 256;          /* inverting: high from the match to TOP */
  } else {
    *hi = (reg(a, port_of[port]) >> bit) & 1u ? 256 : 0;
  }
}

/* Drive of one motor in [-1, 1]: the share of a PWM period with line A high and B low (forward) minus that with
 * A low and B high; both high or both low brake (0 V across the motor). */
static double motor_drive(const lf_avr *a, int k) {
  int lo_a, hi_a, lo_b, hi_b, both;
  line_high(a, &motors[k], 0, &lo_a, &hi_a);
  line_high(a, &motors[k], 1, &lo_b, &hi_b);
  both = (hi_a < hi_b ? hi_a : hi_b) - (lo_a > lo_b ? lo_a : lo_b);
  if (both < 0) both = 0;
  return ((hi_a - lo_a - both) - (hi_b - lo_b - both)) / 256.0;
}

/* Integrate the drive up to now; with recompute, decode it again from the registers (after a write to them). */
static void drive_update(lf_avr *a, int recompute) {
  uint64_t now = a->avr->cycle;
  int k;
  for (k = 0; k < 2; k++) a->drive_sum[k] += a->drive_now[k] * (double)(now - a->drive_since);
  a->drive_since = now;
  for (k = 0; k < 2 && !recompute; k++) /* a timer reconfigured without a hook of ours seeing it */
    recompute = reg(a, motors[k].tccra) != a->tccr_seen[k][0] || reg(a, motors[k].tccrb) != a->tccr_seen[k][1];
  if (!recompute) return;
  for (k = 0; k < 2; k++) {
    a->drive_now[k] = motor_drive(a, k);
    a->tccr_seen[k][0] = reg(a, motors[k].tccra);
    a->tccr_seen[k][1] = reg(a, motors[k].tccrb);
  }
}

static void on_compare_write(avr_t *avr, avr_io_addr_t addr, uint8_t v, void *param) {
  lf_avr *a = (lf_avr *)param;
  (void)addr;
  (void)v;
  a->pwm_written = avr->cycle;
  pil_timing_written(a);
  drive_update(a, 1); /* the register already holds v: simavr's own writer ran first */
}

void pil_connect_motors(lf_avr *a) {
  int i;
  for (i = 0; i < 2; i++) {
    pil_watch_write(a, motors[i].ocra, on_compare_write, 0);
    pil_watch_write(a, motors[i].ocrb, on_compare_write, 0);
  }
}

void pil_motor_direction(lf_avr *a, int port, uint8_t ddr) {
  drive_update(a, 0);
  a->avr->data[ddr_of[port]] = ddr; /* simavr raises the direction IRQ before it stores the value: store it now */
  drive_update(a, 1);
}

void pil_drive_begin(lf_avr *a) {
  drive_update(a, 0);
  a->drive_sum[0] = a->drive_sum[1] = 0;
}

void pil_drive_end(lf_avr *a, uint64_t from) {
  int i;
  double drive[2], bus;
  drive_update(a, 0);
  for (i = 0; i < 2; i++) {
    double span = (double)(a->avr->cycle - from);
    drive[i] = a->drive_step[i] = span > 0 ? a->drive_sum[i] / span : a->drive_now[i];
    if (drive[i] != 0.0) a->board.last_drive = a->avr->cycle;
  }
  bus = lf_bus_voltage(a->m, a->d, a->s, drive); /* the supply under the step's load, as the C loop's lf_drive */
  a->d->ctrl[a->s->actuator_left] = drive[0] * bus;
  a->d->ctrl[a->s->actuator_right] = drive[1] * bus;
}
