"""The robot's firmware as an AVR program: built with avr-gcc, checked, and configured through its EEPROM image.

The program (``twin/csrc/firmware/avr``) is the portable firmware the twin's C callback runs (``line_follower.c``,
``lf_wire.c``) with the drivers of the Pololu 3pi (ATmega328P at 20 MHz; pin map in ``board_3pi.h``). One ELF
serves every robot: its parameters live in EEPROM (``config.h``), written by :func:`config_image` here, by the
processor-in-the-loop glue in the twin, and with ``avrdude -U eeprom:w:…`` on the robot.
"""

from __future__ import annotations

import functools
import hashlib
import os
import shutil
import struct
import subprocess

from lf_common.cache import cache_dir, cached_folder
from lf_common.crc import with_crc
from twin.model.control import ControlParams
from twin.errors import TwinError
from twin.pil.program import FLASH_BYTES, MCU, RAM_BYTES, TRACE_SYMBOLS, Program, load_program  # noqa: F401 (fw.*)

F_CPU_HZ = 20_000_000
BOARD = "pololu-3pi-atmega328p"
BOARD_MAX_SENSORS = 8  # board_3pi_pins.h: PC0..PC4, then the LCD's control lines
TIMER1_HZ = F_CPU_HZ / 8  # the tick and the sensor reads count at 0.4 µs
QTR_TIMEOUT_MAX_US = 26000  # LF_QTR_TIMEOUT_MAX_US: Timer1's 16-bit count
SOURCE_DIR = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "csrc", "firmware")
PROGRAMS = {
    "robot": ("avr/main.c", "avr/qtr_rc.c", "avr/motors.c", "avr/uart.c", "avr/config.c", "line_follower.c", "lf_wire.c"),
    "selftest": ("avr/selftest.c", "line_follower.c", "lf_wire.c"),
}
CFLAGS = ("-Os", "-std=gnu99", "-Wall", "-Wextra", "-Werror", "-ffunction-sections", "-fdata-sections",
          "-Wl,--gc-sections")
INSTALL_AVR_GCC = "apt-get install gcc-avr avr-libc binutils-avr"

CONFIG_MAGIC = 0x3143464C  # "LFC1"
_PARAM_FIELDS = ("pitch_m", "sensor_distance_m", "v_max", "k_b", "k_p", "k_i", "k_d", "dt_s", "wheel_radius_m",
                 "half_track_m", "wheel_speed_max", "accel_max", "integral_limit", "cal_duty", "cal_sweep_rad")
# config.h's lf_config on the MCU, field by field (struct codes: little-endian, no padding, lf_real a 32-bit float),
# named as the glue's layout table names them (twin.pil.layout checks the two agree); the CRC-16 of these bytes follows
_CONFIG_BODY = (("magic", "I"), ("size", "H"), ("params.count", "i"),
                *((f"params.{f}", "f") for f in _PARAM_FIELDS), ("params.cal_sweeps", "i"),
                ("timeout_us", "H"), ("telemetry_every", "H"))
CONFIG_FIELDS = _CONFIG_BODY + (("crc", "H"),)
_BODY = struct.Struct("<" + "".join(code for _, code in _CONFIG_BODY))
CONFIG_BYTES = _BODY.size + 2


def check_config(params: ControlParams, timeout_us: float) -> None:
    """What the 3pi build can run: raise TwinError naming the parameter otherwise."""
    if params.count > BOARD_MAX_SENSORS:
        raise TwinError(f"sensor.count: the {BOARD} firmware reads at most {BOARD_MAX_SENSORS} sensors "
                        f"(PC0..PC4 and the LCD's three control lines), got {params.count}")
    if not 1 <= round(timeout_us) <= QTR_TIMEOUT_MAX_US:
        raise TwinError(f"sensor.timeout: the firmware times the sensors with a 16-bit timer at 0.4 µs, so at most "
                        f"{QTR_TIMEOUT_MAX_US} µs, got {timeout_us:g}")
    counts = params.dt_s * TIMER1_HZ
    if not 1 <= round(counts) <= 65535 or abs(counts - round(counts)) > 1e-6 * counts:
        raise TwinError(f"control.dt: the firmware's tick is a whole number of 0.4 µs Timer1 counts up to "
                        f"{65535 / TIMER1_HZ * 1000:.1f} ms, got {params.dt_s * 1000:g} ms")


