/* Processor in the loop: the robot's firmware ELF runs on an emulated ATmega328P (simavr) in lockstep with MuJoCo.
 * Python's face: twin.pil.mcu. The glue's files, one concern each, share what this header declares:
 *   avr_mcu.c       the MCU's lifetime: an ELF loaded onto a fresh MCU, its RAM and EEPROM, free runs, button B
 *   avr_lockstep.c  the lockstep with the physics, step by step, and its watchdog
 *   avr_sensors.c   the QTR-RC sensor lines: a released line falls when the twin's sensor physics says
 *   avr_motors.c    the motors' voltages, decoded from the timers' PWM and the pins' directions
 *   avr_trace.c     what is read back: each tick from the firmware's RAM, the UART's bytes, the MCU's figures
 *   avr_layout.c    the layout of the structs Python mirrors (twin.pil.layout)
 */
#ifndef LF_AVR_GLUE_H
#define LF_AVR_GLUE_H

#include <stdint.h>

#include <mujoco/mujoco.h>
#include <simavr/sim_avr.h>
#include <simavr/sim_elf.h>

#include "../firmware/avr/board_3pi_pins.h"
#include "../sim/twin_core.h"

/* ATmega328P data-space addresses (datasheet, "Register Summary"): ports, and Timers 0 and 2 for the motors */
enum { PINB = 0x23, DDRB = 0x24, PORTB = 0x25, PINC = 0x26, DDRC = 0x27, PORTC = 0x28, PIND = 0x29, DDRD = 0x2A,
       PORTD = 0x2B, TCCR0A = 0x44, TCCR0B = 0x45, OCR0A = 0x47, OCR0B = 0x48, TCCR2A = 0xB0, TCCR2B = 0xB1,
       OCR2A = 0xB3, OCR2B = 0xB4 };
/* by LF_PORT_*: a port's direction and output registers and its letter (simavr names its IRQs by the letter) */
static const uint8_t ddr_of[3] = {DDRB, DDRC, DDRD}, port_of[3] = {PORTB, PORTC, PORTD};
static const char name_of[3] = {'B', 'C', 'D'};
static const int sensor_pins[LF_BOARD_MAX_SENSORS][2] = LF_SENSOR_PINS; /* {port, bit} of sensor i */

#define UART_KEEP 65536
#define MESSAGE 256

/* The firmware's lf_state as avr-gcc lays it out: no padding, lf_real a 32-bit float. */
#pragma pack(push, 1)
typedef struct {
  uint16_t cal_min[LF_MAX_SENSORS], cal_max[LF_MAX_SENSORS], value[LF_MAX_SENSORS];
  int32_t position, last_position, line_seen, mode;
  uint32_t tick;
  float e, e_prev, integral, v, omega, duty_left, duty_right;
} avr_lf_state;
#pragma pack(pop)

typedef struct {
  int32_t index; /* a sensor, for its cycle timer's callback */
} sensor_ref;

/* The MCU's figures for the run so far (Python: twin.pil.layout.McuStatus). */
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

typedef struct lf_avr {
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
} lf_avr;

static inline uint8_t reg(const lf_avr *a, uint16_t addr) { return a->avr->data[addr]; }

/* Shared by the glue's files only: not exported from the library. */
#pragma GCC visibility push(hidden)
/* avr_sensors.c */
void pil_connect_sensors(lf_avr *a); /* watch the ports' directions: a sensor line released, a motor line's DDR */
/* avr_motors.c */
void pil_connect_motors(lf_avr *a);  /* watch the motors' compare registers */
void pil_motor_direction(lf_avr *a, int port, uint8_t ddr); /* a DDR write on a port other than C */
void pil_drive_begin(lf_avr *a);     /* a physics step begins: the drive so far belongs to earlier steps */
void pil_drive_end(lf_avr *a, uint64_t from); /* the step's mean drive since cycle from, as voltages in d->ctrl */
/* avr_trace.c */
void pil_connect_uart(lf_avr *a);    /* keep the UART's bytes for Python */
void pil_trace_ticks(lf_avr *a);     /* trace the ticks the firmware finished since the last call */
#pragma GCC visibility pop

/* Python's API (twin.pil.mcu) */
lf_avr *lf_avr_open(const char *elf_path, const char *mmcu, uint32_t f_cpu, char *err, int32_t errlen);
void lf_avr_close(lf_avr *a);
int32_t lf_avr_symbol(const lf_avr *a, const char *name);
int32_t lf_avr_eeprom(lf_avr *a, const uint8_t *image, uint32_t size);
int32_t lf_avr_peek(const lf_avr *a, uint32_t addr, uint8_t *out, uint32_t n);
int32_t lf_avr_poke(lf_avr *a, uint32_t addr, const uint8_t *in, uint32_t n);
int32_t lf_avr_run_cycles(lf_avr *a, uint64_t cycles);
int32_t lf_avr_run_until_clear(lf_avr *a, uint32_t addr, uint64_t max_cycles);
void lf_avr_button(lf_avr *a, int32_t pressed);
void lf_avr_attach(lf_avr *a, const mjModel *m, mjData *d, lf_sim *s, double stall_s);
void lf_avr_zero_time(lf_avr *a);
int32_t lf_avr_lockstep(lf_avr *a, void *step1, void *step2, int64_t nstep);
const char *lf_avr_message(const lf_avr *a);
int32_t lf_avr_state(const lf_avr *a, lf_state *out);
void lf_avr_reset_stats(lf_avr *a);
void lf_avr_status_of(const lf_avr *a, lf_avr_status *status);
int32_t lf_avr_uart(lf_avr *a, char *out, int32_t cap);
int32_t lf_avr_layout(const lf_field **fields);

#endif
