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
#include <simavr/sim_interrupts.h>
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

/* Interrupt flags as the ATmega328P keeps them (datasheet, "Reset and Interrupt Handling"), where simavr 1.6 (and
 * its master, sim_interrupts.c) does not:
 * (1) A flag raised while its enable bit is off stays set, and the interrupt runs once the program enables it ("the
 *     Interrupt Flag will be set and remembered until the interrupt is enabled"). simavr queues an interrupt only
 *     when it is raised while enabled: libpololu-avr's OrangutanTime::ticks() masks TOIE2 for a few cycles on every
 *     call, and each Timer2 overflow that landed there lost 256 ticks (102 us) of its clock. After a write to a
 *     register holding enable bits, the glue queues each enabled vector whose flag is set.
 * (2) A flag is cleared by writing a one to it. simavr gives PCIFR and EIFR (whose bits are only such flags, as
 *     the datasheet's register descriptions have them) no writer at all, so a program's PCIFR = 7 set its flags
 *     instead; the glue's writer clears each flag
 *     written with a one (and its pending interrupt) and keeps the others. */
static void after_enable_write(avr_t *avr, avr_io_addr_t addr, uint8_t v, void *param) {
  int i;
  (void)v;
  (void)param;
  for (i = 0; i < avr->interrupts.vector_count; i++) {
    avr_int_vector_t *vec = avr->interrupts.vector[i];
    if (vec->enable.reg == addr && !vec->pending && vec->raised.reg && avr_regbit_get(avr, vec->raised) &&
        avr_regbit_get(avr, vec->enable))
      avr_raise_interrupt(avr, vec);
  }
}

static void clear_flags_written(avr_t *avr, avr_io_addr_t addr, uint8_t v, void *param) {
  int i;
  (void)param;
  for (i = 0; i < avr->interrupts.vector_count; i++) {
    avr_int_vector_t *vec = avr->interrupts.vector[i];
    if (vec->raised.reg == addr && (v & (vec->raised.mask << vec->raised.bit))) avr_clear_interrupt(avr, vec);
  }
  avr->data[addr] &= (uint8_t)~v;
}

static void fix_interrupt_flags(lf_avr *a) {
  avr_int_table_p table = &a->avr->interrupts;
  int i, j;
  for (i = 0; i < table->vector_count; i++) {
    uint16_t enable = table->vector[i]->enable.reg, raised = table->vector[i]->raised.reg;
    avr_io_addr_t io = AVR_DATA_TO_IO(raised);
    for (j = 0; j < i && table->vector[j]->enable.reg != enable; j++) continue;
    if (enable && j == i) pil_watch_write(a, enable, after_enable_write, 0);
    if ((raised == EIFR || raised == PCIFR) && !a->avr->io[io].w.c) a->avr->io[io].w.c = clear_flags_written;
  }
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
  fix_interrupt_flags(a);
  pil_connect_timers(a);
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
