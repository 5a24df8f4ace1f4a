"""What a run of any program on the board reports beside its lap (:class:`BoardReport`): the program, the MCU's load,
the operator's presses, and what the robot showed (LCD text over time, buzzer notes, LEDs, UART lines)."""

from __future__ import annotations

import dataclasses

from twin.pil.board.display import BoardLog
from twin.pil.board.operator import Press


@dataclasses.dataclass(frozen=True)
class BoardReport:
    """A program's run on the board. Times in seconds since power-up; ``lap_start_s`` is when the lap clock started
    (the first physics step the motors drove after the operator's last press; None if they never did).
    ``awake_share``: the MCU's load, cycles awake (not in SLEEP) over all cycles; a program that busy-waits is
    always awake."""

    mcu: str
    board: str
    f_cpu_hz: int
    program: str
    format: str
    flash_bytes: int
    flash_total_bytes: int
    ram_bytes: int | None
    ram_total_bytes: int
    cycles: int
    awake_share: float
    lap_start_s: float | None
    restarts: int
    presses: tuple[Press, ...]
    lcd: tuple[tuple[float, str], ...]
    notes: tuple[tuple[float, float, float, float], ...]  # start, end [s], frequency [Hz], duty
    leds: tuple[tuple[float, bool, bool], ...]  # t [s], red, green: as shown per physics step, after each change
    led_lit_s: tuple[float, float]  # red, green: how long each LED's line was high over the run [s], to the cycle
    uart_lines: int
    unmodelled: tuple[str, ...]
    events_lost: int
    resets: int  # MCU resets after power-up: on the 3pi only its watchdog resets it (the program restarting itself)
    reset_span_s: tuple[float, float] | None  # the first and the last of them [s since power-up]

    @classmethod
    def of(cls, log: BoardLog, **fields) -> "BoardReport":
        return cls(lcd=tuple((s.t, s.text) for s in log.screens),
                   notes=tuple((n.start, n.end, n.hz, n.duty) for n in log.notes),
                   leds=tuple((e.t, e.red, e.green) for e in log.leds), unmodelled=tuple(log.unmodelled()), **fields)

    @property
    def lcd_final(self) -> str:
        return self.lcd[-1][1] if self.lcd else ""

    def led_summary(self, end_s: float) -> dict:
        """The LEDs as shown at the end, how often that changed, and the share of the run each LED's line was high:
        its brightness, also when a PWM dims it faster than a physics step shows."""
        final = self.leds[-1][1:] if self.leds else (False, False)
        span = max(end_s, 1e-9)
        return {"final": {"red": final[0], "green": final[1]}, "changes": len(self.leds),
                "lit_share": {"red": self.led_lit_s[0] / span, "green": self.led_lit_s[1] / span}}

    def summary(self) -> dict:
        end_s = self.cycles / self.f_cpu_hz
        return {
            "mcu": self.mcu, "board": self.board, "f_cpu_hz": self.f_cpu_hz, "program": self.program,
            "format": self.format, "flash_bytes": self.flash_bytes, "flash_total_bytes": self.flash_total_bytes,
            "ram_bytes": self.ram_bytes, "ram_total_bytes": self.ram_total_bytes, "simulated_s": end_s,
            "awake_share": self.awake_share, "lap_start_s": self.lap_start_s, "restarts": self.restarts,
            "presses": [dataclasses.asdict(p) for p in self.presses],
            "lcd": [{"t": t, "text": text} for t, text in self.lcd], "lcd_final": self.lcd_final,
            "notes": [{"start": a, "end": b, "hz": hz, "duty": duty} for a, b, hz, duty in self.notes],
            "leds": self.led_summary(end_s), "uart_lines": self.uart_lines, "unmodelled": list(self.unmodelled),
            "events_lost": self.events_lost,
            "resets": {"count": self.resets, "by": "watchdog", "first_s": self.reset_span_s[0],
                       "last_s": self.reset_span_s[1]} if self.resets else {"count": 0},
        }

    def resets_line(self) -> str | None:
        """What the resets say, or None without any."""
        if not self.resets:
            return None
        first, last = self.reset_span_s
        every = f", every {(last - first) / (self.resets - 1) * 1000:.3g} ms on average" if self.resets > 1 else ""
        return (f"MCU resets: {self.resets} by its watchdog (first {first:.3f} s, last {last:.3f} s after power-up"
                f"{every}): the program restarts itself")
