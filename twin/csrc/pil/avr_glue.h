/* Processor in the loop: a program for the robot's ATmega328P runs on an emulated MCU (simavr) in lockstep with
 * MuJoCo, inside a model of the Pololu 3pi's board. Python's face: twin.pil.mcu. The glue's files, one concern each,
 * share what this header declares:
 *   avr_mcu.c       the MCU's lifetime: a program's flash image loaded onto a fresh MCU, its RAM and EEPROM, free runs
 *   avr_timers.c    the timers where simavr 1.6 falls short: phase-correct modes, their compares up and down, ICR1
 *   avr_lockstep.c  the lockstep with the physics, step by step, and the traced firmware's watchdog
 *   avr_sensors.c   the QTR-RC sensor lines: a released line falls when the twin's sensor physics says
 *   avr_motors.c    the motors' voltages, decoded from the timers' PWM and the pins' directions
 *   avr_lcd.c       the 8x2 HD44780 LCD in 4-bit mode, its text captured at quiet moments
 *   avr_board.c     the rest of the board: buttons, LEDs, buzzer, ADC inputs, unmodelled peripherals, the physics
 *                   trace of any program
 *   avr_timing.c    the twin firmware's reaction time: tick to release, the read's end to the PWM write
 *   avr_trace.c     what is read back from the twin's own firmware (its RAM each tick), the UART, the MCU's figures
 *   avr_layout.c    the layout of the structs Python mirrors (twin.pil.layout)
 * The board's wiring (Pololu 3pi Robot User's Guide, section 9, Pin Assignment Tables; libpololu-avr's
 * OrangutanLCD.h, OrangutanPushbuttons.h, OrangutanLEDs.h, OrangutanBuzzer.cpp, OrangutanAnalog.cpp) is in
 * board_3pi_pins.h beside the twin's firmware, which reads the same lines.
 */
#ifndef LF_AVR_GLUE_H
#define LF_AVR_GLUE_H

#include <stddef.h>
#include <stdint.h>

#include <mujoco/mujoco.h>
#include <simavr/sim_avr.h>
#include <simavr/sim_io.h>

#include "../firmware/avr/board_3pi_pins.h"
#include "../sim/twin_core.h"

/* ATmega328P data-space addresses (datasheet, "Register Summary") */
enum { PINB = 0x23, DDRB = 0x24, PORTB = 0x25, PINC = 0x26, DDRC = 0x27, PORTC = 0x28, PIND = 0x29, DDRD = 0x2A,
       PORTD = 0x2B, PCIFR = 0x3B, EIFR = 0x3C, EIMSK = 0x3D, TCCR0A = 0x44, TCCR0B = 0x45, OCR0A = 0x47,
       OCR0B = 0x48, SPCR = 0x4C, ACSR = 0x50,
       TIMSK1 = 0x6F, ADCSRA = 0x7A, ADMUX = 0x7C, TCCR1A = 0x80, TCCR1B = 0x81, ICR1L = 0x86, OCR1AL = 0x88,
       OCR1BL = 0x8A, TCCR2A = 0xB0, TCCR2B = 0xB1, OCR2A = 0xB3, OCR2B = 0xB4, TWCR = 0xBC, UCSR0B = 0xC1 };
/* by LF_PORT_*: a port's direction and output registers and its letter (simavr names its IRQs by the letter) */
static const uint8_t ddr_of[3] = {DDRB, DDRC, DDRD}, port_of[3] = {PORTB, PORTC, PORTD};
static const char name_of[3] = {'B', 'C', 'D'};
static const int sensor_pins[LF_BOARD_MAX_SENSORS][2] = LF_SENSOR_PINS; /* {port, bit} of sensor i */

#define UART_KEEP 65536
#define MESSAGE 256
#define LCD_FRAMES 512
#define NOTES 512
#define LED_EVENTS 512

/* Peripherals the board model does not connect to anything: a program that uses one gets a note (lf_board_status.used;
 * Python words each bit, twin.pil.board.notes). */
