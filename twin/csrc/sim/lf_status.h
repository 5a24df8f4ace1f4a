/* What the C tells Python about a simulation: one enumeration for the control callback (lf_sim.error) and the
 * processor-in-the-loop glue (lf_avr_lockstep's result). Python mirrors it (twin.core.outcomes.Status) and compares
 * it with the library's name table (lf_status_names) when the library loads. */
#ifndef LF_STATUS_H
#define LF_STATUS_H

#include <stdint.h>

enum lf_status {
  LF_OK = 0,           /* the simulation runs */
  /* the head does not fit the model it is stepped with (lf_check): the callback refuses the simulation */
  LF_ERR_LAYOUT = 1,   /* layout_version is not this library's */
  LF_ERR_MODEL = 2,    /* the mjModel's sizes are not those the head was written for */
  LF_ERR_CAPACITY = 3, /* record_capacity < 1, or the trace ring does not fit in nuserdata */
  LF_ERR_SENSORS = 4,  /* nsensor or firmware.count outside 1..LF_MAX_SENSORS, or not equal */
  LF_ERR_ID = 5,       /* a site, body, texture, actuator or dof id outside the model */
  LF_ERR_CENTRE = 6,   /* the centre line does not lie inside numeric_data */
  LF_ERR_STATE = 7,    /* records_written < 0 */
  /* the processor in the loop refuses to run, or ends the lap */
  LF_ERR_RAY = 8,      /* mj_ray has not been handed over (lf_set_ray) */
  LF_ERR_FIRMWARE = 9, /* the program lacks a global the glue traces (fw_state, fw_raw_us, ...) */
  LF_STALLED = 10      /* the watchdog: the MCU stopped, or stopped ticking, releasing a line or writing its PWM */
};

/* How a lap the C judges (the FMU's lap_judge.c) ended, or that it has not: twin.core.outcomes.Outcome's values in
 * LAP_STATUS order, listed in lf_status_names too so that Python checks them when the library loads. */
enum lf_lap_status {
  LF_LAP_RUNNING = 0,
  LF_LAP_COMPLETED = 1,
  LF_LAP_OFF_TRACK = 2,
  LF_LAP_LINE_LOST = 3,
  LF_LAP_TIMEOUT = 4,
  LF_LAP_DIVERGED = 5,
  LF_LAP_CALIBRATION = 6,
  LF_LAP_REFUSED = 7,
  LF_LAP_WRONG_WAY = 8
};

/* One code's name, for Python's load-time check. */
typedef struct {
  const char *name;
  int32_t value;
} lf_status_name;

/* Every enum lf_status and enum lf_lap_status code with its name; returns their number. */
int32_t lf_status_names(const lf_status_name **names);

#endif
