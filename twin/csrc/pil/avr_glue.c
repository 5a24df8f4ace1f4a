/* Processor in the loop: the robot's firmware ELF runs on an emulated ATmega328P (simavr) in lockstep with MuJoCo.
 *
 * Per physics step of h seconds (lf_avr_lockstep):
 *   1. mj_step1: positions and velocities of the current state;
 *   2. the MCU runs to the step's end. When it releases a sensor line it had driven high, the line's decay time
 *      is the twin's sensor physics for that sensor at that moment (lf_read_sensor, the same code and noise stream
 *      as the C callback), and the line is pulled low that many microseconds later by a simavr cycle timer;
 *   3. each motor's voltage is the supply times the drive its two control lines gave over the step: the lines'
 *      levels decoded from the timer's mode, compare values and the pins' direction (ATmega328P datasheet,
 *      "Compare Output Mode, Fast PWM"), integrated over the cycles between register changes;
 *   4. mj_step2 with those voltages.
 * The MCU's clock never runs ahead of the physics by more than one instruction or one sleep: what it does at
 * cycle c happens when the physics is at the step holding c.
 *
 * After each step, a tick the firmware finished (its fw_ticks_done counter moved) is traced into the head's ring
 * from the firmware's own RAM (fw_state, fw_raw_us, fw_tick_mode), read by their ELF symbols, and the CPU cycles
 * spent awake since the previous tick are counted. A watchdog on simulated time ends the lap as stalled when the
 * MCU stops, no tick completes, a sensor line is never released, or no motor compare value is written.
 *
 * The MCU's UART bytes are kept for Python to drain: they are the robot's telemetry.
 */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <mujoco/mujoco.h>
#include <simavr/avr_eeprom.h>
#include <simavr/avr_extint.h>
#include <simavr/avr_ioport.h>
#include <simavr/avr_uart.h>
#include <simavr/sim_avr.h>
#include <simavr/sim_cycle_timers.h>
#include <simavr/sim_elf.h>
#include <simavr/sim_io.h>
#include <simavr/sim_irq.h>

#include "../firmware/avr/board_3pi_pins.h"
#include "../sim/twin_core.h"

/* ATmega328P data-space addresses (datasheet, "Register Summary"): ports, and Timers 0 and 2 for the motors */
enum { PINB = 0x23, DDRB = 0x24, PORTB = 0x25, PINC = 0x26, DDRC = 0x27, PORTC = 0x28, PIND = 0x29, DDRD = 0x2A,
       PORTD = 0x2B, TCCR0A = 0x44, TCCR0B = 0x45, OCR0A = 0x47, OCR0B = 0x48, TCCR2A = 0xB0, TCCR2B = 0xB1,
       OCR2A = 0xB3, OCR2B = 0xB4 };
static const uint8_t ddr_of[3] = {DDRB, DDRC, DDRD}, port_of[3] = {PORTB, PORTC, PORTD};
static const char name_of[3] = {'B', 'C', 'D'};
static const int sensor_pins[LF_BOARD_MAX_SENSORS][2] = LF_SENSOR_PINS; /* {port, bit} of sensor i */

/* A motor's two control lines: line A on the timer's compare output A, line B on B (board_3pi.h). */
typedef struct {
  uint8_t tccra, tccrb, ocra, ocrb;
  uint8_t port_a, bit_a, port_b, bit_b; /* LF_PORT_*, pin */
} motor_lines;
static const motor_lines motors[2] = {
  {TCCR0A, TCCR0B, OCR0A, OCR0B, LF_PORT_D, 6, LF_PORT_D, 5}, /* left: PD6 (OC0A), PD5 (OC0B) */
  {TCCR2A, TCCR2B, OCR2A, OCR2B, LF_PORT_B, 3, LF_PORT_D, 3}, /* right: PB3 (OC2A), PD3 (OC2B) */
};

/* The firmware's lf_state as avr-gcc lays it out: no padding, lf_real a 32-bit float. */
#pragma pack(push, 1)
typedef struct {
  uint16_t cal_min[LF_MAX_SENSORS], cal_max[LF_MAX_SENSORS], value[LF_MAX_SENSORS];
  int32_t position, last_position, line_seen, mode;
  uint32_t tick;
  float e, e_prev, integral, v, omega, duty_left, duty_right;
} avr_lf_state;
#pragma pack(pop)