enum {
  LF_USED_SPI = 1 << 0,          /* SPCR's SPE: the SPI lines are the motor and button lines; nothing answers */
  LF_USED_TWI = 1 << 1,          /* TWCR's TWEN: I2C is not wired out on the 3pi */
  LF_USED_ADC_PIN = 1 << 2,      /* a conversion of ADC0..5: those pins carry the sensors and the emitter control */
  LF_USED_UART_RX = 1 << 3,      /* UCSR0B's RXEN0: nothing is connected to PD0 */
  LF_USED_COMPARATOR = 1 << 4,   /* ACSR's ACIE: the analog comparator's inputs are not modelled */
  LF_USED_CAPTURE = 1 << 5,      /* TIMSK1's ICIE1 outside the modes with TOP = ICR1: input capture on ICP1 (PB0) */
  LF_USED_INT01 = 1 << 6,        /* EIMSK's INT0/INT1 on PD2/PD3: their level triggering is not polled (avr_mcu.c) */
  LF_USED_BUZZER_GPIO = 1 << 7   /* PB2 toggled by hand, not by Timer1: the buzzer's sound is not captured */
};

/* The firmware's lf_state as avr-gcc lays it out: no padding, lf_real a 32-bit float. */
#pragma pack(push, 1)
typedef struct {
  uint16_t cal_min[LF_MAX_SENSORS], cal_max[LF_MAX_SENSORS], value[LF_MAX_SENSORS];
  int32_t position, last_position, line_seen, mode;
  uint32_t tick;
  float e, e_prev, integral, v, omega, duty_left, duty_right;
  uint16_t call_min[LF_MAX_SENSORS], call_max[LF_MAX_SENSORS];
  int32_t call_reads;
} avr_lf_state;
#pragma pack(pop)

typedef struct {
  int32_t index; /* a sensor, for its cycle timer's callback */
} sensor_ref;

/* The MCU's figures for the run so far (Python: twin.pil.layout.McuStatus). */
typedef struct {
  uint64_t cycle;          /* MCU clock cycles since reset */
  int64_t ticks;           /* control ticks completed (the twin firmware's fw_ticks_done) */
  uint64_t busy_max;       /* most cycles awake in one tick (since lf_avr_reset_stats) */
  uint64_t busy_sum;       /* cycles awake over the ticks counted */
  int64_t busy_ticks;      /* ticks counted */
  int64_t uart_lost;       /* UART bytes not kept because Python had not drained them */
  double read_error_max_us; /* largest |MCU-timed reading - the physics' decay time| of a line that fell in time */
  double read_error_sum_us; /* their sum (signed: MCU minus physics) */
  int64_t read_errors;      /* readings compared */
  uint64_t awake;           /* cycles awake (not in SLEEP) since reset */
  /* the twin firmware's reaction (avr_timing.c), over the ticks timed since lf_avr_reset_stats */
  uint64_t release_cycles_sum, release_cycles_max; /* tick to the sensor lines' release */
  uint64_t compute_cycles_sum, compute_cycles_max, compute_cycles_min; /* the read's end to the first PWM write */
  int64_t timed_ticks;
  /* the same compute split by the code path the tick took (enum lf_compute_path, twin_core.h): cycles, ticks */
  uint64_t compute_path_cycles_sum[LF_COMPUTE_PATHS];
  int64_t compute_path_ticks[LF_COMPUTE_PATHS];
} lf_avr_status;

/* One screen of the LCD, taken when the program had not written to it for LCD_QUIET_S (Python: twin.pil.board). */
typedef struct {
  uint64_t cycle;          /* the last write before the quiet moment */
  uint8_t text[16];        /* character codes shown: line 0, then line 1 (8 each) */
  uint8_t cgram[64];       /* the custom characters' rows, for codes 0..15 */
  int32_t on;              /* display on */
  int32_t pad;
} lf_lcd_frame;

/* A note the buzzer played: Timer1's PWM on OC1B (PB2), as libpololu-avr's OrangutanBuzzer drives it. */
typedef struct {
  uint64_t start, end;     /* cycles; end 0: still sounding */
  double hz;               /* tone frequency [Hz] */
  double duty;             /* the PWM's high share 0..1 (Pololu's volume: OCR1B = OCR1A >> (16 - volume)) */
} lf_note;

