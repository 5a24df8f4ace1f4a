"""The processor-in-the-loop glue's structs as Python mirrors them, checked field by field (name, offset and size in
bytes) against the glue's layout table (``lf_avr_layout``, twin/csrc/pil/avr_layout.c) when it loads:

* ``avr.lf_state``: the firmware's state as avr-gcc lays it out in the MCU's RAM, :class:`AvrFwState`;
* ``avr.lf_config``: the EEPROM image :func:`twin.pil.firmware.config_image` packs (``config.h``);
* ``lf_avr_status``: the MCU's figures, :class:`McuStatus`;
* ``lf_lcd_frame``, ``lf_note``, ``lf_led_event``, ``lf_board_status``: what the board shows (:class:`LcdFrame`,
  :class:`Note`, :class:`LedEvent`, :class:`BoardStatus`).

The glue's copies of the firmware's structs are in turn compiled against the firmware's headers with avr-gcc by
``tests/test_pil_layout.py``.
"""

from __future__ import annotations

import ctypes
from ctypes import c_double, c_int32, c_int64, c_uint8, c_uint32, c_uint64

from twin.core import native as core
from twin.model.timing import COMPUTE_PATHS
from twin.pil.firmware import CONFIG_BYTES, config_layout

LIBRARY = "twin.pil._lfavr"


class McuStatus(ctypes.Structure):
    """``lf_avr_status``: the MCU's figures so far (cycles at the MCU's clock, reading errors [µs])."""

    _fields_ = [("cycle", c_uint64), ("ticks", c_int64), ("busy_max", c_uint64), ("busy_sum", c_uint64),
                ("busy_ticks", c_int64), ("uart_lost", c_int64), ("read_error_max_us", c_double),
                ("read_error_sum_us", c_double), ("read_errors", c_int64), ("awake", c_uint64),
                ("release_cycles_sum", c_uint64), ("release_cycles_max", c_uint64), ("compute_cycles_sum", c_uint64),
                ("compute_cycles_max", c_uint64), ("compute_cycles_min", c_uint64), ("timed_ticks", c_int64),
                ("compute_path_cycles_sum", c_uint64 * len(COMPUTE_PATHS)),
                ("compute_path_ticks", c_int64 * len(COMPUTE_PATHS))]


class LcdFrame(ctypes.Structure):
    """``lf_lcd_frame``: one screen of the LCD at a quiet moment: character codes (line 0, then 1), custom characters."""

    _fields_ = [("cycle", c_uint64), ("text", c_uint8 * 16), ("cgram", c_uint8 * 64), ("on", c_int32), ("pad", c_int32)]


class Note(ctypes.Structure):
    """``lf_note``: a note of the buzzer: cycles (end 0: still sounding), frequency [Hz], PWM duty 0..1."""

    _fields_ = [("start", c_uint64), ("end", c_uint64), ("hz", c_double), ("duty", c_double)]


class LedEvent(ctypes.Structure):
    """``lf_led_event``: the user LEDs after a change."""

    _fields_ = [("cycle", c_uint64), ("red", c_int32), ("green", c_int32)]


class BoardStatus(ctypes.Structure):
    """``lf_board_status``: the buttons' polling, the motors' last drive, unmodelled peripherals used, what shows now."""

    _fields_ = [("last_poll", c_uint64), ("polls", c_int64), ("last_drive", c_uint64), ("used", c_uint32),
                ("buttons", c_int32), ("red", c_int32), ("green", c_int32), ("note", Note), ("frames_lost", c_int64),
                ("notes_lost", c_int64), ("leds_lost", c_int64), ("resets", c_int64), ("first_reset", c_uint64),
                ("last_reset", c_uint64), ("red_lit", c_uint64), ("green_lit", c_uint64)]


class AvrFwState(ctypes.Structure):
    """The firmware's ``lf_state`` on the MCU: the host's :class:`twin.core.native.FwState` with no padding and each
    double (``lf_real``) a 32-bit float, as avr-gcc lays it out."""

    _pack_ = 1
    _fields_ = [(name, ctypes.c_float if kind is c_double else kind) for name, kind in core.FwState._fields_]


def _fields(prefix: str, cls: type[ctypes.Structure]) -> dict[str, tuple[int, int]]:
    out = {prefix: (0, ctypes.sizeof(cls))}
    out.update({f"{prefix}.{f[0]}": (getattr(cls, f[0]).offset, getattr(cls, f[0]).size) for f in cls._fields_})
    return out


def mirrors() -> dict[str, tuple[int, int]]:
    """{"struct" or "struct.field": (offset, size) [bytes]} as Python lays out what ``lf_avr_layout`` lists."""
    config = {"avr.lf_config": (0, CONFIG_BYTES)}
    config.update({f"avr.lf_config.{name}": at for name, at in config_layout().items()})
    return {**_fields("avr.lf_state", AvrFwState), **config, **_fields("lf_avr_status", McuStatus),
            **_fields("lf_lcd_frame", LcdFrame), **_fields("lf_note", Note), **_fields("lf_led_event", LedEvent),
            **_fields("lf_board_status", BoardStatus)}


def check_glue(lib: ctypes.CDLL) -> None:
    """Raise ImportError unless the glue's table equals :func:`mirrors`, field by field."""
    lib.lf_avr_layout.restype = ctypes.c_int32
    lib.lf_avr_layout.argtypes = [ctypes.POINTER(ctypes.POINTER(core.Field))]
    core.check_same(core.library_layout(lib, "lf_avr_layout"), mirrors(), "(offset, size)", LIBRARY)
