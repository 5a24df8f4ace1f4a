"""What the robot showed: the LCD's screens as text, the buzzer's notes, the LEDs, the unmodelled peripherals a
program touched, gathered chunk by chunk from the MCU (:class:`BoardLog`) with times in seconds since power-up.

The LCD's character codes are the HD44780's ROM A00 (Hitachi HD44780U datasheet, Table 4), as on the 3pi's display:
ASCII for 0x20–0x7D (0x5C is ¥), arrows, a few Greek and other signs (Pololu's examples print 0xF7, π, and 0xFF, a full
block). Custom characters (codes 0–15) are shown as Unicode lower blocks when their rows form a bar filled from the
bottom (Pololu's bar graphs), else as ▒.
"""

from __future__ import annotations

import dataclasses
import re

from twin.pil.layout import LcdFrame, LedEvent, Note

ROM_A00 = {0x5C: "¥", 0x7E: "→", 0x7F: "←", 0xA5: "・", 0xDF: "°", 0xE0: "α", 0xE1: "ä", 0xE2: "β", 0xE3: "ε",
           0xE4: "μ", 0xE5: "σ", 0xE6: "ρ", 0xE8: "√", 0xEB: "ˣ", 0xEC: "¢", 0xEE: "ñ", 0xEF: "ö", 0xF2: "θ",
           0xF3: "∞", 0xF4: "Ω", 0xF5: "ü", 0xF6: "Σ", 0xF7: "π", 0xFD: "÷", 0xFF: "█"}
BARS = " ▁▂▃▄▅▆▇█"
WIDTH = 8

# bits of lf_board_status.used (LF_USED_* in twin/csrc/pil/avr_glue.h): what the program used that nothing answers
UNMODELLED = (
    (1 << 0, "SPI: its lines are the motor and button lines of the 3pi; nothing answers on them"),
    (1 << 1, "I2C (TWI): not wired out on the 3pi; nothing answers"),
    (1 << 2, "ADC0-5: those pins carry the reflectance sensors and the emitter control; their voltages are not modelled"),
    (1 << 3, "UART receive: nothing is connected to RX (PD0); no byte arrives"),
    (1 << 4, "analog comparator interrupt: the comparator's inputs are not modelled"),
    (1 << 5, "Timer1 input capture on ICP1 (PB0, the LCD's R/W line): not modelled, TIMER1_CAPT comes only at TOP in "
             "the modes with TOP = ICR1"),
    (1 << 6, "INT0/INT1 (PD2, PD3): low-level triggering is not repeated while the line stays low"),
    (1 << 7, "buzzer toggled by hand on PB2 (not by Timer1): its sound is not captured"),
)


def char(code: int, cgram: bytes) -> str:
    """One character cell as text."""
    if code < 16:
        rows = [cgram[(code & 7) * 8 + r] & 0x1F for r in range(8)]
        filled = sum(1 for r in rows if r == 0x1F)
        if all(r == (0x1F if i >= 8 - filled else 0) for i, r in enumerate(rows)):
            return BARS[filled]
        return "▒"
    if code in ROM_A00:
        return ROM_A00[code]
    return chr(code) if 0x20 <= code < 0x7E else "?"


def screen_text(frame: LcdFrame) -> str:
    """The two lines of a screen, 8 characters each, joined by a newline; blank when the display is off."""
    if not frame.on:
        return " " * WIDTH + "\n" + " " * WIDTH
    codes, cgram = bytes(frame.text), bytes(frame.cgram)
    return "\n".join("".join(char(c, cgram) for c in codes[k * WIDTH: (k + 1) * WIDTH]) for k in (0, 1))


def plain(text: str) -> str:
    """A screen's text for matching and one-line output: each line stripped, lines joined by one space."""
    return re.sub(r"\s+", " ", text).strip()


@dataclasses.dataclass(frozen=True)
class Shown:
    """A screen the LCD showed from ``t`` [s since power-up]."""

    t: float
    text: str


@dataclasses.dataclass(frozen=True)
class Heard:
    """A note of the buzzer: from ``start`` to ``end`` [s since power-up], ``hz``, PWM ``duty`` 0..1."""

    start: float
    end: float
    hz: float
    duty: float


@dataclasses.dataclass(frozen=True)
class Lit:
    """The user LEDs from ``t`` on."""

    t: float
    red: bool
    green: bool


class BoardLog:
    """Everything the board showed, in order, drained from the MCU after each chunk (:meth:`take`)."""

    def __init__(self, f_cpu_hz: int):
        self.f_cpu_hz = f_cpu_hz
        self.screens: list[Shown] = []
        self.notes: list[Heard] = []
        self.leds: list[Lit] = []
        self.used = 0

    def seconds(self, cycle: int) -> float:
        return cycle / self.f_cpu_hz

    def take(self, frames: list[LcdFrame], notes: list[Note], leds: list[LedEvent], used: int) -> None:
        self.screens += [Shown(self.seconds(f.cycle), screen_text(f)) for f in frames]
        self.notes += [Heard(self.seconds(n.start), self.seconds(n.end), n.hz, n.duty) for n in notes]
        self.leds += [Lit(self.seconds(e.cycle), bool(e.red), bool(e.green)) for e in leds]
        self.used |= used

    def close(self, sounding: Note | None, now_s: float) -> None:
        """The run is over: a note still sounding ends now."""
        if sounding is not None and sounding.start:
            self.notes.append(Heard(self.seconds(sounding.start), now_s, sounding.hz, sounding.duty))

    @property
    def screen(self) -> str:
        """What the LCD shows now (blank before the program's first screen)."""
        return self.screens[-1].text if self.screens else " " * WIDTH + "\n" + " " * WIDTH

    def unmodelled(self) -> list[str]:
        """One line per unmodelled peripheral the program used."""
        return [text for bit, text in UNMODELLED if self.used & bit]