/* The user LEDs after a change: red on PD1, green on PD7, lit when driven high (User's Guide, section 9). */
typedef struct {
  uint64_t cycle;
  int32_t red, green;
} lf_led_event;

/* What the board shows Python between chunks (twin.pil.layout.BoardStatus). */
typedef struct {
  uint64_t last_poll;      /* cycle of the last read of the buttons (PINB with a button line an input with its pull-up,
                              not during a sensor read) */
  int64_t polls;           /* such reads */
  uint64_t last_drive;     /* last cycle a motor was driven (a physics step with a non-zero mean drive) */
  uint32_t used;           /* LF_USED_* */
  int32_t buttons;         /* held: A 1, B 2, C 4 */
  int32_t red, green;      /* LEDs now */
  lf_note note;            /* the note sounding now (end 0), if start != 0 */
  int64_t frames_lost, notes_lost, leds_lost; /* events not kept because Python had not drained them */
  int64_t resets;          /* MCU resets after power-up: on this board only its watchdog resets it */
  uint64_t first_reset, last_reset; /* their cycles */
  uint64_t red_lit, green_lit; /* cycles each LED's line was high since power-up: a PWM-dimmed LED's brightness */
} lf_board_status;

/* An I/O module of ours whose only job is simavr's reset hook (avr_board.c): io first, as simavr's modules have it. */
typedef struct {
  avr_io_t io;
  struct lf_avr *a;
} lf_reset_watch;

typedef struct {
  /* HD44780 */
  uint8_t ddram[128], cgram[64];
  uint8_t ac, cg_ac, cg, mode8, lines2, phase, hi, inc, eshift, on, e, reading, shift;
  int32_t plugged;         /* 0: the LCD's lines are sensor lines (the twin's firmware with more than 5 sensors) */
  uint64_t busy_until, last_write, dirty_since; /* dirty_since: the first write not yet in a kept screen */
  int32_t dirty, have_last, rewriting; /* rewriting: the last screen was kept while the program went on writing */
  lf_lcd_frame last;
  lf_lcd_frame frames[LCD_FRAMES];
  int32_t nframes;
  /* buttons */
  avr_io_read_t pinb_read;
  void *pinb_param;
  int32_t buttons;
  uint64_t last_poll, last_release;
  int64_t polls;
  /* buzzer */
  int32_t sounding;
  lf_note note;
  lf_note notes[NOTES];
  int32_t nnotes;
  uint8_t pb2_seen, txen;
  /* LEDs: on-cycles integrated over the step, the shown state, its changes */
  uint64_t led_since, led_on[2], led_lit[2];
  int32_t led_now[2], led_shown[2];
  lf_led_event leds[LED_EVENTS];
  int32_t nleds;
  /* the physics trace of any program */
  uint64_t last_drive;
  int64_t trace_every, steps;
  double prev_x, prev_y, prev_yaw, prev_t;
  int32_t have_prev;
  lf_board_status lost;    /* only the *_lost counters are used */
  uint32_t used;
  lf_reset_watch reset_watch; /* counts the resets after power-up */
  int64_t resets;
  uint64_t first_reset, last_reset;
} lf_board;

/* A write hook chained after what simavr already does at an I/O address (simavr's own chaining has four slots). */
typedef struct {
  avr_io_write_t orig, mine;
  void *orig_param;
  struct lf_avr *a;
  int32_t before;          /* mine runs before simavr's own write (the register still holds its old value) */
} write_hook;
#define WRITE_HOOKS 64

/* A timer in a phase-correct mode, whose compares the glue matches itself (avr_timers.c). */
typedef struct {
  struct lf_avr *a;
  int32_t k;               /* Timer k */
  int32_t active;          /* counting in a phase-correct mode */
  int32_t restart;         /* the TCCR write being handled changes the mode or the clock */
  uint64_t bottom;         /* cycle of this period's BOTTOM */
  uint32_t ocr[2];         /* OCRnA, OCRnB in force (double-buffered: taken at TOP or BOTTOM) */
  uint8_t level[2];        /* OCnA, OCnB */
  uint8_t driving[2];      /* the compare output drives its pin */
  uint16_t r_ocr[2];       /* simavr's compare registers, given back when the timer leaves the mode */
  avr_io_read_t tcnt_read; /* simavr's TCNTn reader, chained */
  void *tcnt_param;
} pil_phase_timer;