enum { LF_AVR_RUNNING = 0, LF_AVR_STALLED = 1, LF_AVR_REFUSED = 2 };
#define UART_KEEP 65536
#define MESSAGE 256

typedef struct lf_avr lf_avr;
typedef struct {
  int32_t index; /* a sensor, for its cycle timer's callback */
} sensor_ref;

/* The MCU's figures for the run so far (Python: twin.pil.lap.McuStatus). */
typedef struct {
  uint64_t cycle;          /* MCU clock cycles since reset */
  int64_t ticks;           /* control ticks completed (the firmware's fw_ticks_done) */
  uint64_t busy_max;       /* most cycles awake in one tick (since lf_avr_reset_stats) */
  uint64_t busy_sum;       /* cycles awake over the ticks counted */
  int64_t busy_ticks;      /* ticks counted */
  int64_t uart_lost;       /* UART bytes not kept because Python had not drained them */
  double read_error_max_us; /* largest |MCU-timed reading - the physics' decay time| of a line that fell in time */
  double read_error_sum_us; /* their sum (signed: MCU minus physics) */
  int64_t read_errors;      /* readings compared */
} lf_avr_status;

struct lf_avr {
  avr_t *avr;
  elf_firmware_t firmware;
  uint32_t f_cpu;
  /* symbols: data-space addresses, 0 where absent */
  uint16_t a_state, a_raw, a_tick_mode, a_ticks;
  /* lockstep */
  const mjModel *m;
  mjData *d;
  lf_sim *s;
  int32_t nsensor;
  sensor_ref refs[LF_BOARD_MAX_SENSORS];
  uint8_t ddr_seen[3];
  uint64_t zero_cycle;                       /* MCU cycle at MuJoCo time 0 */
  uint64_t released[LF_BOARD_MAX_SENSORS];   /* cycle of each line's last release */
  uint64_t pwm_written;                      /* cycle of the last motor compare write */
  uint64_t tick_cycle;                       /* cycle of the last completed tick */
  uint64_t stall_cycles;                     /* the watchdog's limit */
  double height0;                            /* sensor 0's height at its last release [m] */
  double physics_us[LF_BOARD_MAX_SENSORS];   /* each line's decay time at its last release [us] */
  /* motor drive integrated over the step */
  uint64_t drive_since;
  double drive_now[2], drive_sum[2];
  uint8_t tccr_seen[2][2];                   /* the motor timers' control registers when the drive was decoded */
  /* CPU time */
  uint64_t busy, busy_tick_start;
  int64_t ticks_seen;
  lf_avr_status status;
  /* UART */
  char uart[UART_KEEP];
  int32_t uart_len;
  char message[MESSAGE];
};

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

static uint8_t reg(const lf_avr *a, uint16_t addr) { return a->avr->data[addr]; }

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
  drive_update(a, 1); /* the register already holds v: simavr's own writer ran first */
}

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
  if (port != LF_PORT_C) { /* a motor line may have changed direction */
    drive_update(a, 0);
    a->avr->data[ddr_of[port]] = (uint8_t)value; /* simavr raises this IRQ before it stores the value: store it now */
    drive_update(a, 1);
  }
  for (i = 0; i < a->nsensor; i++) {
    uint8_t bit = (uint8_t)(1u << sensor_pins[i][1]);
    double raw_us;
    if (sensor_pins[i][0] != port || !(before & bit) || (value & bit)) continue;
    a->released[i] = a->avr->cycle;
    avr_cycle_timer_cancel(a->avr, line_falls, &a->refs[i]);
    if (!(reg(a, port_of[port]) & bit)) continue; /* released low: nothing was charged, the line stays low */
    if (!a->s || !kinematics_ready(a, i)) { /* no physics attached, or not yet stepped: a dark floor */
      raw_us = a->s ? a->s->sensor.timeout_us : 2500.0;
    } else {
      double height = lf_read_sensor(a->m, a->d, a->s, i);
      int emitters = (reg(a, ddr_of[LF_EMITTER_PORT]) >> LF_EMITTER_PIN) & (reg(a, port_of[LF_EMITTER_PORT]) >> LF_EMITTER_PIN) & 1;
      if (i == 0) a->height0 = height;
      raw_us = emitters ? a->s->raw[i] : a->s->sensor.timeout_us; /* emitters off: no light comes back */
    }
    a->physics_us[i] = raw_us;
    avr_cycle_timer_register(a->avr, (avr_cycle_count_t)(raw_us * a->f_cpu / 1e6 + 0.5), line_falls, &a->refs[i]);
  }
}

