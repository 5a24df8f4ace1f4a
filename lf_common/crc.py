"""The check that guards what a robot keeps in EEPROM (the firmware's configuration, its stored gains):
CRC-16/XMODEM, as avr-libc's ``_crc_xmodem_update`` computes it, stored little-endian right after the bytes it covers."""

from __future__ import annotations

import binascii
import struct

CRC_BYTES = 2


def with_crc(body: bytes) -> bytes:
    """``body`` followed by its CRC."""
    return body + struct.pack("<H", binascii.crc_hqx(body, 0))


def crc_ok(image: bytes) -> bool:
    """Whether ``image`` (bytes then their CRC, as :func:`with_crc` writes them) passes its check."""
    body, crc = image[:-CRC_BYTES], image[-CRC_BYTES:]
    return len(image) > CRC_BYTES and struct.unpack("<H", crc)[0] == binascii.crc_hqx(body, 0)
