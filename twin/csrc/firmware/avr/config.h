/* What this robot's firmware is told, from EEPROM: the control parameters (lf_params), the sensor read timeout and
 * the telemetry rate. The twin writes the image (twin.pil.firmware.config_image); on the robot it is flashed with
 * the program (avrdude -U eeprom:w:config.hex). An image with the wrong mark, size or checksum, or with a sensor
 * count or timeout this board cannot run (config.c), is not used: the robot then stays still with its motors
 * braked, rather than run on guesses.
 *
 * Layout, little-endian, no padding (avr-gcc aligns to 1 byte; lf_real is a 32-bit float on the MCU):
 *   0 magic "LFC1" | 4 size of the whole image (uint16) | 6 lf_params (68 B) | 74 timeout_us (uint16)
 *   76 telemetry_every (uint16) | 78 CRC-16/XMODEM of bytes 0..77 (uint16)
 * Python's image (twin.pil.firmware.CONFIG_FIELDS) is checked field by field against the glue's copy of this struct
 * when the glue loads (twin/csrc/pil/avr_layout.c), and against this header by avr-gcc (tests/test_pil_layout.py).
 */
#ifndef LF_CONFIG_H
#define LF_CONFIG_H

#include <stdint.h>

#include "../line_follower.h"

#define LF_CONFIG_MAGIC 0x3143464CUL /* "LFC1" */

typedef struct {
  uint32_t magic;
  uint16_t size;
  lf_params params;
  uint16_t timeout_us;
  uint16_t telemetry_every;
  uint16_t crc;
} lf_config;

/* 1 if EEPROM holds a valid image (copied to *out), 0 if not. */
uint8_t config_load(lf_config *out);

#endif
