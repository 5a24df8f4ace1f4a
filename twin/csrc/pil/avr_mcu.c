/* The MCU's lifetime: a program's flash image (Python reads it from an ELF or an Intel HEX file, twin.pil.program)
 * loaded onto a fresh simavr ATmega328P with the board's hooks connected; its RAM, its EEPROM, free runs (no physics
 * attached) and the pushbuttons. Nothing here depends on the program's symbols: the twin's own firmware is told
 * where its traced globals are (lf_avr_trace_globals), any other program runs without. */
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <simavr/avr_eeprom.h>
#include <simavr/avr_extint.h>
#include <simavr/avr_ioport.h>
#include <simavr/avr_timer.h>
#include <simavr/sim_io.h>
#include <simavr/sim_irq.h>

#include "avr_glue.h"

static char log_text[MESSAGE]; /* simavr's last error message, for the one-line error Python raises */

static void logger(avr_t *avr, const int level, const char *format, va_list ap) {
  (void)avr;
  if (level <= LOG_ERROR) vsnprintf(log_text, sizeof log_text, format, ap);
}

/* simavr's raw mode sleeps in real time to keep the MCU's pace; the twin keeps the pace of the physics instead */
static void no_sleep(avr_t *avr, avr_cycle_count_t how_long) {
  (void)avr;
  (void)how_long;
}

static void chained_write(avr_t *avr, avr_io_addr_t addr, uint8_t v, void *param) {
  write_hook *h = (write_hook *)param;
  if (h->before) h->mine(avr, addr, v, h->a);
  if (h->orig) h->orig(avr, addr, v, h->orig_param);
  else avr->data[addr] = v;
  if (!h->before) h->mine(avr, addr, v, h->a);
}

void pil_watch_write(lf_avr *a, uint16_t addr, avr_io_write_t fn, int before) {
  avr_io_addr_t io = AVR_DATA_TO_IO(addr);
  write_hook *h;
  if (a->nhooks >= WRITE_HOOKS) abort(); /* a programming error of the glue: WRITE_HOOKS is sized for its hooks */
  h = &a->hooks[a->nhooks++];
  h->orig = a->avr->io[io].w.c, h->orig_param = a->avr->io[io].w.param, h->mine = fn, h->a = a, h->before = before;
  a->avr->io[io].w.c = chained_write, a->avr->io[io].w.param = h;
}

/* simavr 1.6's timers (cores/sim_megax8.h) know no Timer1 WGM 10 and 11 (phase-correct PWM with TOP = ICR1 or OCR1A,
 * the mode libpololu-avr's OrangutanBuzzer plays notes in: without it Timer1 never overflows and is_playing() waits
 * for ever) nor the 8-bit timers' WGM 1 and 5, and it counts every phase-correct mode up to TOP and back to 0 in
 * (TOP + 1) prescaled clocks instead of 2 TOP (datasheet, "Phase Correct PWM Mode"). The glue adds the missing modes
 * and, while a timer is in a phase-correct mode, doubles its prescaler: overflows (and the notes they time) then come
 * every 2 (TOP + 1) clocks, within 1/TOP of the MCU's period. */
static const uint8_t tccr_a[3] = {TCCR0A, TCCR1A, TCCR2A}, tccr_b[3] = {TCCR0B, TCCR1B, TCCR2B};

static int phase_correct(int k, int wgm) {
  return k == 1 ? (wgm >= 1 && wgm <= 3) || (wgm >= 8 && wgm <= 11) : wgm == 1 || wgm == 5;
}

static void before_tccr(avr_t *avr, avr_io_addr_t addr, uint8_t v, void *param) {
  lf_avr *a = (lf_avr *)param;
  int k, i;
  (void)avr;
  for (k = 0; k < 3; k++) {
    uint8_t ra = addr == tccr_a[k] ? v : reg(a, tccr_a[k]), rb = addr == tccr_b[k] ? v : reg(a, tccr_b[k]);
    int wgm = (ra & 3) | ((rb >> 1) & (k == 1 ? 0xc : 0x4)), slow = phase_correct(k, wgm);
    if (!a->timers[k] || (addr != tccr_a[k] && addr != tccr_b[k])) continue;
    for (i = 1; i < 8; i++) /* CS 0: stopped; AVR_TIMER_EXTCLK_CHOOSE (0x80): the Tn pin clocks it */
      if (a->cs_div[k][i] < 0x80) a->timers[k]->cs_div[i] = (uint8_t)(a->cs_div[k][i] + slow);
  }
}

