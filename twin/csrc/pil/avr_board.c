/* The rest of the 3pi's board around the MCU (board_3pi_pins.h), for any program:
 *   buttons   A, B, C pull their lines low when held (lf_avr_buttons, avr_mcu.c); a read of PINB with a button line an
 *             input with its pull-up, outside a sensor read, counts as polling the buttons (Python's operator waits
 *             for it);
 *   LEDs      red PD1 and green PD7, lit when driven high; the UART's TX (PD1) idles high. A line's share of the step
 *             high decides what the LED shows (the LCD's microsecond writes on PD7 do not light it); the time each
 *             line was high is counted to the cycle, so a PWM-dimmed LED's brightness is its share of the run;
 *   buzzer    Timer1's PWM on OC1B (PB2): each note's frequency from the timer's mode, prescaler and TOP, its duty
 *             from OCR1B, as OrangutanBuzzer sets them (src/OrangutanBuzzer/OrangutanBuzzer.cpp, playFrequency);
 *   ADC       ADC6: 2/3 of the battery voltage, ADC7: the trimmer, against AVCC = 5 V (OrangutanAnalog.cpp,
 *             readBatteryMillivolts_3pi: (mV * 3 + 1) / 2);
 *   notes     registers of peripherals nothing on the board answers (LF_USED_*);
 *   trace     for any program, the physics every trace_every steps into the head's ring: pose, motor voltages,
 *             wheel speeds, the sensors' decay times; v and omega from the pose's change. Nothing comes from the
 *             program's memory. */
#include <math.h>
#include <string.h>

#include <simavr/avr_adc.h>
#include <simavr/avr_ioport.h>
#include <simavr/sim_io.h>
#include <simavr/sim_irq.h>

#include "avr_glue.h"

#define SENSOR_READ_S 0.005 /* a PINB read this soon after a sensor line's release belongs to the sensor read */
#define NOTE_MIN_S 0.0005 /* shorter: Timer1's registers rewritten one after the other (a note's end, the next's start) */
#define BUTTON_MASK ((1u << 1) | (1u << 4) | (1u << 5))

void lf_avr_board(lf_avr *a, int32_t lcd_plugged, double battery_v, double trimmer_v, int64_t trace_every) {
  avr_irq_t *adc = avr_io_getirq(a->avr, AVR_IOCTL_ADC_GETIRQ, 0);
  a->board.plugged = lcd_plugged;
  a->board.trace_every = trace_every;
  if (adc) {
    avr_raise_irq(adc + ADC_IRQ_ADC0 + LF_ADC_BATTERY, (uint32_t)(battery_v * 2.0 / 3.0 * 1000.0 + 0.5));
    avr_raise_irq(adc + ADC_IRQ_ADC0 + LF_ADC_TRIMMER, (uint32_t)(trimmer_v * 1000.0 + 0.5));
  }
}

/* --- buttons: simavr's PINB reader, and a count of the reads that poll the buttons */
static uint8_t on_pinb_read(avr_t *avr, avr_io_addr_t addr, void *param) {
  lf_avr *a = (lf_avr *)param;
  uint8_t v = a->board.pinb_read(avr, addr, a->board.pinb_param);
  uint8_t inputs = (uint8_t)(~reg(a, DDRB) & reg(a, PORTB) & BUTTON_MASK);
  if (inputs && a->avr->cycle - a->board.last_release >= cycles_of(a, SENSOR_READ_S)) {
    a->board.last_poll = a->avr->cycle;
    a->board.polls++;
  }
  return v;
}

/* --- LEDs */
static int led_line(const lf_avr *a, int pin) {
  uint8_t bit = (uint8_t)(1u << pin);
  if (pin == LF_LED_RED_PIN && a->board.txen) return 1; /* TXEN0: the UART drives TX, idling high */
  return (reg(a, DDRD) & bit) && (reg(a, PORTD) & bit);
}

