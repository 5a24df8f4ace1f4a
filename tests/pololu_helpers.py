"""Running Pololu's 3pi example programs (``../shared/pololu-examples``) on the twin's 3pi board, and reading what
the robot showed, for tests/test_pololu_examples.py (whose docstring says where each expectation comes from)."""

from __future__ import annotations

import functools
import os

import pytest

from twin.core.lap import LapLimits
from twin.errors import TwinError

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
EXAMPLES = os.path.normpath(os.path.join(ROOT, "..", "shared", "pololu-examples"))
F_CPU = 20e6


def _missing(why: str):
    if os.environ.get("CI"):
        pytest.fail(f"CI has {why}")
    pytest.skip(why)


@pytest.fixture(scope="module")
def examples() -> str:
    """The folder of Pololu's HEX files, with simavr's glue built; a skip (a failure under CI) naming what is missing."""
    try:
        from twin.pil.mcu import glue

        glue()
    except TwinError as e:
        _missing(f"simavr's glue (gcc-avr, simavr, libsimavr-dev before pip install -e .): {e}")
    if not os.path.isdir(EXAMPLES):
        _missing(f"Pololu's example programs in {EXAMPLES} (the shared/ folder beside the repository)")
    return EXAMPLES


def hex_path(name: str) -> str:
    path = os.path.join(EXAMPLES, f"{name}.hex")
    if not os.path.isfile(path):
        _missing(f"{path}")
    return path


@functools.lru_cache(maxsize=None)
def run(name: str, seconds: float, presses: tuple | None = (), trimmer_v: float | None = None, trace: bool = False):
    """``name``.hex on the 3pi for ``seconds`` of simulated time (or until a lap it drives ends) → (lap, report,
    UART lines). ``presses``: (button, at [s], lcd text or None, hold [s]) in order; () nobody presses; None: the
    default operator."""
    from twin.core.digital_twin import DigitalTwin
    from twin.model.robots import THREE_PI, use_robot
    from twin.pil.board import run_board_lap
    from twin.pil.board.operator import Script, Step
    from twin.pil.program import load_program

    twin = DigitalTwin(track="oval")
    use_robot(twin, THREE_PI)
    operator = None if presses is None else Script([Step(*p) for p in presses], "test")
    lines: list[tuple[float, str]] = []
    kw = {} if trimmer_v is None else {"trimmer_v": trimmer_v}
    lap, report = run_board_lap(twin, load_program(hex_path(name)), limits=LapLimits(timeout_s=seconds),
                                keep_trace=trace, operator=operator, on_line=lambda t, line: lines.append((t, line)),
                                **kw)
    return lap, report, lines


def screens(report) -> list[str]:
    """The LCD's screens in order, each as 'line 1|line 2' with trailing blanks (and a blank line 2) cut."""
    return ["|".join(line.rstrip() for line in text.split("\n")).rstrip("|") for _, text in report.lcd]


def timed(report) -> list[tuple[float, str]]:
    return list(zip((t for t, _ in report.lcd), screens(report)))


def first_time(report, shown: str) -> float:
    return next(t for t, s in timed(report) if s == shown)


KEYS = {"C": 0, "C#": 1, "D": 2, "D#": 3, "E-": 3, "E": 4, "F": 5, "F#": 6, "G": 7, "G#": 8, "A": 9, "B-": 10, "B": 11}


def hz(note: str) -> float:
    """'A4' → 440 Hz: note number key + 12 octave (A4 = 57), equal-tempered (OrangutanBuzzer.cpp:316-332)."""
    n = KEYS[note[:-1]] + 12 * int(note[-1])
    return 440.0 * 2 ** ((n - 57) / 12)


def check_notes(played, expected, *, duty=0.5, gap_ms=3.0):
    """Notes played (start, end, Hz, duty) against (note, ms) in order, a note None a rest: each note at its pitch and
    length, the next one after the rests between them (and up to ``gap_ms`` for the program's own work)."""
    sounding = [(note, ms) for note, ms in expected if note]
    assert len(played) >= len(sounding), played
    rest, k = 0.0, 0
    for note, ms in expected:
        if note is None:
            rest += ms
            continue
        start, end, f, d = played[k]
        assert f == pytest.approx(hz(note), rel=5e-3), (k, note, f)
        # timeout = dur * f / 1000 periods (OrangutanBuzzer.cpp:281), counted down past 0 (:85): one period more
        assert ms - 1.0 <= (end - start) * 1e3 <= ms + 1.0 + 1e3 / f, (k, note, end - start)
        assert d == pytest.approx(duty, rel=0.02), (k, note, d)
        if k:
            assert 0 <= (start - played[k - 1][1]) * 1e3 - rest <= gap_ms, (k, note, start, played[k - 1][1], rest)
        rest, k = 0.0, k + 1


def led_changes(report, red: bool = True) -> list[tuple[float, bool]]:
    """When the red (or green) LED changed and to what, from the report's changes of either."""
    out, last = [], False
    for t, r, g in report.leds:
        v = r if red else g
        if v != last:
            out.append((t, v))
            last = v
    return out


def lit_share(report, red: bool = True) -> float:
    return report.led_summary(report.cycles / F_CPU)["lit_share"]["red" if red else "green"]


def motor_volts(speed: int) -> float:
    """set_motors(speed): both timers in inverted fast PWM (TCCR0A = TCCR2A = 0xF3, OrangutanMotors.cpp:131), one
    driver input held at OCR = 0, the other at OCR = speed (:208-214): speed/256 of the period across the motor
    (datasheet 14.7.3), of the 3pi's regulated 9.25 V."""
    from twin.model.robots import THREE_PI

    return speed / 256 * THREE_PI.values["power.regulator_voltage"]


def adc10(volts: float) -> float:
    return volts / 5.0 * 1024  # ATmega328P datasheet 24.7: ADC = V_in 1024 / V_ref
