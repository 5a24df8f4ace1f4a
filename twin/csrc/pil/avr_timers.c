/* The ATmega328P's timers where simavr 1.6 (cores/sim_megax8.h, sim/avr_timer.c) falls short of the datasheet:
 *   modes     Timer1's WGM 10 and 11 (phase-correct PWM with TOP = ICR1 or OCR1A, the mode libpololu-avr's
 *             OrangutanBuzzer plays notes in: without it Timer1 never overflows and is_playing() waits for ever) and
 *             the 8-bit timers' WGM 1 and 5 are missing; every phase-correct mode is counted up to TOP and back to 0
 *             in (TOP + 1) prescaled clocks instead of 2 TOP. The glue adds the modes and, while a timer is in a
 *             phase-correct mode, doubles its prescaler: overflows (and the notes they time) come every 2 (TOP + 1)
 *             clocks, within 1/TOP of the MCU's period.
 *   compares  in a phase-correct mode simavr matches each compare once a period, at 2 (OCR + 1) clocks after BOTTOM.
 *             The datasheet ("Phase Correct PWM Mode" of each timer) matches twice, counting up and counting
 *             down, and sets or clears the OCnx pin at each as COMnx says; OrangutanServos toggles a servo's pin in
 *             each TIMER1_COMPA interrupt and OrangutanPulseIn times the buzzer's OC1B pulses by pin-change
 *             interrupts. The glue takes those timers' compares from simavr (a compare it does not know the
 *             register of is never armed) and matches them itself, up and down, from simavr's own BOTTOM (tov_base,
 *             tov_cycles): the interrupt flag; the pin's level, raised on the timer's output IRQ (a pin-change
 *             interrupt sees it) and kept as the PORTx bit while the output drives the pin (it overrides PORTx:
 *             simavr's port then keeps it and a read of PINx answers it); OCRnx double-buffered (taken at TOP, or
 *             at BOTTOM in WGM 8 and 9); and a read of TCNTn counting up and down.
 *   ICR1      with TOP = ICR1 (WGM 8, 10, 14, OrangutanServos' modes) simavr reads ICR1 only when the timer is
 *             reconfigured, and raises the input-capture flag at TOP only on its external-clock path. */
#include <string.h>

#include <simavr/avr_ioport.h>
#include <simavr/avr_timer.h>
#include <simavr/sim_io.h>
#include <simavr/sim_irq.h>

#include "avr_glue.h"

enum { TCNT0 = 0x46, TCNT1L = 0x84, TCNT2 = 0xB2 };
static const uint8_t tccr_a[3] = {TCCR0A, TCCR1A, TCCR2A}, tccr_b[3] = {TCCR0B, TCCR1B, TCCR2B};
static const uint8_t ocr_a[3] = {OCR0A, OCR1AL, OCR2A}, ocr_b[3] = {OCR0B, OCR1BL, OCR2B};
static const uint8_t tcnt[3] = {TCNT0, TCNT1L, TCNT2};

static int wgm_of(int k, uint8_t ra, uint8_t rb) { return (ra & 3) | ((rb >> 1) & (k == 1 ? 0xc : 0x4)); }

static int wgm_now(const lf_avr *a, int k) { return wgm_of(k, reg(a, tccr_a[k]), reg(a, tccr_b[k])); }

static int phase_correct(int k, int wgm) {
  return k == 1 ? (wgm >= 1 && wgm <= 3) || (wgm >= 8 && wgm <= 11) : wgm == 1 || wgm == 5;
}

static int top_is_ocra(int k, int wgm) { return k == 1 ? wgm == 9 || wgm == 11 : wgm == 5; }

