/* Minimal ATmega328P program around the firmware, to prove it builds for the robot's MCU and to measure its
 * flash and RAM use. The real sketch replaces read_sensors/set_motors with the QTR-RC and motor drivers. */
#include "line_follower.h"
#include "lf_wire.h"

#include <avr/io.h>

static lf_state state;
static lf_params params;

static void read_sensors(uint16_t *raw, int32_t count) {
  int32_t i;
  for (i = 0; i < count; i++) raw[i] = (uint16_t)(PINB + 8u * i) << 3; /* stand-in for the RC timing */
}

static void send(const char *line, int n) { /* stand-in for the UART / Bluetooth SPP driver */
  int i;
  for (i = 0; i < n; i++) UDR0 = (uint8_t)line[i];
}

static void set_motors(lf_real left, lf_real right) {
  OCR0A = (uint8_t)(127.0 + 127.0 * left);
  OCR0B = (uint8_t)(127.0 + 127.0 * right);
}

int main(void) {
  uint16_t raw[LF_MAX_SENSORS];
  char line[LF_WIRE_MAX];
  uint32_t t_ms = 0;
  params.count = 8;
  params.pitch_m = 0.009525;
  params.sensor_distance_m = 0.04;
  params.v_max = 0.8;
  params.k_b = 0.5;
  params.k_p = 20.0;
  params.k_i = 0.0;
  params.k_d = 0.5;
  params.dt_s = 0.005;
  params.wheel_radius_m = 0.016;
  params.half_track_m = 0.0425;
  params.wheel_speed_max = 75.4;
  params.accel_max = 4.0;
  params.integral_limit = 1.0;
  params.cal_duty = 0.15;
  params.cal_sweep_rad = 1.0;
  params.cal_sweeps = 2;
  lf_calibrate_reset(&state, 2500);
  lf_reset(&state, LF_CALIBRATE);
  for (;;) {
    read_sensors(raw, params.count);
    lf_step(&state, &params, raw);
    if (state.mode == LF_IDLE) lf_reset(&state, LF_RUN);
    set_motors(state.duty_left, state.duty_right);
    t_ms += 5;
    if ((state.tick & 1u) == 0) /* telemetry every 2 ticks */
      send(line, lf_wire_sample(line, t_ms, state.position, state.line_seen, (int32_t)(state.duty_left * 7540),
                                (int32_t)(state.duty_right * 7540)));
    if (state.tick == 1) send(line, lf_wire_start(line, t_ms));
  }
}
