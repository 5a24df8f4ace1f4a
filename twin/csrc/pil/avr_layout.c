/* The layout of the structs Python mirrors for the processor in the loop (twin.pil.layout): every field's offset and
 * size, compared when the glue loads (the MCU's figures, and what the board shows: LCD screens, notes, LEDs). The firmware's structs are named "avr.<its type>": the glue's copies of them as
 * avr-gcc lays them out (no padding, lf_real a 32-bit float), which tests/test_pil_layout.py compiles against the
 * firmware's own headers with avr-gcc. */
#include <stddef.h>

#include "avr_glue.h"

/* The EEPROM configuration (firmware/avr/config.h) as avr-gcc lays it out. The glue never reads it: Python writes
 * the image (twin.pil.firmware.config_image), and this copy lets the image's layout be checked. */
#pragma pack(push, 1)
typedef struct {
  int32_t count;
  float pitch_m, sensor_distance_m, v_max, k_b, k_p, k_i, k_d, dt_s, wheel_radius_m, half_track_m, wheel_speed_max,
      accel_max, integral_limit, cal_duty, cal_sweep_rad;
  int32_t cal_sweeps;
} avr_lf_params;

typedef struct {
  uint32_t magic;
  uint16_t size;
  avr_lf_params params;
  uint16_t timeout_us;
  uint16_t telemetry_every;
  uint16_t crc;
} avr_lf_config;
#pragma pack(pop)

#define AVR_FIELD(type, field) LF_FIELD_NAMED("avr." #type "." #field, avr_##type, field)
#define WHOLE(name, type) {name, 0, (int64_t)sizeof(type)}

static const lf_field fields[] = {
  WHOLE("avr.lf_state", avr_lf_state),
  AVR_FIELD(lf_state, cal_min), AVR_FIELD(lf_state, cal_max), AVR_FIELD(lf_state, value),
  AVR_FIELD(lf_state, position), AVR_FIELD(lf_state, last_position), AVR_FIELD(lf_state, line_seen),
  AVR_FIELD(lf_state, mode), AVR_FIELD(lf_state, tick), AVR_FIELD(lf_state, e), AVR_FIELD(lf_state, e_prev),
  AVR_FIELD(lf_state, integral), AVR_FIELD(lf_state, v), AVR_FIELD(lf_state, omega), AVR_FIELD(lf_state, duty_left),
  AVR_FIELD(lf_state, duty_right), AVR_FIELD(lf_state, call_min), AVR_FIELD(lf_state, call_max),
  AVR_FIELD(lf_state, call_reads),

  WHOLE("avr.lf_config", avr_lf_config),
  AVR_FIELD(lf_config, magic), AVR_FIELD(lf_config, size), AVR_FIELD(lf_config, params.count),
  AVR_FIELD(lf_config, params.pitch_m), AVR_FIELD(lf_config, params.sensor_distance_m),
  AVR_FIELD(lf_config, params.v_max), AVR_FIELD(lf_config, params.k_b), AVR_FIELD(lf_config, params.k_p),
  AVR_FIELD(lf_config, params.k_i), AVR_FIELD(lf_config, params.k_d), AVR_FIELD(lf_config, params.dt_s),
  AVR_FIELD(lf_config, params.wheel_radius_m), AVR_FIELD(lf_config, params.half_track_m),
  AVR_FIELD(lf_config, params.wheel_speed_max), AVR_FIELD(lf_config, params.accel_max),
  AVR_FIELD(lf_config, params.integral_limit), AVR_FIELD(lf_config, params.cal_duty),
  AVR_FIELD(lf_config, params.cal_sweep_rad), AVR_FIELD(lf_config, params.cal_sweeps),
  AVR_FIELD(lf_config, timeout_us), AVR_FIELD(lf_config, telemetry_every), AVR_FIELD(lf_config, crc),

  WHOLE("lf_avr_status", lf_avr_status),
  LF_FIELD(lf_avr_status, cycle), LF_FIELD(lf_avr_status, ticks), LF_FIELD(lf_avr_status, busy_max),
  LF_FIELD(lf_avr_status, busy_sum), LF_FIELD(lf_avr_status, busy_ticks), LF_FIELD(lf_avr_status, uart_lost),
  LF_FIELD(lf_avr_status, read_error_max_us), LF_FIELD(lf_avr_status, read_error_sum_us),
  LF_FIELD(lf_avr_status, read_errors), LF_FIELD(lf_avr_status, awake),
  LF_FIELD(lf_avr_status, release_cycles_sum), LF_FIELD(lf_avr_status, release_cycles_max),
  LF_FIELD(lf_avr_status, compute_cycles_sum), LF_FIELD(lf_avr_status, compute_cycles_max),
  LF_FIELD(lf_avr_status, compute_cycles_min), LF_FIELD(lf_avr_status, timed_ticks),
  LF_FIELD(lf_avr_status, compute_path_cycles_sum), LF_FIELD(lf_avr_status, compute_path_ticks),

  WHOLE("lf_lcd_frame", lf_lcd_frame),
  LF_FIELD(lf_lcd_frame, cycle), LF_FIELD(lf_lcd_frame, text), LF_FIELD(lf_lcd_frame, cgram), LF_FIELD(lf_lcd_frame, on),
  LF_FIELD(lf_lcd_frame, pad),

  WHOLE("lf_note", lf_note),
  LF_FIELD(lf_note, start), LF_FIELD(lf_note, end), LF_FIELD(lf_note, hz), LF_FIELD(lf_note, duty),

  WHOLE("lf_led_event", lf_led_event),
  LF_FIELD(lf_led_event, cycle), LF_FIELD(lf_led_event, red), LF_FIELD(lf_led_event, green),

  WHOLE("lf_board_status", lf_board_status),
  LF_FIELD(lf_board_status, last_poll), LF_FIELD(lf_board_status, polls), LF_FIELD(lf_board_status, last_drive),
  LF_FIELD(lf_board_status, used), LF_FIELD(lf_board_status, buttons), LF_FIELD(lf_board_status, red),
  LF_FIELD(lf_board_status, green), LF_FIELD(lf_board_status, note), LF_FIELD(lf_board_status, frames_lost),
  LF_FIELD(lf_board_status, notes_lost), LF_FIELD(lf_board_status, leds_lost), LF_FIELD(lf_board_status, resets),
  LF_FIELD(lf_board_status, first_reset), LF_FIELD(lf_board_status, last_reset), LF_FIELD(lf_board_status, red_lit),
  LF_FIELD(lf_board_status, green_lit),
};

int32_t lf_avr_layout(const lf_field **out) {
  *out = fields;
  return (int32_t)(sizeof(fields) / sizeof(fields[0]));
}