/* Timer1 with TOP = ICR1 (WGM 8, 10, 14), the modes of libpololu-avr's OrangutanServos, where simavr 1.6 falls short
 * twice. (1) It reads ICR1 only when the timer is reconfigured (a TCCR1A/B write that changes its clock or mode), so
 * a program that starts the clock first and sets ICR1 after (OrangutanServos: TCCR1B, then ICR1 = 25000) counts to
 * the old TOP, 0, for ever: an interrupt every few cycles, the program crawling. After an ICR1 write the glue stops
 * and restarts the clock through TCCR1B's own handlers, so the new TOP counts from then on (ICR1L: the low byte
 * completes a 16-bit write, ATmega328P datasheet 15.3). (2) It raises the input-capture flag at TOP ("the ICF1 flag
 * is set when TCNT1 reaches TOP", 15.9.3-15.9.5) only on its external-clock path, so OrangutanServos' TIMER1_CAPT
 * never ran. The glue raises it once a period: with the overflow in fast PWM (WGM 14), half a period after it in the
 * phase-correct modes (WGM 8, 10: simavr's overflow is BOTTOM there), in step with simavr's own period (tov_base,
 * tov_cycles) from every reconfiguration on. */
int pil_timer1_top_is_icr(lf_avr *a) {
  uint8_t rb = reg(a, TCCR1B);
  int wgm = (reg(a, TCCR1A) & 3) | ((rb >> 1) & 0xc);
  return (rb & 7) && (wgm == 8 || wgm == 10 || wgm == 14) ? wgm : 0;
}