static void on_uart(struct avr_irq_t *irq, uint32_t value, void *param) {
  lf_avr *a = (lf_avr *)param;
  (void)irq;
  if (a->uart_len < UART_KEEP) a->uart[a->uart_len++] = (char)value;
  else a->status.uart_lost++;
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
  uint32_t flags = 0;
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
  /* the UART's bytes come to us, not to simavr's console */
  avr_ioctl(a->avr, AVR_IOCTL_UART_GET_FLAGS('0'), &flags);
  flags &= ~(uint32_t)(AVR_UART_FLAG_STDIO | AVR_UART_FLAG_POLL_SLEEP);
  avr_ioctl(a->avr, AVR_IOCTL_UART_SET_FLAGS('0'), &flags);
  avr_irq_register_notify(avr_io_getirq(a->avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUTPUT), on_uart, a);
  for (i = 0; i < 3; i++)
    avr_irq_register_notify(avr_io_getirq(a->avr, AVR_IOCTL_IOPORT_GETIRQ(name_of[i]), IOPORT_IRQ_DIRECTION_ALL),
                            on_direction, a);
  for (i = 0; i < 2; i++) {
    avr_register_io_write(a->avr, motors[i].ocra, on_compare_write, a);
    avr_register_io_write(a->avr, motors[i].ocrb, on_compare_write, a);
  }
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

/* Connect the twin: from now on, sensor releases read this simulation's physics. */
void lf_avr_attach(lf_avr *a, const mjModel *m, mjData *d, lf_sim *s, double stall_s) {
  int i;
  a->m = m, a->d = d, a->s = s;
  a->nsensor = s->nsensor < LF_BOARD_MAX_SENSORS ? s->nsensor : LF_BOARD_MAX_SENSORS;
  a->stall_cycles = (uint64_t)(stall_s * a->f_cpu);
  for (i = 0; i < LF_BOARD_MAX_SENSORS; i++) a->released[i] = a->avr->cycle;
  a->pwm_written = a->tick_cycle = a->drive_since = a->avr->cycle;
  a->busy_tick_start = a->busy;
}

/* MuJoCo's time 0 is now (the robot was put on the start line). */
void lf_avr_zero_time(lf_avr *a) { a->zero_cycle = a->avr->cycle; }

void lf_avr_reset_stats(lf_avr *a) {
  a->status.busy_max = a->status.busy_sum = 0;
  a->status.busy_ticks = a->status.read_errors = 0;
  a->status.read_error_max_us = a->status.read_error_sum_us = 0.0;
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
  return 0;
}

int32_t lf_avr_state_size(void) { return (int32_t)sizeof(avr_lf_state); }

/* A tick the firmware finished: trace it from its RAM, count its awake cycles. */
static void record_tick(lf_avr *a) {
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
    a->s->raw[i] = raw[i];
    if (a->physics_us[i] < a->s->sensor.timeout_us) { /* how well the MCU timed a line that fell */
      double error = raw[i] - a->physics_us[i];
      if (fabs(error) > a->status.read_error_max_us) a->status.read_error_max_us = fabs(error);
      a->status.read_error_sum_us += error;
      a->status.read_errors++;
    }
  }
  a->s->ticks++;
  lf_write_record(a->m, a->d, a->s, mode, a->height0);
}

static int stalled(lf_avr *a, const char *why) {
  snprintf(a->message, sizeof a->message, "%s", why);
  return LF_AVR_STALLED;
}

/* Step the physics nstep times with the MCU in lockstep (see the top of this file); returns LF_AVR_RUNNING, or
 * LF_AVR_STALLED / LF_AVR_REFUSED with the reason in lf_avr_message. */