typedef struct lf_avr {
  avr_t *avr;
  write_hook hooks[WRITE_HOOKS];
  int32_t nhooks;
  struct avr_timer_t *timers[3];             /* Timer0, 1, 2 (avr_timers.c corrects their phase-correct modes) */
  uint8_t cs_div[3][16];                     /* their prescaler tables as simavr built them */
  pil_phase_timer phase[3];                  /* their compares in a phase-correct mode */
  avr_io_write_t port_write[2];              /* simavr's PORTB and PORTD writers, behind the glue's (avr_timers.c) */
  void *port_param[2];
  uint8_t port_written[2];                   /* what the program last wrote to PORTB and PORTD */
  uint32_t f_cpu;
  /* the twin firmware's globals (data-space addresses, 0 where absent): with all four, each tick is traced from RAM */
  uint16_t a_state, a_raw, a_tick_mode, a_ticks;
  /* lockstep */
  const mjModel *m;
  mjData *d;
  lf_sim *s;
  int32_t nsensor;
  sensor_ref refs[LF_BOARD_MAX_SENSORS];
  uint8_t ddr_seen[3];
  uint64_t zero_cycle;                       /* MCU cycle at MuJoCo time 0 */
  int32_t press_at_zero, press_pending;      /* buttons held from time 0 on (lf_avr_zero_time_at_tick) */
  uint64_t released[LF_BOARD_MAX_SENSORS];   /* cycle of each line's last release */
  int64_t reads[LF_BOARD_MAX_SENSORS];       /* each line's releases since attach: its reading's index (its noise) */
  uint64_t pwm_written;                      /* cycle of the last motor compare write */
  uint64_t tick_cycle;                       /* cycle of the last completed tick */
  uint64_t stall_cycles;                     /* the watchdog's limit */
  double height0;                            /* sensor 0's height at its last release [m] */
  double physics_us[LF_BOARD_MAX_SENSORS];   /* each line's decay time at its last release [us] */
  double physics_prev_us[LF_BOARD_MAX_SENSORS]; /* and at the release before: the read a tick traced may be that one */
  /* motor drive integrated over the step */
  uint64_t drive_since;
  double drive_now[2], drive_sum[2];
  double drive_step[2];                      /* the last step's mean drive, left and right, in [-1, 1] */
  uint8_t tccr_seen[2][2];                   /* the motor timers' control registers when the drive was decoded */
  /* CPU time */
  uint64_t busy, busy_tick_start;
  int64_t ticks_seen;
  /* the reaction of the tick being timed (avr_timing.c) */
  int32_t timing_phase;
  uint64_t timing_tick, timing_release, timing_read_end;
  lf_avr_status status;
  lf_board board;
  /* UART */
  char uart[UART_KEEP];
  int32_t uart_len;
  char message[MESSAGE];
} lf_avr;

static inline uint8_t reg(const lf_avr *a, uint16_t addr) { return a->avr->data[addr]; }
static inline int traced(const lf_avr *a) { return a->a_state && a->a_raw && a->a_tick_mode && a->a_ticks; }
static inline uint64_t cycles_of(const lf_avr *a, double seconds) { return (uint64_t)(seconds * a->f_cpu + 0.5); }

/* Shared by the glue's files only: not exported from the library. */
#pragma GCC visibility push(hidden)
/* avr_timers.c */
void pil_connect_timers(lf_avr *a);  /* the timers' missing modes, their phase-correct compares, ICR1 as TOP */
/* avr_mcu.c */
void pil_watch_write(lf_avr *a, uint16_t addr, avr_io_write_t fn, int before); /* fn(avr, addr, v, a) after (or
                                                                                  before) simavr's own write */
