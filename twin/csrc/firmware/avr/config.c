#include "config.h"

#include <avr/eeprom.h>
#include <stddef.h>
#include <util/crc16.h>

#include "board_3pi.h"
#include "qtr_rc.h"

uint8_t config_load(lf_config *out) {
  const uint8_t *bytes = (const uint8_t *)out;
  uint16_t crc = 0;
  size_t i;
  eeprom_read_block(out, (const void *)0, sizeof *out);
  for (i = 0; i < offsetof(lf_config, crc); i++) crc = _crc_xmodem_update(crc, bytes[i]);
  if (out->magic != LF_CONFIG_MAGIC || out->size != sizeof *out || out->crc != crc) return 0;
  /* what this board and its timers can do; the twin refuses the rest before it writes the image */
  if (out->params.count < 1 || out->params.count > LF_BOARD_MAX_SENSORS) return 0;
  if (out->timeout_us < 1 || out->timeout_us > LF_QTR_TIMEOUT_MAX_US || out->telemetry_every < 1) return 0;
  return 1;
}