def config_image(params: ControlParams, timeout_us: float, telemetry_every: int) -> bytes:
    """The EEPROM image ``config.h`` describes, for these parameters (checked with :func:`check_config`)."""
    check_config(params, timeout_us)
    if not 1 <= telemetry_every <= 65535:
        raise TwinError(f"telemetry every: 1..65535 ticks, got {telemetry_every}")
    body = _BODY.pack(CONFIG_MAGIC, CONFIG_BYTES, params.count, *(getattr(params, f) for f in _PARAM_FIELDS),
                      params.cal_sweeps, round(timeout_us), telemetry_every)
    return with_crc(body)


def config_layout() -> dict[str, tuple[int, int]]:
    """{field: (offset, size) [bytes]} of the image :func:`config_image` packs."""
    out, at = {}, 0
    for name, code in CONFIG_FIELDS:
        out[name] = (at, struct.calcsize("<" + code))
        at += out[name][1]
    return out


def intel_hex(data: bytes) -> str:
    """``data`` at address 0 as Intel HEX (what avrdude's ``-U eeprom:w:FILE`` reads)."""
    lines = []
    for at in range(0, len(data), 16):
        chunk = data[at: at + 16]
        record = bytes([len(chunk), at >> 8, at & 0xFF, 0]) + chunk
        lines.append(":" + (record + bytes([-sum(record) & 0xFF])).hex().upper())
    return "\n".join(lines + [":00000001FF"]) + "\n"


def _avr_gcc() -> str:
    gcc = shutil.which("avr-gcc")
    if not gcc:
        raise TwinError(f"avr-gcc is not installed; the firmware is built with it ({INSTALL_AVR_GCC})")
    return gcc


@functools.lru_cache(maxsize=4)
def _compiler_version(gcc: str) -> str:
    return subprocess.run([gcc, "--version"], capture_output=True, text=True, timeout=30).stdout


def _source_digest(gcc: str) -> str:
    h = hashlib.sha256()
    for root, _, files in sorted(os.walk(SOURCE_DIR)):
        for name in sorted(files):
            if name.endswith((".c", ".h")):
                path = os.path.join(root, name)
                h.update(os.path.relpath(path, SOURCE_DIR).encode() + b"\0")
                with open(path, "rb") as f:
                    h.update(f.read())
    h.update(_compiler_version(gcc).encode())
    h.update(" ".join(CFLAGS).encode())
    return h.hexdigest()[:16]


def build(program: str = "robot") -> str:
    """The ELF of ``program`` (``robot`` or ``selftest``) for the ATmega328P, built once per source version."""
    gcc = _avr_gcc()
    sources = [os.path.join(SOURCE_DIR, s) for s in PROGRAMS[program]]

    def compile_into(folder: str) -> None:
        out = os.path.join(folder, f"{program}.elf")
        done = subprocess.run([gcc, f"-mmcu={MCU}", f"-DF_CPU={F_CPU_HZ}UL", *CFLAGS, "-o", out, *sources, "-lm"],
                              capture_output=True, text=True, timeout=300)
        if done.returncode:
            lines = done.stderr.strip().splitlines() or ["no message"]
            first = next((line for line in lines if "error" in line), lines[0])
            raise TwinError(f"avr-gcc could not build the {program} firmware: {first}")

    folder = cached_folder(os.path.join(cache_dir(), "firmware", f"{program}-{_source_digest(gcc)}"), compile_into,
                           f"the {program} firmware")
    return os.path.join(folder, f"{program}.elf")


ElfInfo = Program  # the twin's firmware as a program (twin.pil.program)


def check_elf(path: str, need: tuple[str, ...] = ()) -> Program:
    """A program built for the ATmega328P (:func:`twin.pil.program.load_program`: ELF or Intel HEX) with the globals
    ``need``, or a one-line TwinError saying why not."""
    program = load_program(path)
    if need and not program.symbols:
        raise TwinError(f"{path}: has no symbol table ({'a HEX file' if program.kind == 'hex' else 'stripped?'}); the "
                        "twin reads its firmware's globals by name")
    missing = [n for n in need if n not in program.symbols]
    if missing:
        raise TwinError(f"{path}: has no {', '.join(missing)}; the twin traces each tick from these globals of "
                        "twin/csrc/firmware/avr/main.c, so build the firmware from that source")
    return program