/* avr_sensors.c */
void pil_connect_sensors(lf_avr *a); /* watch the ports' directions: a sensor line released, a motor line's DDR */
/* avr_motors.c */
void pil_connect_motors(lf_avr *a);  /* watch the motors' compare registers */
void pil_motor_direction(lf_avr *a, int port, uint8_t ddr); /* a DDR write on a port other than C */
void pil_drive_begin(lf_avr *a);     /* a physics step begins: the drive so far belongs to earlier steps */
void pil_drive_end(lf_avr *a, uint64_t from); /* the step's mean drive since cycle from, as voltages in d->ctrl */
/* avr_timing.c */
void pil_connect_timing(lf_avr *a);  /* watch the control tick's interrupt */
void pil_timing_release(lf_avr *a, double read_us); /* a sensor line released; it falls read_us later */
void pil_timing_written(lf_avr *a);  /* a motor compare value written */
/* avr_lcd.c */
void pil_connect_lcd(lf_avr *a);     /* watch E, RS, R/W and the data lines */
void pil_lcd_step(lf_avr *a);        /* a step ended: keep the screen if the program has been quiet */
/* avr_board.c */
void pil_connect_board(lf_avr *a);   /* buttons, LEDs, buzzer, ADC inputs, the unmodelled peripherals' registers */
void pil_board_step(lf_avr *a, uint64_t from); /* the step since cycle from ended: LEDs shown, the physics trace */
void pil_led_update(lf_avr *a);      /* a port D line may have changed */
int32_t pil_drain(void *ring, int32_t *n, size_t size, void *out, int32_t cap); /* events to Python, in order */
/* avr_trace.c */
void pil_connect_uart(lf_avr *a);    /* keep the UART's bytes for Python */
void pil_trace_ticks(lf_avr *a, uint64_t step_from_cycle); /* trace the ticks the firmware finished since the last call */
#pragma GCC visibility pop

/* Python's API (twin.pil.mcu) */
lf_avr *lf_avr_open(const uint8_t *flash, uint32_t flash_size, const uint8_t *eeprom, uint32_t eeprom_size,
                    const char *mmcu, uint32_t f_cpu, char *err, int32_t errlen);
void lf_avr_close(lf_avr *a);
void lf_avr_trace_globals(lf_avr *a, uint16_t state, uint16_t raw, uint16_t tick_mode, uint16_t ticks);
void lf_avr_board(lf_avr *a, int32_t lcd_plugged, double battery_v, double trimmer_v, int64_t trace_every);
int32_t lf_avr_eeprom(lf_avr *a, const uint8_t *image, uint32_t size);
int32_t lf_avr_peek(const lf_avr *a, uint32_t addr, uint8_t *out, uint32_t n);
int32_t lf_avr_poke(lf_avr *a, uint32_t addr, const uint8_t *in, uint32_t n);
int32_t lf_avr_run_cycles(lf_avr *a, uint64_t cycles);
int32_t lf_avr_run_until_clear(lf_avr *a, uint32_t addr, uint64_t max_cycles);
void lf_avr_buttons(lf_avr *a, int32_t pressed);
void lf_avr_attach(lf_avr *a, const mjModel *m, mjData *d, lf_sim *s, double stall_s);
void lf_avr_zero_time(lf_avr *a);
/* time 0 at the twin firmware's next control tick, the buttons in `pressed` held from then on */
void lf_avr_zero_time_at_tick(lf_avr *a, double period_s, int32_t pressed);
int32_t lf_avr_lockstep(lf_avr *a, void *step1, void *step2, int64_t nstep);
const char *lf_avr_message(const lf_avr *a);
int32_t lf_avr_state(const lf_avr *a, lf_state *out);
void lf_avr_reset_stats(lf_avr *a);
void lf_avr_status_of(const lf_avr *a, lf_avr_status *status);
void lf_avr_board_status(const lf_avr *a, lf_board_status *status);
int32_t lf_avr_uart(lf_avr *a, char *out, int32_t cap);
int32_t lf_avr_lcd_frames(lf_avr *a, lf_lcd_frame *out, int32_t cap);
void lf_avr_lcd_flush(lf_avr *a);
int pil_timer1_top_is_icr(lf_avr *a); /* Timer1's WGM (8, 10, 14) when it runs with TOP = ICR1 and a capture flag at TOP, else 0 */
int32_t lf_avr_notes(lf_avr *a, lf_note *out, int32_t cap);
int32_t lf_avr_leds(lf_avr *a, lf_led_event *out, int32_t cap);
int32_t lf_avr_layout(const lf_field **fields);

#endif