/* --- the modes and the prescaler (simavr's write handlers run after these) */
static void before_tccr(avr_t *avr, avr_io_addr_t addr, uint8_t v, void *param) {
  lf_avr *a = (lf_avr *)param;
  int k, i;
  (void)avr;
  for (k = 0; k < 3; k++) {
    avr_timer_t *t = a->timers[k];
    uint8_t ra, rb;
    int wgm, slow;
    if (!t || (addr != tccr_a[k] && addr != tccr_b[k])) continue;
    ra = addr == tccr_a[k] ? v : reg(a, tccr_a[k]), rb = addr == tccr_b[k] ? v : reg(a, tccr_b[k]);
    wgm = wgm_of(k, ra, rb), slow = phase_correct(k, wgm);
    a->phase[k].restart = wgm != wgm_now(a, k) || (rb & 7) != (reg(a, tccr_b[k]) & 7);
    for (i = 1; i < 8; i++) /* CS 0: stopped; AVR_TIMER_EXTCLK_CHOOSE (0x80): the Tn pin clocks it */
      if (a->cs_div[k][i] < 0x80) t->cs_div[i] = (uint8_t)(a->cs_div[k][i] + slow);
    for (i = 0; i < 2; i++) /* the compares the glue matches itself: simavr arms none without a register */
      t->comp[i].r_ocr = slow && !(i == 0 && top_is_ocra(k, wgm)) ? 0 : a->phase[k].r_ocr[i];
  }
}

/* --- the compares of a phase-correct mode, matched up and down */
typedef struct {
  uint64_t half;   /* BOTTOM to TOP in cycles: simavr's period is 2 (TOP + 1) clocks */
  uint64_t clock;  /* cycles per count */
  uint32_t top;
} span;

static span span_of(const avr_timer_t *t) {
  span s;
  s.half = t->tov_cycles / 2, s.clock = t->cs_div_value / 2, s.top = t->tov_top;
  return s;
}

/* The cycle at which compare i matches counting up (down = 0) or down, or 0 if it does not then. */
static uint64_t match_at(const pil_phase_timer *p, span s, int i, int down) {
  uint32_t o = p->ocr[i];
  if (o == 0) return down ? 0 : p->bottom;
  if (o >= s.top) return o == s.top && down ? p->bottom + s.half : 0;
  return down ? p->bottom + s.half + (s.top - o) * s.clock : p->bottom + o * s.clock;
}

/* The count at cycle c of this period, and whether it is counting down. */
static uint32_t count_at(const pil_phase_timer *p, span s, uint64_t c, int *down) {
  uint64_t in = c - p->bottom, n;
  *down = in >= s.half;
  n = (*down ? in - s.half : in) / s.clock;
  if (n > s.top) n = s.top;
  return (uint32_t)(*down ? s.top - n : n);
}

/* COMnx: 2 clears the pin counting up and sets it counting down, 3 the other way round; 1 toggles OCnA where
 * OCRnA is TOP (WGM 9, 11; WGM 5), else leaves the pin to PORT, as 0 does. Returns the mode, 0 if disconnected. */
static int output_mode(const lf_avr *a, int k, int i) {
  int com = (reg(a, tccr_a[k]) >> (i ? 4 : 6)) & 3;
  int wgm = wgm_now(a, k);
  return com == 1 && !(i == 0 && top_is_ocra(k, wgm)) ? 0 : com;
}

static void drive_pin(lf_avr *a, pil_phase_timer *p, int i, int level) {
  avr_timer_t *t = a->timers[p->k];
  uint16_t port = t->comp[i].com_pin.reg;
  p->driving[i] = 1;
  if (p->level[i] == level) return;
  p->level[i] = (uint8_t)level;
  if (port && (reg(a, (uint16_t)(port - 1)) & (1u << t->comp[i].com_pin.bit))) /* DDRx is PORTx - 1 */
    avr_raise_irq(t->io.irq + TIMER_IRQ_OUT_COMP + i, AVR_IOPORT_OUTPUT | (uint32_t)level);
}

/* The pins' levels at cycle c with COM 2 or 3: high below OCR counting up, at or below it counting down (so OCR 0
 * keeps the pin low and OCR = TOP high, as the datasheet says). */
static void levels_at(lf_avr *a, pil_phase_timer *p, span s, uint64_t c) {
  int i, down;
  uint32_t n = count_at(p, s, c, &down);
  for (i = 0; i < 2; i++) {
    int mode = output_mode(a, p->k, i);
    if (mode >= 2) drive_pin(a, p, i, (down ? n <= p->ocr[i] : n < p->ocr[i]) ^ (mode == 3));
  }
}

