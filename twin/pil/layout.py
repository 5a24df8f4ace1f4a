"""The processor-in-the-loop glue's structs as Python mirrors them, checked field by field (name, offset and size in
bytes) against the glue's layout table (``lf_avr_layout``, twin/csrc/pil/avr_layout.c) when it loads:

* ``avr.lf_state``: the firmware's state as avr-gcc lays it out in the MCU's RAM, :class:`AvrFwState`;
* ``avr.lf_config``: the EEPROM image :func:`twin.pil.firmware.config_image` packs (``config.h``);
* ``lf_avr_status``: the MCU's figures, :class:`McuStatus`.

The glue's copies of the firmware's structs are in turn compiled against the firmware's headers with avr-gcc by
``tests/test_pil_layout.py``.
"""

from __future__ import annotations

import ctypes
from ctypes import c_double, c_int64, c_uint64

from twin.core import native as core
from twin.pil.firmware import CONFIG_BYTES, config_layout

LIBRARY = "twin.pil._lfavr"


class McuStatus(ctypes.Structure):
    """``lf_avr_status``: the MCU's figures so far (cycles at the MCU's clock, reading errors [µs])."""

    _fields_ = [("cycle", c_uint64), ("ticks", c_int64), ("busy_max", c_uint64), ("busy_sum", c_uint64),
                ("busy_ticks", c_int64), ("uart_lost", c_int64), ("read_error_max_us", c_double),
                ("read_error_sum_us", c_double), ("read_errors", c_int64)]


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
    return {**_fields("avr.lf_state", AvrFwState), **config, **_fields("lf_avr_status", McuStatus)}


def check_glue(lib: ctypes.CDLL) -> None:
    """Raise ImportError unless the glue's table equals :func:`mirrors`, field by field."""
    lib.lf_avr_layout.restype = ctypes.c_int32
    lib.lf_avr_layout.argtypes = [ctypes.POINTER(ctypes.POINTER(core.Field))]
    core.check_same(core.library_layout(lib, "lf_avr_layout"), mirrors(), "(offset, size)", LIBRARY)
