/* A test program, not the robot's: it runs the portable firmware's functions on the MCU for inputs the host puts
 * in RAM, so their 16-bit int and 32-bit float arithmetic can be compared with the host build's
 * (tests/test_mcu_arithmetic.py, through twin/csrc/pil's peek/poke).
 *
 * Protocol: the host writes st_in, then st_command; the program runs the command, writes st_out, and clears
 * st_command. Structures are packed as avr-gcc lays them out (no padding, lf_real = 32-bit float).
 */
#include <avr/io.h>
#include <string.h>

#include "../lf_wire.h"
#include "../line_follower.h"

enum {
  ST_IDLE = 0,
  ST_READ_CALIBRATED = 1, /* Eq. 8 */
  ST_READ_LINE = 2,       /* readLine, Eq. 9's weighted average */
  ST_LINE_ANGLE = 3,      /* Eq. 9 */
  ST_CONTROL = 4,         /* Eqs. 10-11 */
  ST_WHEEL_DUTIES = 5,
  ST_CALIBRATION_TICKS = 6,
  ST_WIRE_SAMPLE = 7
};

typedef struct {
  lf_params params;
  lf_state state;
  uint16_t raw[LF_MAX_SENSORS];
  int32_t position;
  lf_real a, b; /* e; or v and omega */
  uint32_t t_ms;
  int32_t seen, wl, wr;
} st_input;

typedef struct {
  lf_state state;
  uint16_t values[LF_MAX_SENSORS];
  int32_t position;
  lf_real a, b;
  uint32_t ticks;
  int16_t length;
  char text[LF_WIRE_MAX];
} st_output;

volatile uint8_t st_command;
st_input st_in;
st_output st_out;

int main(void) {
  for (;;) {
    uint8_t command = st_command;
    if (command == ST_IDLE) continue;
    st_out.state = st_in.state;
    switch (command) {
      case ST_READ_CALIBRATED:
        lf_read_calibrated(&st_in.state, st_in.raw, st_out.values, st_in.params.count);
        break;
      case ST_READ_LINE:
        st_out.position = lf_read_line(&st_out.state, st_in.raw, st_in.params.count);
        break;
      case ST_LINE_ANGLE:
        st_out.a = lf_line_angle(st_in.position, st_in.params.count, st_in.params.pitch_m,
                                 st_in.params.sensor_distance_m);
        break;
      case ST_CONTROL:
        lf_control(&st_out.state, &st_in.params, st_in.a);
        break;
      case ST_WHEEL_DUTIES:
        lf_wheel_duties(&st_in.params, st_in.a, st_in.b, &st_out.a, &st_out.b);
        break;
      case ST_CALIBRATION_TICKS:
        st_out.ticks = lf_calibration_ticks(&st_in.params);
        break;
      case ST_WIRE_SAMPLE:
        memset(st_out.text, 0, sizeof st_out.text);
        st_out.length = (int16_t)lf_wire_sample(st_out.text, st_in.t_ms, st_in.position, st_in.seen, st_in.wl, st_in.wr);
        break;
      default:
        st_out.length = -1;
    }
    st_command = ST_IDLE;
  }
}