static void take_ocr(lf_avr *a, pil_phase_timer *p, span s) {
  int i;
  for (i = 0; i < 2; i++) {
    uint16_t low = i ? ocr_b[p->k] : ocr_a[p->k];
    uint32_t high = p->k == 1 ? (uint32_t)reg(a, (uint16_t)(low + 1)) << 8 : 0u; /* OCR1xH follows OCR1xL */
    p->ocr[i] = i == 0 && top_is_ocra(p->k, wgm_now(a, p->k)) ? s.top : (reg(a, low) | high);
  }
}

static uint64_t next_event(const pil_phase_timer *p, span s, uint64_t after) {
  uint64_t next = p->bottom + 2 * s.half, c;
  int i, down;
  if (p->bottom + s.half > after && p->bottom + s.half < next) next = p->bottom + s.half;
  for (i = 0; i < 2; i++)
    for (down = 0; down < 2; down++)
      if ((c = match_at(p, s, i, down)) > after && c < next) next = c;
  return next;
}

static avr_cycle_count_t on_phase_event(avr_t *avr, avr_cycle_count_t when, void *param) {
  pil_phase_timer *p = (pil_phase_timer *)param;
  lf_avr *a = p->a;
  avr_timer_t *t = a->timers[p->k];
  span s = span_of(t);
  int i, down, wgm = wgm_now(a, p->k);
  int at_bottom = p->k == 1 && (wgm == 8 || wgm == 9); /* OCR1x taken at BOTTOM there, else at TOP */
  if (when == p->bottom + 2 * s.half) {
    p->bottom = when;
    if (at_bottom) take_ocr(a, p, s);
  } else if (when == p->bottom + s.half && !at_bottom) {
    take_ocr(a, p, s);
  }
  for (i = 0; i < 2; i++)
    for (down = 0; down < 2; down++) {
      if (match_at(p, s, i, down) != when) continue;
      avr_raise_interrupt(avr, &t->comp[i].interrupt);
      if (output_mode(a, p->k, i) == 1) drive_pin(a, p, i, !p->level[i]);
    }
  levels_at(a, p, s, when);
  return next_event(p, s, when);
}

/* A pin the compare output no longer drives goes back to what the program last wrote to its PORTx bit. */
static void release_pins(lf_avr *a, pil_phase_timer *p) {
  avr_timer_t *t = a->timers[p->k];
  int i;
  for (i = 0; i < 2; i++) {
    avr_regbit_t pin = t->comp[i].com_pin;
    uint8_t bit = (uint8_t)(1u << pin.bit);
    avr_io_addr_t io = AVR_DATA_TO_IO(pin.reg);
    if (!p->driving[i] || (p->active && output_mode(a, p->k, i))) continue;
    p->driving[i] = 0, p->level[i] = 0;
    if (pin.reg == PORTB || pin.reg == PORTD) {
      uint8_t v = (uint8_t)((reg(a, pin.reg) & ~bit) | (a->port_written[pin.reg == PORTD] & bit));
      a->avr->io[io].w.c(a->avr, pin.reg, v, a->avr->io[io].w.param);
    }
  }
}

/* After anything that may have restarted or retimed timer k: follow simavr's BOTTOM from now on. */
static void phase_sync(lf_avr *a, int k, int take) {
  pil_phase_timer *p = &a->phase[k];
  avr_timer_t *t = a->timers[k];
  span s;
  int i, wgm;
  if (!t) return;
  avr_cycle_timer_cancel(a->avr, on_phase_event, p);
  wgm = wgm_now(a, k);
  p->active = phase_correct(k, wgm) && (reg(a, tccr_b[k]) & 7) && t->cs_div_value >= 2 && t->tov_cycles > 1;
  release_pins(a, p);
  if (!p->active) return;
  for (i = 0; i < 2; i++) t->comp[i].comp_cycles = 0; /* (OCRnA as TOP: simavr would match it at BOTTOM) */
  s = span_of(t);
  if (top_is_ocra(k, wgm)) p->ocr[0] = s.top; /* (a new TOP is simavr's at once) */
  p->bottom = t->tov_base;
  while (p->bottom + 2 * s.half <= a->avr->cycle) p->bottom += 2 * s.half;
  if (take) take_ocr(a, p, s);
  levels_at(a, p, s, a->avr->cycle);
  avr_cycle_timer_register(a->avr, next_event(p, s, a->avr->cycle) - a->avr->cycle, on_phase_event, p);
}