void pil_led_update(lf_avr *a) {
  lf_board *b = &a->board;
  uint64_t now = a->avr->cycle;
  int k;
  for (k = 0; k < 2; k++) {
    if (b->led_now[k]) b->led_on[k] += now - b->led_since, b->led_lit[k] += now - b->led_since;
    b->led_now[k] = led_line(a, k ? LF_LED_GREEN_PIN : LF_LED_RED_PIN);
  }
  b->led_since = now;
}

static void leds_step(lf_avr *a, uint64_t from) {
  lf_board *b = &a->board;
  uint64_t span = a->avr->cycle - from;
  int k, shown[2], changed = 0;
  pil_led_update(a);
  for (k = 0; k < 2; k++) {
    shown[k] = span ? 2 * b->led_on[k] >= span : b->led_now[k];
    changed |= shown[k] != b->led_shown[k];
    b->led_shown[k] = shown[k];
    b->led_on[k] = 0;
  }
  if (!changed) return;
  if (b->nleds < LED_EVENTS) {
    lf_led_event *e = &b->leds[b->nleds++];
    e->cycle = a->avr->cycle, e->red = shown[0], e->green = shown[1];
  } else {
    b->lost.leds_lost++;
  }
}

/* --- buzzer */
static void buzzer_update(lf_avr *a, int restart) {
  static const int prescale[8] = {0, 1, 8, 64, 256, 1024, 0, 0};
  lf_board *b = &a->board;
  uint8_t ca = reg(a, TCCR1A), cb = reg(a, TCCR1B), com = (uint8_t)((ca >> 4) & 3);
  int wgm = (ca & 3) | ((cb >> 1) & 0xc), n = prescale[cb & 7];
  double top = 0, hz = 0, duty = 0;
  unsigned ocra = reg(a, OCR1AL) | (unsigned)reg(a, OCR1AL + 1) << 8, ocrb = reg(a, OCR1BL) | (unsigned)reg(a, OCR1BL + 1) << 8;
  unsigned icr = reg(a, ICR1L) | (unsigned)reg(a, ICR1L + 1) << 8;
  int sounding;
  switch (wgm) {
    case 1: case 2: case 3: top = (1 << (wgm + 7)) - 1; break;  /* phase correct, 8/9/10-bit */
    case 5: case 6: case 7: top = (1 << (wgm + 3)) - 1; break;  /* fast, 8/9/10-bit */
    case 8: case 10: case 14: case 12: top = icr; break;
    case 9: case 11: case 15: case 4: top = ocra; break;
    default: top = 0;
  }
  if (n && top > 0 && com) {
    if (wgm == 4 || wgm == 12) { /* CTC: a toggling OC1B is a square wave */
      hz = com == 1 ? a->f_cpu / (2.0 * n * (top + 1)) : 0, duty = 0.5;
    } else {
      int fast = wgm == 5 || wgm == 6 || wgm == 7 || wgm == 14 || wgm == 15;
      hz = fast ? a->f_cpu / (n * (top + 1)) : a->f_cpu / (2.0 * n * top);
      duty = fmin(1.0, (double)ocrb / top);
      if (com == 3) duty = 1.0 - duty;
      if (com == 1) hz = 0; /* toggle mode on OC1B in PWM modes: disconnected */
    }
  }
  sounding = hz > 0 && duty > 0 && duty < 1 && (reg(a, DDRB) & (1u << LF_BUZZER_PIN));
  if (b->sounding && (!sounding || restart || hz != b->note.hz || duty != b->note.duty)) {
    b->note.end = a->avr->cycle;
    if (b->note.end - b->note.start < cycles_of(a, NOTE_MIN_S)) { /* registers passing through a state, not a note */
    } else if (b->nnotes < NOTES) {
      b->notes[b->nnotes++] = b->note;
    } else {
      b->lost.notes_lost++;
    }
    b->sounding = 0;
  }
  if (sounding && !b->sounding) {
    b->note.start = a->avr->cycle, b->note.end = 0, b->note.hz = hz, b->note.duty = duty;
    b->sounding = 1;
  }
}

