/* Telemetry on the wire (see twin/telemetry/wire.py): NMEA-style lines "$LF...*CS\n", integers only, formatted without
 * printf so the MCU spends a few hundred cycles per line. Each function writes into buf (at least
 * LF_WIRE_MAX bytes), NUL-terminates it and returns the line's length. */
#ifndef LF_WIRE_H
#define LF_WIRE_H

#include <stdint.h>

#define LF_WIRE_MAX 96
#define LF_WIRE_VERSION 1

int lf_wire_header(char *buf, int32_t sensors, int32_t dt_us, int32_t every);
int lf_wire_sample(char *buf, uint32_t t_ms, int32_t pos, int32_t seen, int32_t wl_crad, int32_t wr_crad);
int lf_wire_start(char *buf, uint32_t t_ms);
int lf_wire_lap(char *buf, uint32_t t_ms, uint32_t lap_ms);

#endif
