/* The 3pi's 8x2 character LCD: an HD44780-compatible controller on a 4-bit bus (board_3pi_pins.h), driven as
 * libpololu-avr's OrangutanLCD drives it (src/OrangutanLCD/OrangutanLCD.cpp: init2, send, sendData, busyWait).
 *
 * Writes are latched on E's falling edge with R/W low: in 8-bit mode (its state at power-up) one nibble on DB4..DB7
 * is a whole instruction (DB0..DB3 are not wired); after "function set, 4-bit" each byte is two nibbles, high first.
 * A read (R/W high) drives DB7 while E is high: the busy flag on the first nibble, address counter bit 3 on the
 * second; the controller is busy 37 us after an instruction and 1.52 ms after clear or home (Hitachi HD44780U
 * datasheet, Table 6), so a program's busy-flag polling paces it as on the robot. It drives DB7 only (the line
 * busyWait reads); it drives nothing while R/W is low. Any byte sequence is taken: unknown instructions do nothing,
 * addresses wrap, so garbage on the lines gives a garbled screen, never a fault.
 *
 * What the screen shows is kept when the program has not written for LCD_QUIET_S: each rewrite of a screen (Pololu's
 * examples clear and reprint every 100 ms) gives one frame, and a frame equal to the last is not kept again. A program
 * that rewrites the screen without pause (a clock, a counter: `lcd_goto_xy(0, 0); print(...)` in a loop) is never
 * quiet, so its screen is also kept when a pass begins (clear, home or an address set) after LCD_REWRITE_S of writing,
 * as the previous pass left it, and after LCD_STALE_S of writing in any case; lf_avr_lcd_flush keeps the screen at the
 * end of a run. */
#include <string.h>

#include <simavr/avr_ioport.h>
#include <simavr/sim_io.h>
#include <simavr/sim_irq.h>

#include "avr_glue.h"

#define LCD_QUIET_S 0.005
#define LCD_REWRITE_S 0.1 /* a screen rewritten without pause is kept at most this often, at the start of a pass */
#define LCD_STALE_S 1.0   /* … and, written without pause nor new pass, at least this often */
#define LCD_SHORT_S 37e-6 /* execution time of most instructions */
#define LCD_LONG_S 1.52e-3 /* clear display, return home */

static const int data_pins[4][2] = LF_LCD_DATA_PINS;

/* A line's level as the LCD sees it: what the MCU drives on an output, else the pin's state (pull-up, the LCD's own
 * drive, or what it last was). */
static int level(const lf_avr *a, int port, int bit) {
  uint8_t mask = (uint8_t)(1u << bit);
  if (reg(a, ddr_of[port]) & mask) return (reg(a, port_of[port]) & mask) != 0;
  return (reg(a, port_of[port] - 2) & mask) != 0; /* PINx sits two below PORTx */
}

static uint8_t next_address(uint8_t ac, int inc, int lines2) {
  if (!lines2) return (uint8_t)(inc ? (ac + 1) % 80 : (ac + 79) % 80);
  if (inc) return ac == 0x27 ? 0x40 : ac == 0x67 ? 0x00 : (uint8_t)((ac + 1) & 0x7f);
  return ac == 0x40 ? 0x27 : ac == 0x00 ? 0x67 : (uint8_t)((ac - 1) & 0x7f);
}

static void screen(const lf_board *b, lf_lcd_frame *f) {
  int line, col;
  memset(f, 0, sizeof *f);
  for (line = 0; line < 2; line++)
    for (col = 0; col < 8; col++) {
      int at = b->lines2 ? (line ? 0x40 : 0) + (col + b->shift) % 40 : line ? -1 : (col + b->shift) % 80;
      f->text[line * 8 + col] = at < 0 ? ' ' : b->ddram[at];
    }
  memcpy(f->cgram, b->cgram, sizeof f->cgram);
  f->on = b->on;
}

/* Keep what the screen shows now (as it stood at `cycle`), unless it equals the last screen kept; `rewriting`: kept
 * while the program goes on writing (at a pass's start, or stale), not after a pause. */
static void keep_screen(lf_avr *a, uint64_t cycle, int rewriting) {
  lf_board *b = &a->board;
  lf_lcd_frame f;
  b->dirty = 0, b->rewriting = rewriting;
  screen(b, &f);
  f.cycle = cycle;
  if (b->have_last && !memcmp(f.text, b->last.text, sizeof f.text) && !memcmp(f.cgram, b->last.cgram, sizeof f.cgram) &&
      f.on == b->last.on)
    return;
  b->last = f, b->have_last = 1;
  if (b->nframes < LCD_FRAMES) b->frames[b->nframes++] = f;
  else b->lost.frames_lost++;
}

/* An instruction that starts a new pass over the screen (clear, home, set DDRAM address). */
static int starts_pass(uint8_t byte) {
  return (byte & 0x80) || byte == 0x01 || (byte & 0xfe) == 0x02;
}

static void instruction(lf_avr *a, uint8_t byte) {
  lf_board *b = &a->board;
  double busy = LCD_SHORT_S;
  if (byte & 0x80) { /* set DDRAM address */
    b->ac = (uint8_t)(byte & 0x7f), b->cg = 0;
  } else if (byte & 0x40) { /* set CGRAM address */
    b->cg_ac = (uint8_t)(byte & 0x3f), b->cg = 1;
  } else if (byte & 0x20) { /* function set */
    b->mode8 = (byte >> 4) & 1, b->lines2 = (byte >> 3) & 1;
  } else if (byte & 0x10) { /* cursor or display shift */
    int right = (byte >> 2) & 1;
    if (byte & 0x08) b->shift = (uint8_t)((b->shift + (right ? 39 : 1)) % 40);
    else b->ac = next_address(b->ac, right, b->lines2);
  } else if (byte & 0x08) { /* display on/off */
    b->on = (byte >> 2) & 1;
  } else if (byte & 0x04) { /* entry mode */
    b->inc = (byte >> 1) & 1, b->eshift = byte & 1;
  } else if (byte & 0x02) { /* return home */
    b->ac = 0, b->shift = 0, b->cg = 0, busy = LCD_LONG_S;
  } else if (byte & 0x01) { /* clear display */
    memset(b->ddram, ' ', sizeof b->ddram);
    b->ac = 0, b->shift = 0, b->cg = 0, b->inc = 1, busy = LCD_LONG_S;
  }
  b->busy_until = a->avr->cycle + cycles_of(a, busy);
}

