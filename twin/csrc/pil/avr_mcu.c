/* The MCU's lifetime: a firmware ELF loaded onto a fresh simavr ATmega328P with the board's hooks connected; its RAM
 * by symbol, its EEPROM, free runs (no physics attached) and button B. */
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <simavr/avr_eeprom.h>
#include <simavr/avr_extint.h>
#include <simavr/avr_ioport.h>
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

static uint16_t symbol(const lf_avr *a, const char *name) {
  uint32_t i;
  for (i = 0; i < a->firmware.symbolcount; i++)
    if (!strcmp(a->firmware.symbol[i]->symbol, name) && a->firmware.symbol[i]->addr >= 0x800000u)
      return (uint16_t)(a->firmware.symbol[i]->addr - 0x800000u);
  return 0;
}

/* Load an ELF onto a fresh MCU. NULL with the reason in err if simavr cannot. */
lf_avr *lf_avr_open(const char *elf_path, const char *mmcu, uint32_t f_cpu, char *err, int32_t errlen) {
  lf_avr *a = (lf_avr *)calloc(1, sizeof(lf_avr));
  int i;
  avr_global_logger_set(logger);
  log_text[0] = 0;
  if (!a) {
    snprintf(err, (size_t)errlen, "out of memory");
    return 0;
  }
  if (elf_read_firmware(elf_path, &a->firmware) != 0) {
    snprintf(err, (size_t)errlen, "simavr cannot read it%s%s", log_text[0] ? ": " : "", log_text);
    free(a);
    return 0;
  }
  a->avr = avr_make_mcu_by_name(mmcu);
  if (!a->avr) {
    snprintf(err, (size_t)errlen, "simavr has no MCU named %s", mmcu);
    free(a);
    return 0;
  }
  avr_init(a->avr);
  a->avr->log = LOG_ERROR;
  a->avr->sleep = no_sleep;
  /* INT0/INT1 share PD2 and PD3 with a sensor line and a motor's PWM line. In low-level mode (their reset state)
   * simavr polls such a pin every cycle while it is low, whether or not the interrupt is enabled: ~85 % of the
   * emulation's time. The firmware enables neither, so their level re-triggering cannot change what it does. */
  avr_extint_set_strict_lvl_trig(a->avr, 0, 0);
  avr_extint_set_strict_lvl_trig(a->avr, 1, 0);
  a->firmware.frequency = f_cpu;
  a->avr->frequency = f_cpu;
  a->f_cpu = f_cpu;
  avr_load_firmware(a->avr, &a->firmware);
  a->avr->frequency = f_cpu;
  pil_connect_uart(a);
  pil_connect_sensors(a);
  pil_connect_motors(a);
  for (i = 0; i < LF_BOARD_MAX_SENSORS; i++) a->refs[i].index = i;
  a->a_state = symbol(a, "fw_state");
  a->a_raw = symbol(a, "fw_raw_us");
  a->a_tick_mode = symbol(a, "fw_tick_mode");
  a->a_ticks = symbol(a, "fw_ticks_done");
  return a;
}

void lf_avr_close(lf_avr *a) {
  if (!a) return;
  if (a->avr) avr_terminate(a->avr);
  free(a);
}

/* Data-space address of a global of the firmware, -1 if it has none by that name. */
int32_t lf_avr_symbol(const lf_avr *a, const char *name) {
  uint16_t at = symbol(a, name);
  return at ? at : -1;
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

/* Hold button B pressed (1) or let it go (0): pressed pulls the line low against the pull-up. */
void lf_avr_button(lf_avr *a, int32_t pressed) {
  avr_ioport_external_t e;
  e.name = name_of[LF_BUTTON_B_PORT];
  e.mask = pressed ? (1u << LF_BUTTON_B_PIN) : 0;
  e.value = 0;
  avr_ioctl(a->avr, AVR_IOCTL_IOPORT_SET_EXTERNAL(name_of[LF_BUTTON_B_PORT]), &e);
  avr_raise_irq(avr_io_getirq(a->avr, AVR_IOCTL_IOPORT_GETIRQ(name_of[LF_BUTTON_B_PORT]), LF_BUTTON_B_PIN),
                pressed ? 0 : ((reg(a, port_of[LF_BUTTON_B_PORT]) >> LF_BUTTON_B_PIN) & 1u));
}