int32_t lf_avr_lockstep(lf_avr *a, void *step1, void *step2, int64_t nstep) {
  typedef void (*step_fn)(const mjModel *, mjData *);
  const mjModel *m = a->m;
  mjData *d = a->d;
  lf_sim *s = a->s;
  int64_t k;
  int i;
  char why[MESSAGE];
  if (!a->a_state || !a->a_raw || !a->a_tick_mode || !a->a_ticks) {
    snprintf(a->message, sizeof a->message, "the firmware has no fw_state, fw_raw_us, fw_tick_mode or fw_ticks_done");
    return LF_AVR_REFUSED;
  }
  if (!lf_has_ray() || lf_check(m, s) != LF_OK) {
    snprintf(a->message, sizeof a->message, "the simulation's head does not fit its model (error %d)", lf_check(m, s));
    return LF_AVR_REFUSED;
  }
  for (k = 0; k < nstep; k++) {
    double h = m->opt.timestep, power;
    uint64_t end = a->zero_cycle + (uint64_t)((d->time + h) * a->f_cpu + 0.5);
    uint32_t ticks;
    ((step_fn)step1)(m, d);
    drive_update(a, 0); /* the drive so far belongs to earlier steps */
    a->drive_sum[0] = a->drive_sum[1] = 0;
    {
      uint64_t from = a->avr->cycle;
      while (a->avr->cycle < end) {
        uint64_t c0 = a->avr->cycle;
        int awake = a->avr->state == cpu_Running;
        int state = avr_run(a->avr);
        if (awake) a->busy += a->avr->cycle - c0;
        if (state == cpu_Done || state == cpu_Crashed) {
          ((step_fn)step2)(m, d);
          return stalled(a, state == cpu_Done ? "the MCU stopped (it slept with interrupts off)" : "the MCU crashed");
        }
      }
      drive_update(a, 0);
      for (i = 0; i < 2; i++) {
        double span = (double)(a->avr->cycle - from);
        double drive = span > 0 ? a->drive_sum[i] / span : a->drive_now[i];
        d->ctrl[i == 0 ? s->actuator_left : s->actuator_right] = drive * s->supply_voltage;
      }
    }
    memcpy(&ticks, a->avr->data + a->a_ticks, sizeof ticks);
    while (a->ticks_seen < (int64_t)ticks) { /* at most one per step unless the period is shorter than h */
      a->ticks_seen++;
      record_tick(a);
    }
    ((step_fn)step2)(m, d);
    power = lf_motor_power(m, d, s->actuator_left) + lf_motor_power(m, d, s->actuator_right);
    s->energy_j += h * power;
    s->last_time = d->time;
    /* the watchdog, on simulated time */
    if (a->avr->cycle - a->tick_cycle > a->stall_cycles) {
      snprintf(why, sizeof why, "no control tick completed for %.3g s", (double)(a->avr->cycle - a->tick_cycle) / a->f_cpu);
      return stalled(a, why);
    }
    for (i = 0; i < a->nsensor; i++) {
          if (a->avr->cycle - a->released[i] > a->stall_cycles) {
        snprintf(why, sizeof why, "sensor %d's line (P%c%d) was not released for %.3g s", i, name_of[sensor_pins[i][0]],
                 sensor_pins[i][1], (double)(a->avr->cycle - a->released[i]) / a->f_cpu);
        return stalled(a, why);
      }
    }
    if (a->avr->cycle - a->pwm_written > a->stall_cycles) {
      snprintf(why, sizeof why, "no motor PWM compare value was written for %.3g s",
               (double)(a->avr->cycle - a->pwm_written) / a->f_cpu);
      return stalled(a, why);
    }
  }
  return LF_AVR_RUNNING;
}

const char *lf_avr_message(const lf_avr *a) { return a->message; }

/* Hand Python the UART bytes received since the last call (at most cap). */
int32_t lf_avr_uart(lf_avr *a, char *out, int32_t cap) {
  int32_t n = a->uart_len < cap ? a->uart_len : cap;
  memcpy(out, a->uart, (size_t)n);
  memmove(a->uart, a->uart + n, (size_t)(a->uart_len - n));
  a->uart_len -= n;
  return n;
}

void lf_avr_status_of(const lf_avr *a, lf_avr_status *status) {
  *status = a->status;
  status->cycle = a->avr->cycle;
  status->ticks = a->ticks_seen;
}
