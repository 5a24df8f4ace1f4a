"""The person at the robot: who presses its buttons while a program waits on them.

Pololu's 3pi examples show a prompt, wait for button B, calibrate by spinning, wait for B again and go. The default
:class:`Operator` does what a person would: when the program has been polling the buttons (reading PINB with a button
line an input with its pull-up) while the motors stood still for ``patience`` seconds, it presses the button the LCD
asks for ("Press A", "push C", "button B"), else B, and holds it ``hold`` seconds. A :class:`Script` (``--operator
FILE``) presses instead what a JSON file lists, in order, each at a time or when the LCD shows a text::

    {"presses": [{"button": "B", "lcd": "Press B"},
                 {"button": "B", "at": 9.5, "hold": 0.3}]}

``at`` is seconds since power-up; ``lcd`` a text the screen must show (both lines joined by a space; case and runs of
spaces ignored);
with both, the press waits for both. After the last press nobody touches the robot.

Decisions are taken between chunks of simulated time (:data:`twin.pil.lap.CHUNK_S`), from the simulated state only:
the same seed gives the same presses.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import re

from twin.errors import TwinError
from twin.pil.board.display import plain

BUTTONS = {"A": 1, "B": 2, "C": 4}  # lf_avr_buttons' bits
ASKED = re.compile(r"(?i)\b(?:press|push|hit|button)\s*([abc])\b")
HOLD_S = 0.2  # a person's press, long enough for Pololu's 100 ms polling loops and 10 ms debouncing
PATIENCE_S = 0.5
POLLING_GAP_S = 0.15  # a program still polling read the buttons this recently (Pololu's loops: every 100 ms)
MAX_SCRIPT_BYTES = 1 << 20


@dataclasses.dataclass(frozen=True)
class Press:
    """A press: button (A, B or C), at ``t`` [s since power-up], held ``hold`` [s], by whom."""

    t: float
    button: str
    hold: float
    by: str


@dataclasses.dataclass(frozen=True)
class Seen:
    """What the operator sees between chunks: the time [s since power-up], the buttons' last poll and the motors'
    last drive [s, -inf never], and the LCD's screen."""

    now: float
    last_poll: float
    last_drive: float
    screen: str


class Operator:
    """The default operator (module docstring)."""

    def __init__(self, patience_s: float = PATIENCE_S, hold_s: float = HOLD_S):
        self.patience_s, self.hold_s = patience_s, hold_s
        self.released = -math.inf  # when the last press ended
        self.polling_since: float | None = None  # the first poll seen of the polling going on now

    def decide(self, seen: Seen) -> Press | None:
        if seen.now - seen.last_poll > POLLING_GAP_S:  # not polling (any more)
            self.polling_since = None
            return None
        if self.polling_since is None:
            self.polling_since = seen.last_poll
        quiet_since = max(seen.last_drive, self.released, self.polling_since)
        if seen.now - quiet_since < self.patience_s:
            return None
        asked = ASKED.search(plain(seen.screen))
        press = Press(seen.now, asked.group(1).upper() if asked else "B", self.hold_s, "operator")
        self.released, self.polling_since = seen.now + self.hold_s, None
        return press


@dataclasses.dataclass(frozen=True)
class Step:
    button: str
    at: float | None
    lcd: str | None
    hold: float


class Script:
    """Presses read from a file (module docstring)."""

    def __init__(self, steps: list[Step], source: str):
        self.steps, self.source, self.next = steps, source, 0
        self.released = -math.inf

    def decide(self, seen: Seen) -> Press | None:
        if self.next >= len(self.steps) or seen.now < self.released:
            return None
        step = self.steps[self.next]
        if step.at is not None and seen.now < step.at:
            return None
        if step.lcd is not None and plain(step.lcd).lower() not in plain(seen.screen).lower():
            return None
        self.next += 1
        self.released = seen.now + step.hold
        return Press(seen.now, step.button, step.hold, "script")


def load_script(path: str) -> Script:
    """The presses in ``path``, checked; a one-line TwinError naming the problem otherwise."""
    if not os.path.isfile(path):
        raise TwinError(f"--operator {path}: no such file")
    try:
        if os.path.getsize(path) > MAX_SCRIPT_BYTES:
            raise TwinError(f"--operator {path}: larger than {MAX_SCRIPT_BYTES} bytes; not a list of presses")
        with open(path, encoding="utf-8") as f:
            doc = json.load(f)
    except (OSError, UnicodeDecodeError) as e:
        raise TwinError(f"--operator {path}: cannot read it ({getattr(e, 'strerror', None) or e})") from None
    except json.JSONDecodeError as e:
        raise TwinError(f"--operator {path}: not JSON ({e.msg}, line {e.lineno})") from None
    presses = doc.get("presses") if isinstance(doc, dict) else None
    if not isinstance(presses, list) or set(doc) - {"presses"}:
        raise TwinError(f'--operator {path}: expected {{"presses": [{{"button": "B", "at": 2.0}}, ...]}}')
    steps = []
    for k, p in enumerate(presses, 1):
        where = f"--operator {path}: press {k}"
        if not isinstance(p, dict) or set(p) - {"button", "at", "lcd", "hold"}:
            raise TwinError(f"{where}: expected an object with button and at and/or lcd (and hold)")
        button = p.get("button")
        if button not in BUTTONS:
            raise TwinError(f"{where}: button must be A, B or C, got {button!r}")
        at, lcd, hold = p.get("at"), p.get("lcd"), p.get("hold", HOLD_S)
        if at is None and lcd is None:
            raise TwinError(f"{where}: give at (seconds since power-up) or lcd (a text the screen shows), or both")
        if at is not None and not (_number(at) and 0 <= at <= 3600):
            raise TwinError(f"{where}: at must be a number of seconds in [0, 3600], got {at!r}")
        if lcd is not None and not (isinstance(lcd, str) and plain(lcd)):
            raise TwinError(f"{where}: lcd must be a non-empty text, got {lcd!r}")
        if not (_number(hold) and 0.01 <= hold <= 60):
            raise TwinError(f"{where}: hold must be a number of seconds in [0.01, 60], got {hold!r}")
        steps.append(Step(button, None if at is None else float(at), lcd, float(hold)))
    return Script(steps, path)


def _number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