static void after_icr1(avr_t *avr, avr_io_addr_t addr, uint8_t v, void *param) {
  lf_avr *a = (lf_avr *)param;
  uint8_t rb = reg(a, TCCR1B);
  avr_io_addr_t io = AVR_DATA_TO_IO(TCCR1B);
  (void)addr;
  (void)v;
  if (!pil_timer1_top_is_icr(a)) return;
  avr->io[io].w.c(avr, TCCR1B, (uint8_t)(rb & ~7u), avr->io[io].w.param); /* (the capture follows: after_tccr1) */
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

static void after_tccr1(avr_t *avr, avr_io_addr_t addr, uint8_t v, void *param) {
  (void)avr;
  (void)addr;
  (void)v;
  sync_capture((lf_avr *)param);
}

static void fix_timers(lf_avr *a) {
  static const avr_timer_wgm_t fast8 = AVR_TIMER_WGM_FASTPWM8(), fast9 = AVR_TIMER_WGM_FASTPWM9(),
                               fast10 = AVR_TIMER_WGM_FASTPWM10(), ocr = AVR_TIMER_WGM_OCPWM(),
                               icr = AVR_TIMER_WGM_ICPWM();
  avr_io_t *port;
  int k;
  for (port = a->avr->io_port; port; port = port->next) {
    avr_timer_t *t = (avr_timer_t *)port;
    if (!port->kind || strcmp(port->kind, "timer") || t->name < '0' || t->name > '2') continue;
    k = t->name - '0';
    a->timers[k] = t;
    memcpy(a->cs_div[k], t->cs_div, sizeof t->cs_div);
    t->wgm_op[1] = fast8; /* counted as a fast 8-bit PWM at twice the prescaler, as all phase-correct modes */
    if (k == 1) t->wgm_op[2] = fast9, t->wgm_op[3] = fast10, t->wgm_op[10] = icr, t->wgm_op[11] = ocr;
    else t->wgm_op[5] = ocr;
  }
  for (k = 0; k < 3; k++) {
    pil_watch_write(a, tccr_a[k], before_tccr, 1);
    pil_watch_write(a, tccr_b[k], before_tccr, 1);
  }
  pil_watch_write(a, ICR1L, after_icr1, 0);
  pil_watch_write(a, TCCR1A, after_tccr1, 0);
  pil_watch_write(a, TCCR1B, after_tccr1, 0);
}

/* A program's flash (and EEPROM) image onto a fresh MCU. NULL with the reason in err if simavr cannot. Python has
 * checked that the image fits the MCU's flash: simavr aborts the process on one that does not. */
lf_avr *lf_avr_open(const uint8_t *flash, uint32_t flash_size, const uint8_t *eeprom, uint32_t eeprom_size,
                    const char *mmcu, uint32_t f_cpu, char *err, int32_t errlen) {
  lf_avr *a = (lf_avr *)calloc(1, sizeof(lf_avr));
  int i;
  avr_global_logger_set(logger);
  log_text[0] = 0;
  if (!a) {
    snprintf(err, (size_t)errlen, "out of memory");
    return 0;
  }
  a->avr = avr_make_mcu_by_name(mmcu);
  if (!a->avr) {
    snprintf(err, (size_t)errlen, "simavr has no MCU named %s", mmcu);
    free(a);
    return 0;
  }
  avr_init(a->avr);
  if (flash_size > a->avr->flashend + 1u) {
    snprintf(err, (size_t)errlen, "%u bytes of program do not fit the %s's %u bytes of flash", flash_size, mmcu,
             a->avr->flashend + 1u);
    avr_terminate(a->avr);
    free(a);
    return 0;
  }
  a->avr->log = LOG_ERROR;
  a->avr->sleep = no_sleep;
  /* INT0/INT1 share PD2 and PD3 with the LCD's RS line and a motor's PWM line. In low-level mode (their reset
   * state) simavr polls such a pin every cycle while it is low, whether or not the interrupt is enabled: ~85 % of
   * the emulation's time. A program that enables either gets a note (LF_USED_INT01). */
  avr_extint_set_strict_lvl_trig(a->avr, 0, 0);
  avr_extint_set_strict_lvl_trig(a->avr, 1, 0);
  a->avr->frequency = f_cpu;
  a->avr->vcc = a->avr->avcc = a->avr->aref = LF_VCC_MV; /* the 3pi's regulated 5 V, also its ADC reference */
  a->f_cpu = f_cpu;
  avr_loadcode(a->avr, (uint8_t *)flash, flash_size, 0);
  if (eeprom && eeprom_size && lf_avr_eeprom(a, eeprom, eeprom_size)) {
    snprintf(err, (size_t)errlen, "its %u bytes of EEPROM data do not fit the %s's EEPROM", eeprom_size, mmcu);
    lf_avr_close(a);
    return 0;
  }
  fix_timers(a);
  pil_connect_uart(a);
  pil_connect_sensors(a);
  pil_connect_motors(a);
  pil_connect_lcd(a);
  pil_connect_board(a);
  pil_connect_timing(a);
  for (i = 0; i < LF_BOARD_MAX_SENSORS; i++) a->refs[i].index = i;
  return a;
}

void lf_avr_close(lf_avr *a) {
  if (!a) return;
  if (a->avr) avr_terminate(a->avr);
  free(a);
}

/* The twin's own firmware: where its traced globals live (twin/csrc/firmware/avr/main.c); each finished tick is then
 * traced from its RAM and the watchdog of lf_avr_lockstep applies. */
void lf_avr_trace_globals(lf_avr *a, uint16_t state, uint16_t raw, uint16_t tick_mode, uint16_t ticks) {
  a->a_state = state, a->a_raw = raw, a->a_tick_mode = tick_mode, a->a_ticks = ticks;
}

int32_t lf_avr_eeprom(lf_avr *a, const uint8_t *image, uint32_t size) {
  avr_eeprom_desc_t desc;
  desc.ee = (uint8_t *)image;
  desc.offset = 0;
  desc.size = size;
  /* simavr 1.6 answers -1 when it has copied the image (its res is never set) and -2 when it refuses it */
  return avr_ioctl(a->avr, AVR_IOCTL_EEPROM_SET, &desc) == -2 ? -1 : 0;
}

int32_t lf_avr_peek(const lf_avr *a, uint32_t addr, uint8_t *out, uint32_t n) {
  if ((uint64_t)addr + n > (uint64_t)a->avr->ramend + 1) return -1;
  memcpy(out, a->avr->data + addr, n);
  return 0;
}

int32_t lf_avr_poke(lf_avr *a, uint32_t addr, const uint8_t *in, uint32_t n) {
  if ((uint64_t)addr + n > (uint64_t)a->avr->ramend + 1 || addr < 0x100) return -1; /* SRAM only, not the I/O space */
  memcpy(a->avr->data + addr, in, n);
  return 0;
}

/* Run free for a number of cycles (no physics attached); returns as lf_avr_run_until_clear. */
int32_t lf_avr_run_cycles(lf_avr *a, uint64_t cycles) {
  uint64_t end = a->avr->cycle + cycles;
  while (a->avr->cycle < end) {
    int state = avr_run(a->avr);
    if (state == cpu_Done || state == cpu_Crashed) return 2;
  }
  return 0;
}

/* Run until the byte at addr is 0 or max_cycles pass: 0 done, 1 out of cycles, 2 the MCU stopped. */
int32_t lf_avr_run_until_clear(lf_avr *a, uint32_t addr, uint64_t max_cycles) {
  uint64_t end = a->avr->cycle + max_cycles;
  while (a->avr->data[addr]) {
    int state = avr_run(a->avr);
    if (state == cpu_Done || state == cpu_Crashed) return 2;
    if (a->avr->cycle >= end) return 1;
  }
  return 0;
}

/* Hold the buttons in pressed (A 1, B 2, C 4) and let the others go. A held button pulls its line low through
 * 1 kOhm: an input reads 0 (simavr's external drive beats the pull-up), an output still reads what the MCU drives. */
void lf_avr_buttons(lf_avr *a, int32_t pressed) {
  static const int pins[3] = LF_BUTTON_PINS;
  avr_ioport_external_t e;
  int k;
  e.name = 'B';
  e.mask = 0;
  e.value = 0;
  for (k = 0; k < 3; k++)
    if (pressed & (1 << k)) e.mask |= (uint8_t)(1u << pins[k]);
  avr_ioctl(a->avr, AVR_IOCTL_IOPORT_SET_EXTERNAL('B'), &e);
  a->board.buttons = pressed & 7;
  for (k = 0; k < 3; k++) {
    uint8_t bit = (uint8_t)(1u << pins[k]);
    if (reg(a, DDRB) & bit) continue; /* an output: the MCU's drive wins */
    if (pressed & (1 << k)) avr_raise_irq(avr_io_getirq(a->avr, AVR_IOCTL_IOPORT_GETIRQ('B'), pins[k]), 0);
    else if (reg(a, PORTB) & bit) avr_raise_irq(avr_io_getirq(a->avr, AVR_IOCTL_IOPORT_GETIRQ('B'), pins[k]), 1);
  }
}