static void on_timer1_write(avr_t *avr, avr_io_addr_t addr, uint8_t v, void *param) {
  (void)avr;
  (void)v;
  buzzer_update((lf_avr *)param, addr == OCR1BL); /* OrangutanBuzzer writes OCR1B last for every note */
}

/* PORTB written: PB2 toggled with Timer1's output disconnected is a buzzer driven by hand. */
static void on_port_b(struct avr_irq_t *irq, uint32_t value, void *param) {
  lf_avr *a = (lf_avr *)param;
  uint8_t pb2 = (uint8_t)(value & (1u << LF_BUZZER_PIN));
  (void)irq;
  if (pb2 != a->board.pb2_seen && (reg(a, DDRB) & (1u << LF_BUZZER_PIN)) && !(reg(a, TCCR1A) & 0x30))
    a->board.used |= LF_USED_BUZZER_GPIO;
  a->board.pb2_seen = pb2;
}

/* --- peripherals nothing answers */
static void on_peripheral_write(avr_t *avr, avr_io_addr_t addr, uint8_t v, void *param) {
  lf_avr *a = (lf_avr *)param;
  uint32_t used = 0;
  (void)avr;
  switch (addr) {
    case SPCR: used = v & 0x40 ? LF_USED_SPI : 0; break;
    case TWCR: used = v & 0x04 ? LF_USED_TWI : 0; break;
    case ADCSRA: used = (v & 0x40) && (reg(a, ADMUX) & 0x0f) < 6 ? LF_USED_ADC_PIN : 0; break;
    case UCSR0B: /* simavr's reset leaves TXEN0 set; only a program's own write turns the transmitter on here */
      used = v & 0x10 ? LF_USED_UART_RX : 0;
      pil_led_update(a);
      a->board.txen = (v & 0x08) != 0;
      pil_led_update(a);
      break;
    case ACSR: used = v & 0x08 ? LF_USED_COMPARATOR : 0; break;
    case TIMSK1: used = (v & 0x20) && !pil_timer1_top_is_icr(a) ? LF_USED_CAPTURE : 0; break; /* (at TOP: modelled) */
    case EIMSK: used = v & 0x03 ? LF_USED_INT01 : 0; break;
    default: break;
  }
  a->board.used |= used;
}

/* simavr's avr_reset calls every I/O module's reset hook: after power-up only the watchdog resets the 3pi's MCU
 * (no reset button is pressed, no brown-out is modelled), so this counts the program's watchdog resets. */
static void on_reset(avr_io_t *io) {
  lf_avr *a = ((lf_reset_watch *)io)->a;
  lf_board *b = &a->board;
  if (!b->resets) b->first_reset = a->avr->cycle;
  b->resets++, b->last_reset = a->avr->cycle;
}

void pil_connect_board(lf_avr *a) {
  static const uint16_t timer1[] = {TCCR1A, TCCR1B, ICR1L, OCR1AL, OCR1BL};
  static const uint16_t watched[] = {SPCR, TWCR, ADCSRA, UCSR0B, ACSR, TIMSK1, EIMSK};
  size_t i;
  avr_io_addr_t pinb = AVR_DATA_TO_IO(PINB);
  a->board.pinb_read = a->avr->io[pinb].r.c, a->board.pinb_param = a->avr->io[pinb].r.param;
  a->avr->io[pinb].r.c = on_pinb_read, a->avr->io[pinb].r.param = a; /* simavr refuses a second reader: chain it */
  avr_irq_register_notify(avr_io_getirq(a->avr, AVR_IOCTL_IOPORT_GETIRQ('B'), IOPORT_IRQ_REG_PORT), on_port_b, a);
  for (i = 0; i < sizeof timer1 / sizeof timer1[0]; i++) pil_watch_write(a, timer1[i], on_timer1_write, 0);
  for (i = 0; i < sizeof watched / sizeof watched[0]; i++) pil_watch_write(a, watched[i], on_peripheral_write, 0);
  a->board.reset_watch.io.kind = "lf_reset_count";
  a->board.reset_watch.io.reset = on_reset;
  a->board.reset_watch.a = a;
  avr_register_io(a->avr, &a->board.reset_watch.io); /* after avr_init: power-up's own reset is not counted */
}

