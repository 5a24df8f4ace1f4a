"""An emulated ATmega328P running a program on the 3pi's board (simavr, through the C glue ``twin.pil._lfavr``).

:class:`Mcu` loads a program's flash image (:class:`twin.pil.program.Program`, from an ELF or a HEX file) and gives
its RAM (by symbol where the program has them), its EEPROM, the board's buttons and what the board shows (LCD
screens, buzzer notes, LEDs), and, attached to a simulation, the lockstep with MuJoCo (``twin/csrc/pil``;
``avr_glue.h`` lists its files). Without simavr the glue is not built, and opening an MCU says what to install. The
glue's structs are checked when it loads (:mod:`twin.pil.layout`).
"""

from __future__ import annotations

import ctypes
import glob
import os
from ctypes import c_char_p, c_double, c_int32, c_int64, c_uint16, c_uint32, c_uint64, c_void_p

import mujoco

from twin.core import native as core
from twin.core.outcomes import Status
from twin.pil.firmware import F_CPU_HZ
from twin.pil.layout import LIBRARY, AvrFwState, BoardStatus, LcdFrame, LedEvent, McuStatus, Note, check_glue
from twin.pil.program import MCU, TRACE_SYMBOLS, Program
from twin.errors import TwinError

INSTALL_SIMAVR = ("processor in the loop needs simavr: apt-get install simavr libsimavr-dev, then pip install -e . "
                  "again to build twin.pil._lfavr")


_lib: ctypes.CDLL | None = None


def glue() -> ctypes.CDLL:
    """The glue library, loaded and checked once; TwinError with the install hint if it is missing."""
    global _lib
    if _lib is not None:
        return _lib
    here = os.path.dirname(os.path.abspath(__file__))
    found = sorted(glob.glob(os.path.join(here, "_lfavr*.so")))
    if not found:
        raise TwinError(INSTALL_SIMAVR)
    try:
        lib = ctypes.CDLL(found[0])
    except OSError as e:  # built, but libsimavr has gone since
        raise TwinError(f"{INSTALL_SIMAVR} ({e})") from None
    try:
        core.check_library(lib)
        check_glue(lib)
    except (ImportError, AttributeError) as e:  # built from older sources
        raise TwinError(f"{LIBRARY} is out of date ({e}); rebuild it with pip install -e .") from None
    lib.lf_set_ray.argtypes = [c_void_p]
    lib.lf_set_ray(core.mujoco_function("mj_ray"))
    p = ctypes.POINTER
    lib.lf_avr_open.argtypes = [c_char_p, c_uint32, c_char_p, c_uint32, c_char_p, c_uint32, c_char_p, c_int32]
    lib.lf_avr_open.restype = c_void_p
    lib.lf_avr_close.argtypes = [c_void_p]
    lib.lf_avr_trace_globals.argtypes = [c_void_p, c_uint16, c_uint16, c_uint16, c_uint16]
    lib.lf_avr_board.argtypes = [c_void_p, c_int32, c_double, c_double, c_int64]
    lib.lf_avr_eeprom.argtypes = [c_void_p, c_char_p, c_uint32]
    lib.lf_avr_eeprom.restype = c_int32
    lib.lf_avr_peek.argtypes = [c_void_p, c_uint32, c_char_p, c_uint32]
    lib.lf_avr_poke.argtypes = [c_void_p, c_uint32, c_char_p, c_uint32]
    lib.lf_avr_peek.restype = lib.lf_avr_poke.restype = c_int32
    lib.lf_avr_run_until_clear.argtypes = [c_void_p, c_uint32, c_uint64]
    lib.lf_avr_run_until_clear.restype = c_int32
    lib.lf_avr_run_cycles.argtypes = [c_void_p, c_uint64]
    lib.lf_avr_run_cycles.restype = c_int32
    lib.lf_avr_attach.argtypes = [c_void_p, c_void_p, c_void_p, c_void_p, c_double]
    lib.lf_avr_zero_time.argtypes = lib.lf_avr_reset_stats.argtypes = [c_void_p]
    lib.lf_avr_zero_time_at_tick.argtypes = [c_void_p, c_double, c_int32]
    lib.lf_avr_buttons.argtypes = [c_void_p, c_int32]
    lib.lf_avr_state.argtypes = [c_void_p, p(core.FwState)]
    lib.lf_avr_state.restype = c_int32
    lib.lf_avr_lockstep.argtypes = [c_void_p, c_void_p, c_void_p, c_int64]
    lib.lf_avr_lockstep.restype = c_int32
    lib.lf_avr_message.argtypes = [c_void_p]
    lib.lf_avr_message.restype = c_char_p
    lib.lf_avr_uart.argtypes = [c_void_p, c_char_p, c_int32]
    lib.lf_avr_uart.restype = c_int32
    lib.lf_avr_status_of.argtypes = [c_void_p, p(McuStatus)]
    lib.lf_avr_board_status.argtypes = [c_void_p, p(BoardStatus)]
    lib.lf_avr_lcd_flush.argtypes = [c_void_p]
    for name, kind in (("lf_avr_lcd_frames", LcdFrame), ("lf_avr_notes", Note), ("lf_avr_leds", LedEvent)):
        getattr(lib, name).argtypes = [c_void_p, p(kind), c_int32]
        getattr(lib, name).restype = c_int32
    _lib = lib
    return lib