static void data(lf_avr *a, uint8_t byte) {
  lf_board *b = &a->board;
  if (b->cg) {
    b->cgram[b->cg_ac] = (uint8_t)(byte & 0x1f);
    b->cg_ac = (uint8_t)((b->cg_ac + (b->inc ? 1 : 63)) & 0x3f);
  } else {
    b->ddram[b->ac & 0x7f] = byte;
    b->ac = next_address(b->ac, b->inc, b->lines2);
    if (b->eshift) b->shift = (uint8_t)((b->shift + (b->inc ? 1 : 39)) % 40);
  }
  b->busy_until = a->avr->cycle + cycles_of(a, LCD_SHORT_S);
}

/* E fell with R/W low: a nibble on DB4..DB7. */
static void latch(lf_avr *a) {
  lf_board *b = &a->board;
  uint8_t nibble = 0, byte;
  int rs = level(a, LF_PORT_D, LF_LCD_RS_PIN), k;
  for (k = 0; k < 4; k++) nibble |= (uint8_t)(level(a, data_pins[k][0], data_pins[k][1]) << k);
  if (b->mode8) {
    byte = (uint8_t)(nibble << 4), b->phase = 0;
  } else if (!b->phase) {
    b->hi = nibble, b->phase = 1;
    return;
  } else {
    byte = (uint8_t)(b->hi << 4 | nibble), b->phase = 0;
  }
  if (!rs && b->dirty && starts_pass(byte) && a->avr->cycle - b->dirty_since >= cycles_of(a, LCD_REWRITE_S))
    keep_screen(a, b->last_write, 1); /* the previous pass, whole: a screen rewritten without pause */
  if (rs) data(a, byte);
  else instruction(a, byte);
  if (!b->dirty) b->dirty_since = a->avr->cycle;
  b->last_write = a->avr->cycle;
  b->dirty = 1;
}

/* Drive DB7 (PD7) from the LCD while it is being read, or let it go. */
static void drive_db7(lf_avr *a, int drive, int value) {
  avr_ioport_external_t e;
  e.name = 'D';
  e.mask = drive ? (uint8_t)(1u << data_pins[3][1]) : 0;
  e.value = drive && value ? e.mask : 0;
  avr_ioctl(a->avr, AVR_IOCTL_IOPORT_SET_EXTERNAL('D'), &e);
}

/* PORTD written (it holds E and RS; simavr updates the pins right after this returns). */
static void on_port_d(struct avr_irq_t *irq, uint32_t value, void *param) {
  lf_avr *a = (lf_avr *)param;
  lf_board *b = &a->board;
  int e = level(a, LF_PORT_D, LF_LCD_E_PIN);
  (void)irq;
  (void)value;
  if (b->plugged && e != b->e) {
    b->e = (uint8_t)e;
    if (e && level(a, LF_PORT_B, LF_LCD_RW_PIN)) { /* a read begins */
      int bit = b->mode8 || !b->phase ? a->avr->cycle < b->busy_until : (b->ac >> 3) & 1;
      b->reading = 1;
      if (!level(a, LF_PORT_D, LF_LCD_RS_PIN)) drive_db7(a, 1, bit);
    } else if (!e && b->reading) { /* a read ends */
      b->reading = 0;
      drive_db7(a, 0, 0);
      if (!b->mode8) b->phase ^= 1;
    } else if (!e) {
      latch(a);
    }
  }
  pil_led_update(a);
}

void pil_connect_lcd(lf_avr *a) {
  lf_board *b = &a->board;
  memset(b->ddram, ' ', sizeof b->ddram);
  b->mode8 = 1, b->inc = 1, b->plugged = 1; /* the controller's state after its internal reset */
  avr_irq_register_notify(avr_io_getirq(a->avr, AVR_IOCTL_IOPORT_GETIRQ('D'), IOPORT_IRQ_REG_PORT), on_port_d, a);
}

void pil_lcd_step(lf_avr *a) {
  lf_board *b = &a->board;
  if (!b->plugged || !b->dirty) return;
  if (a->avr->cycle - b->last_write >= cycles_of(a, LCD_QUIET_S)) keep_screen(a, b->last_write, 0);
  else if (a->avr->cycle - b->dirty_since >= cycles_of(a, LCD_STALE_S)) keep_screen(a, b->last_write, 1);
}

/* The end of a run: keep the screen as it is now if the program wrote since the last screen kept, unless it is
 * rewriting the screen without pause (then the last whole pass, already kept, is what it showed; this one may be
 * half written). */
void lf_avr_lcd_flush(lf_avr *a) {
  if (a->board.plugged && a->board.dirty && !a->board.rewriting) keep_screen(a, a->board.last_write, 0);
}

/* Hand Python the screens kept since the last call (at most cap). */
int32_t lf_avr_lcd_frames(lf_avr *a, lf_lcd_frame *out, int32_t cap) {
  return pil_drain(a->board.frames, &a->board.nframes, sizeof *out, out, cap);
}