/* --- the physics trace */
static void trace_physics(lf_avr *a) {
  lf_board *b = &a->board;
  lf_sim *s = a->s;
  lf_record *r;
  double dt;
  int i;
  memset(&s->fw, 0, sizeof s->fw);
  s->fw.line_seen = 1; /* not the program's: line loss is not judged for a program the twin cannot read */
  for (i = 0; i < s->nsensor; i++) s->raw[i] = (uint16_t)fmin(65535.0, a->physics_us[i] + 0.5);
  lf_write_record(a->m, a->d, s, 0.0, a->height0, a->drive_step[0] * s->supply_voltage,
                  a->drive_step[1] * s->supply_voltage); /* commanded: the drive at the nominal supply */
  r = (lf_record *)(s + 1) + ((s->records_written - 1) % s->record_capacity);
  dt = r->time_s - b->prev_t;
  if (b->have_prev && dt > 0) {
    double dyaw = remainder(r->yaw_rad - b->prev_yaw, 6.283185307179586);
    r->v_mps = ((r->x_m - b->prev_x) * cos(r->yaw_rad) + (r->y_m - b->prev_y) * sin(r->yaw_rad)) / dt;
    r->omega_radps = dyaw / dt;
  }
  b->prev_x = r->x_m, b->prev_y = r->y_m, b->prev_yaw = r->yaw_rad, b->prev_t = r->time_s, b->have_prev = 1;
  s->ticks++;
}

void pil_board_step(lf_avr *a, uint64_t from) {
  lf_board *b = &a->board;
  leds_step(a, from);
  if (traced(a) || b->trace_every < 1) return;
  if (b->steps++ % b->trace_every == 0) trace_physics(a);
}

void lf_avr_board_status(const lf_avr *a, lf_board_status *out) {
  const lf_board *b = &a->board;
  *out = b->lost;
  out->last_poll = b->last_poll, out->polls = b->polls, out->last_drive = b->last_drive, out->used = b->used;
  out->buttons = b->buttons, out->red = b->led_shown[0], out->green = b->led_shown[1];
  out->resets = b->resets, out->first_reset = b->first_reset, out->last_reset = b->last_reset;
  out->red_lit = b->led_lit[0] + (b->led_now[0] ? a->avr->cycle - b->led_since : 0);
  out->green_lit = b->led_lit[1] + (b->led_now[1] ? a->avr->cycle - b->led_since : 0);
  if (b->sounding) out->note = b->note;
  else memset(&out->note, 0, sizeof out->note);
}

/* Hand over at most cap of a ring's n events (each size bytes) and keep the rest, in order; returns how many. */
int32_t pil_drain(void *ring, int32_t *n, size_t size, void *out, int32_t cap) {
  int32_t k = *n < cap ? *n : cap;
  memcpy(out, ring, (size_t)k * size);
  memmove(ring, (char *)ring + (size_t)k * size, (size_t)(*n - k) * size);
  *n -= k;
  return k;
}

int32_t lf_avr_notes(lf_avr *a, lf_note *out, int32_t cap) {
  return pil_drain(a->board.notes, &a->board.nnotes, sizeof *out, out, cap);
}

int32_t lf_avr_leds(lf_avr *a, lf_led_event *out, int32_t cap) {
  return pil_drain(a->board.leds, &a->board.nleds, sizeof *out, out, cap);
}