class Mcu:
    """One emulated MCU running ``program`` (:func:`twin.pil.program.load_program`). The twin's own firmware (a program
    with the traced globals) is traced from its RAM at every tick; any other program runs on the board alone."""

    def __init__(self, program: Program, mcu: str = MCU, f_cpu_hz: int = F_CPU_HZ):
        self.lib, self.program, self.f_cpu_hz = glue(), program, f_cpu_hz
        err = ctypes.create_string_buffer(256)
        self.handle = self.lib.lf_avr_open(program.flash, len(program.flash), program.eeprom or None,
                                           len(program.eeprom), mcu.encode(), f_cpu_hz, err, len(err))
        if not self.handle:
            raise TwinError(f"{program.path}: {err.value.decode(errors='replace')}")
        if program.traced:
            self.lib.lf_avr_trace_globals(self.handle, *(program.symbols[n] for n in TRACE_SYMBOLS))
        self._attached: tuple = ()

    @property
    def elf(self) -> Program:  # the name the twin firmware's callers know it by
        return self.program

    def close(self) -> None:
        if self.handle:
            self.lib.lf_avr_close(self.handle)
            self.handle = None

    def __enter__(self) -> "Mcu":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def address(self, name: str) -> int:
        if name not in self.program.symbols:
            raise TwinError(f"{self.program.path}: has no global named {name}")
        return self.program.symbols[name]

    def peek(self, name_or_address: str | int, n: int) -> bytes:
        at = self.address(name_or_address) if isinstance(name_or_address, str) else name_or_address
        buf = ctypes.create_string_buffer(n)
        if self.lib.lf_avr_peek(self.handle, at, buf, n):
            raise TwinError(f"peek {n} bytes at 0x{at:x}: outside the MCU's RAM")
        return buf.raw

    def poke(self, name_or_address: str | int, data: bytes) -> None:
        at = self.address(name_or_address) if isinstance(name_or_address, str) else name_or_address
        if self.lib.lf_avr_poke(self.handle, at, data, len(data)):
            raise TwinError(f"poke {len(data)} bytes at 0x{at:x}: outside the MCU's RAM")

    def eeprom(self, image: bytes) -> None:
        if self.lib.lf_avr_eeprom(self.handle, image, len(image)):
            raise TwinError(f"the MCU's EEPROM cannot take {len(image)} bytes")

    def run_until_clear(self, name: str, max_cycles: int) -> int:
        """Run until the byte ``name`` is 0: 0 done, 1 out of cycles, 2 the MCU stopped."""
        return self.lib.lf_avr_run_until_clear(self.handle, self.address(name), max_cycles)

    def run_cycles(self, cycles: int) -> int:
        """Run free (nothing attached) for ``cycles``: 0, or 2 if the MCU stopped."""
        return self.lib.lf_avr_run_cycles(self.handle, cycles)

    # --- in the loop
    def attach(self, model: mujoco.MjModel, data: mujoco.MjData, sim: core.Sim, stall_s: float) -> None:
        """Sensor reads from now on come from this simulation; the watchdog allows ``stall_s`` simulated seconds."""
        self._attached = (model, data, sim)  # kept alive while the C holds their addresses
        self.lib.lf_avr_attach(self.handle, model._address, data._address, ctypes.addressof(sim), stall_s)

    def lockstep(self, nstep: int) -> tuple[Status, str]:
        """Step the attached simulation ``nstep`` times with the MCU: OK, or why it stopped (stalled, refused)."""
        code = self.lib.lf_avr_lockstep(self.handle, core.mujoco_function("mj_step1"), core.mujoco_function("mj_step2"),
                                        nstep)
        return Status(code), (self.lib.lf_avr_message(self.handle) or b"").decode(errors="replace")

    def zero_time(self) -> None:
        self.lib.lf_avr_zero_time(self.handle)

    def zero_time_at_tick(self, period_s: float, pressed: int = 0) -> None:
        """MuJoCo's time 0 at the twin firmware's next control tick (every ``period_s``), not now; the buttons in
        ``pressed`` (A 1, B 2, C 4) held from time 0 on, so no tick under way now sees them."""
        self.lib.lf_avr_zero_time_at_tick(self.handle, period_s, int(pressed))

    def reset_stats(self) -> None:
        self.lib.lf_avr_reset_stats(self.handle)

    def buttons(self, pressed: int) -> None:
        """Hold the buttons in ``pressed`` (A 1, B 2, C 4) and let the others go."""
        self.lib.lf_avr_buttons(self.handle, int(pressed))

    def board(self, lcd_plugged: bool, battery_v: float, trimmer_v: float, trace_every: int) -> None:
        """The board's set-up: the LCD plugged in (else its lines are sensor lines), the battery voltage on ADC6
        (through its 2/3 divider) and the trimmer's on ADC7 [V], a physics trace record every ``trace_every`` steps
        for a program that is not traced from its RAM (0: none)."""
        self.lib.lf_avr_board(self.handle, int(lcd_plugged), battery_v, trimmer_v, trace_every)

    def board_status(self) -> BoardStatus:
        out = BoardStatus()
        self.lib.lf_avr_board_status(self.handle, ctypes.byref(out))
        return out

    def _drain(self, name: str, kind: type, cap: int = 512) -> list:
        out = []
        while True:
            buf = (kind * cap)()
            n = getattr(self.lib, name)(self.handle, buf, cap)
            out += [buf[i] for i in range(n)]
            if n < cap:
                return out

    def lcd_frames(self, flush: bool = False) -> list[LcdFrame]:
        """The LCD's screens kept since the last call (each taken when the program had been quiet, or as a pass of a
        screen rewritten without pause began); ``flush``: the screen as it is now too, if written since (a run's end)."""
        if flush:
            self.lib.lf_avr_lcd_flush(self.handle)
        return self._drain("lf_avr_lcd_frames", LcdFrame)

    def notes(self) -> list[Note]:
        """The buzzer's notes that ended since the last call."""
        return self._drain("lf_avr_notes", Note)

    def leds(self) -> list[LedEvent]:
        """The LEDs' changes since the last call."""
        return self._drain("lf_avr_leds", LedEvent)

    def state(self) -> core.FwState:
        out = core.FwState()
        if self.lib.lf_avr_state(self.handle, ctypes.byref(out)):
            raise TwinError(f"{self.program.path}: has no fw_state")
        return out

    def uart(self) -> bytes:
        buf = ctypes.create_string_buffer(65536)
        n = self.lib.lf_avr_uart(self.handle, buf, len(buf))  # before buf.raw is read
        return buf.raw[:n]

    def status(self) -> McuStatus:
        out = McuStatus()
        self.lib.lf_avr_status_of(self.handle, ctypes.byref(out))
        return out


def state_size() -> int:
    """Bytes of the firmware's lf_state on the MCU as the glue reads it (checked against the ELF's symbol size)."""
    glue()  # its avr.lf_state is AvrFwState's size, or it does not load
    return ctypes.sizeof(AvrFwState)