static int timer_of(uint16_t addr) {
  int k;
  for (k = 0; k < 3; k++)
    if (addr == tccr_a[k] || addr == tccr_b[k] || addr == ocr_a[k] || addr == ocr_b[k] || addr == tcnt[k]) return k;
  return -1;
}

/* --- Timer1 with TOP = ICR1 (WGM 8, 10, 14). (1) After an ICR1 write the glue stops and restarts the clock through
 * TCCR1B's own handlers, so the new TOP counts from then on (OrangutanServos starts the clock first and sets ICR1
 * = 25000 after: without this it counts to the old TOP, 0, for ever, an interrupt every few cycles; ICR1L: the
 * low byte completes a 16-bit write, datasheet 15.3). (2) The input-capture flag at TOP ("the ICF1 flag is set
 * when TCNT1 reaches TOP", 15.9.3-15.9.5), once a period: with the overflow in fast PWM (WGM 14), half a period
 * after it in the phase-correct modes (simavr's overflow is BOTTOM there). */
int pil_timer1_top_is_icr(lf_avr *a) {
  int wgm = wgm_now(a, 1);
  return (reg(a, TCCR1B) & 7) && (wgm == 8 || wgm == 10 || wgm == 14) ? wgm : 0;
}

static void after_icr1(avr_t *avr, avr_io_addr_t addr, uint8_t v, void *param) {
  lf_avr *a = (lf_avr *)param;
  uint8_t rb = reg(a, TCCR1B);
  avr_io_addr_t io = AVR_DATA_TO_IO(TCCR1B);
  (void)addr;
  (void)v;
  if (!pil_timer1_top_is_icr(a)) return;
  avr->io[io].w.c(avr, TCCR1B, (uint8_t)(rb & ~7u), avr->io[io].w.param); /* (the hooks below follow) */
  avr->io[io].w.c(avr, TCCR1B, rb, avr->io[io].w.param);
}

static avr_cycle_count_t capture_at_top(avr_t *avr, avr_cycle_count_t when, void *param) {
  avr_timer_t *t = (avr_timer_t *)param;
  avr_raise_interrupt(avr, &t->icr);
  return t->tov_cycles > 1 ? when + t->tov_cycles : 0;
}

static void sync_capture(lf_avr *a) {
  avr_timer_t *t = a->timers[1];
  int wgm;
  avr_cycle_count_t next;
  if (!t) return;
  avr_cycle_timer_cancel(a->avr, capture_at_top, t);
  wgm = pil_timer1_top_is_icr(a);
  if (!wgm || t->tov_cycles <= 1) return;
  next = t->tov_base + (wgm == 14 ? 0 : t->tov_cycles / 2);
  while (next <= a->avr->cycle) next += t->tov_cycles;
  avr_cycle_timer_register(a->avr, next - a->avr->cycle, capture_at_top, t);
}

/* A timer's register written (simavr has handled it): its mode, clock, TOP or count may have changed. A TCCR write
 * that restarted the timer takes the compare values at once; a compare write waits for TOP or BOTTOM. */
static void after_timer_write(avr_t *avr, avr_io_addr_t addr, uint8_t v, void *param) {
  lf_avr *a = (lf_avr *)param;
  int k = timer_of(addr), tccr;
  (void)avr;
  (void)v;
  if (k < 0) return;
  tccr = addr == tccr_a[k] || addr == tccr_b[k];
  if (k == 1 && tccr) sync_capture(a);
  if (tccr || a->phase[k].active) phase_sync(a, k, tccr && a->phase[k].restart);
}

/* --- a program's PORTB/PORTD write: the bits a compare output drives keep its level (the output overrides PORTx,
 * datasheet, "Compare Match Output Unit"); the program's own bits are kept for when the output lets go of the pin. */
static void on_port_write(avr_t *avr, avr_io_addr_t addr, uint8_t v, void *param) {
  lf_avr *a = (lf_avr *)param;
  int n = addr == PORTD, k, i;
  uint8_t mask = 0, levels = 0;
  for (k = 0; k < 3; k++) {
    avr_timer_t *t = a->timers[k];
    for (i = 0; t && a->phase[k].active && i < 2; i++) {
      uint8_t bit = (uint8_t)(1u << t->comp[i].com_pin.bit);
      if (t->comp[i].com_pin.reg != addr || !a->phase[k].driving[i] || !(reg(a, (uint16_t)(addr - 1)) & bit)) continue;
      mask |= bit;
      if (a->phase[k].level[i]) levels |= bit;
    }
  }
  a->port_written[n] = v;
  a->port_write[n](avr, addr, (uint8_t)((v & ~mask) | levels), a->port_param[n]);
}

/* --- reads: the count as the MCU would read it (simavr counts up to TOP and wraps) */
static uint8_t on_tcnt_read(avr_t *avr, avr_io_addr_t addr, void *param) {
  pil_phase_timer *p = (pil_phase_timer *)param;
  lf_avr *a = p->a;
  uint8_t v = p->tcnt_read(avr, addr, p->tcnt_param);
  int down;
  uint32_t n;
  if (!p->active) return v;
  n = count_at(p, span_of(a->timers[p->k]), avr->cycle, &down);
  avr->data[addr] = (uint8_t)n;
  if (p->k == 1) avr->data[addr + 1] = (uint8_t)(n >> 8); /* TCNT1H: read through TEMP after the low byte */
  return (uint8_t)n;
}

void pil_connect_timers(lf_avr *a) {
  static const avr_timer_wgm_t fast8 = AVR_TIMER_WGM_FASTPWM8(), fast9 = AVR_TIMER_WGM_FASTPWM9(),
                               fast10 = AVR_TIMER_WGM_FASTPWM10(), ocr = AVR_TIMER_WGM_OCPWM(),
                               icr = AVR_TIMER_WGM_ICPWM();
  avr_io_t *port;
  int k, i;
  for (port = a->avr->io_port; port; port = port->next) {
    avr_timer_t *t = (avr_timer_t *)port;
    avr_io_addr_t io;
    if (!port->kind || strcmp(port->kind, "timer") || t->name < '0' || t->name > '2') continue;
    k = t->name - '0';
    a->timers[k] = t;
    memcpy(a->cs_div[k], t->cs_div, sizeof t->cs_div);
    a->phase[k].a = a, a->phase[k].k = k;
    for (i = 0; i < 2; i++) a->phase[k].r_ocr[i] = t->comp[i].r_ocr;
    t->wgm_op[1] = fast8; /* counted as a fast 8-bit PWM at twice the prescaler, as all phase-correct modes */
    if (k == 1) t->wgm_op[2] = fast9, t->wgm_op[3] = fast10, t->wgm_op[10] = icr, t->wgm_op[11] = ocr;
    else t->wgm_op[5] = ocr;
    io = AVR_DATA_TO_IO(tcnt[k]); /* simavr's own reader computes the count: chain it */
    a->phase[k].tcnt_read = a->avr->io[io].r.c, a->phase[k].tcnt_param = a->avr->io[io].r.param;
    a->avr->io[io].r.c = on_tcnt_read, a->avr->io[io].r.param = &a->phase[k];
  }
  for (i = 0; i < 2; i++) { /* (before any hook of the glue wraps them) */
    avr_io_addr_t io = AVR_DATA_TO_IO(i ? PORTD : PORTB);
    a->port_write[i] = a->avr->io[io].w.c, a->port_param[i] = a->avr->io[io].w.param;
    a->avr->io[io].w.c = on_port_write, a->avr->io[io].w.param = a;
  }
  for (k = 0; k < 3; k++) {
    if (!a->timers[k]) continue;
    pil_watch_write(a, tccr_a[k], before_tccr, 1);
    pil_watch_write(a, tccr_b[k], before_tccr, 1);
    pil_watch_write(a, tccr_a[k], after_timer_write, 0);
    pil_watch_write(a, tccr_b[k], after_timer_write, 0);
    pil_watch_write(a, ocr_a[k], after_timer_write, 0);
    pil_watch_write(a, ocr_b[k], after_timer_write, 0);
    pil_watch_write(a, tcnt[k], after_timer_write, 0);
  }
  pil_watch_write(a, ICR1L, after_icr1, 0);
}
