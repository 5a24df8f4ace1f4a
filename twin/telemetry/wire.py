"""The telemetry on the wire: the compact line form the robot's firmware sends over its serial link, and the
commands the twin sends back.

Same records as the file format (:mod:`twin.telemetry.jsonl`), as short ASCII lines an 8-bit MCU can ``printf``
at its loop rate, framed like NMEA 0183: ``$`` + comma-separated fields + ``*`` + checksum + newline, the
checksum being the XOR of the bytes between ``$`` and ``*`` as two hex digits. Integers only; no line is longer
than ``MAX_LINE`` bytes.

**Robot → twin** (telemetry; wire version 2, version 1 lines are still read):

* ``$LFH,2,<robot>,<sensors>,<dt_us>,<every>,<gains_seq>*CS``: header, sent at power-up and at every lap start.
  ``robot`` is the robot's id (1–16 of ``A-Z a-z 0-9 _ -``), ``gains_seq`` the sequence number of the command
  whose gains are in force for the lap that starts (0: the gains it booted on). Version 1:
  ``$LFH,1,<sensors>,<dt_us>,<every>*CS`` (no id, no commands).
* ``$LFS,<t_ms>,<pos>,<seen>,<wl_crad>,<wr_crad>*CS``: sample; time since power-up [ms], readLine position,
  line seen 0/1, encoder wheel speeds [0.01 rad/s]
* ``$LFE,<t_ms>,START*CS``, ``$LFE,<t_ms>,LAP,<lap_ms>*CS``, ``$LFE,<t_ms>,FAIL,<reason>*CS``: events
* ``$LFE,<t_ms>,BOOT,<source>,<seq>,<bad>*CS``: power-up, after the header: which gains it runs on. ``source``
  is ``STORED`` (the newest set stored in EEPROM), ``BACKUP`` (the newest stored set failed its CRC: the set
  stored before it, the last good one) or ``CONFIG`` (the gains it was flashed with: nothing good is stored);
  ``seq`` the command that stored them (0 for CONFIG); ``bad`` how many stored sets failed their check.
* ``$LFR,<seq>,ACK*CS``, ``$LFR,<seq>,NAK,<reason>*CS``: the answer to command ``seq``. Reasons: ``RANGE`` (a
  gain outside what the firmware accepts), ``LOCKED`` (its owner does not let the twin change it), ``EEPROM``
  (storing failed: written, read back, not equal), ``BADCMD`` (a command it does not know).
* ``$LFR,<seq>,GAINS,<in_force_seq>,<v_max>,<kb>,<kp>,<ki>,<kd>*CS``: the answer to GET: the gains in force
  (and the command that set them), in thousandths (below).

**Twin → robot** (commands, each with a sequence number 1–65535 the twin counts up and keeps):

* ``$LFC,<seq>,SET,<v_max>,<kb>,<kp>,<ki>,<kd>*CS``: new gains, in thousandths of their unit (v_max in mm/s,
  K_B in mm/s per rad, K_P in 0.001/s, K_I in 0.001/s², K_D in 0.001). The robot checks each against the range
  it accepts, answers ACK (or NAK) at once, and applies them **only between laps**: from its next lap start,
  whose header then carries ``seq``. A second SET before that replaces the first.
* ``$LFC,<seq>,GET*CS``: read the gains in force back (answer GAINS).
* ``$LFC,<seq>,STORE*CS``: keep the gains in force across power cycles: write them to EEPROM with their CRC,
  read them back, then ACK (NAK,EEPROM if they differ).

* ``$LFK,<n>*CS``: keep-alive: the twin is there and working (it sends one every ``KEEPALIVE_S``, 1 s, while
  it re-tunes, when no command goes out). ``n`` counts 1–65535 and wraps; it is not a command's sequence number:
  the robot answers it at once with the same line (``$LFK,<n>*CS``: the robot is there too), acts on nothing,
  keeps its last command's answer, and a robot waiting for the twin (an emulated robot in lockstep) goes on
  waiting, counting its idle time from this sign of life. A robot that does not know it ignores the line.

A robot answers every command it can decode once; a command repeating the last ``seq`` (the twin sent it again
after losing the answer) gets the same answer again and is not acted on twice. A line that fails its checksum
is not answered: the twin's wait for the answer ends, and it says so.

**Storing gains** (the twin's own firmware; any firmware may do the same): two slots of
``"LFG2" | gen (u16) | seq (u16) | v_max, kb, kp, ki, kd (i32, thousandths) | CRC-16/XMODEM of the rest (u16)``,
little-endian, 30 bytes each (:mod:`twin.link.robot_end` writes and checks them). STORE writes the slot that does
not hold the newest good set, with ``gen`` one more; at power-up the newest slot whose CRC checks wins.

A sample every ``every`` control ticks (default 2: 100 lines/s at Δt = 5 ms, ≈ 3.5 kB/s, within a 115200-baud
Bluetooth SPP link). A line whose checksum or fields are wrong raises :class:`WireError`; readers count and
skip those. :class:`LineSplitter` cuts a byte stream into lines with a bounded memory: a line longer than
``MAX_LINE`` is junk however long it goes on, and is skipped up to its newline without being kept.
"""

from __future__ import annotations

import dataclasses
import re
from typing import Mapping

from twin.errors import TwinError

WIRE_VERSION = 2  # what this reads and the twin's robots send; version 1 lines are read too
MAX_LINE = 96  # bytes; longer is garbage (the longest valid line is < 70)
GAIN_ADDRESSES = ("control.v_max", "control.kb", "control.kp", "control.ki", "control.kd")  # SET's order
GAIN_SCALE = 1000  # gains travel in thousandths of their unit
GAIN_LIMIT = 10**7  # |gain| in thousandths a line may carry
SEQ_MAX = 65535
KEEPALIVE_S = 1.0  # [s] while the twin is busy (re-tuning), a keep-alive goes out this often
BOOT_SOURCES = ("STORED", "BACKUP", "CONFIG")
COMMANDS = ("SET", "GET", "STORE")
NAK_REASONS = ("RANGE", "LOCKED", "EEPROM", "BADCMD")
_ROBOT_ID = re.compile(r"[A-Za-z0-9_-]{1,16}")


class WireError(TwinError):
    """A corrupted or truncated telemetry line."""


class UnknownCommand(WireError):
    """A well-framed command line (checksum and sequence number good) that is not a command this protocol has:
    the robot answers it NAK,BADCMD."""

    def __init__(self, message: str, seq: int):
        super().__init__(message)
        self.seq = seq


@dataclasses.dataclass(frozen=True)
class Header:
    sensors: int
    dt_s: float
    every: int
    robot: str | None = None  # the robot's id; None: a version 1 header (no id, no commands)
    gains_seq: int | None = None  # the command whose gains are in force (0: as booted); None in version 1

    @property
    def version(self) -> int:
        return 1 if self.robot is None else 2


@dataclasses.dataclass(frozen=True)
class Sample:
    t: float  # [s] since power-up
    pos: int
    seen: int
    wl: float  # [rad/s]
    wr: float


@dataclasses.dataclass(frozen=True)
class Event:
    t: float
    event: str  # START, LAP, FAIL
    lap_time_s: float | None = None
    reason: str | None = None


@dataclasses.dataclass(frozen=True)
class Boot:
    """Power-up: the gains the robot runs on, where they came from, and how many stored sets failed their check."""

    t: float
    source: str  # STORED, BACKUP or CONFIG
    seq: int  # the command that stored them (0: CONFIG)
    bad: int = 0


@dataclasses.dataclass(frozen=True)
class Command:
    """Twin → robot: SET (with gains in thousandths, :data:`GAIN_ADDRESSES` order), GET or STORE."""

    seq: int
    op: str
    gains: tuple[int, ...] | None = None


@dataclasses.dataclass(frozen=True)
class KeepAlive:
    """Twin → robot, and the robot's echo: the other end is there (``n`` counts 1–65535, wrapping)."""

    n: int


@dataclasses.dataclass(frozen=True)
class Reply:
    """Robot → twin: ACK, NAK (with its reason) or GAINS (the gains in force and the command that set them)."""

    seq: int
    kind: str
    reason: str | None = None
    in_force: int | None = None
    gains: tuple[int, ...] | None = None


def valid_robot_id(text: str) -> bool:
    return bool(_ROBOT_ID.fullmatch(text))


def gains_to_wire(values: Mapping[str, float]) -> tuple[int, ...]:
    """Gains by address → the integers a SET carries (thousandths, rounded)."""
    return tuple(round(float(values[a]) * GAIN_SCALE) for a in GAIN_ADDRESSES)


def gains_from_wire(gains: tuple[int, ...]) -> dict[str, float]:
    """A SET's or GAINS' integers → gains by address."""
    return {a: g / GAIN_SCALE for a, g in zip(GAIN_ADDRESSES, gains)}


def on_the_wire(values: Mapping[str, float]) -> dict[str, float]:
    """The gains as a robot will receive them: rounded to thousandths (what the twin races before sending)."""
    return gains_from_wire(gains_to_wire(values))


class LineSplitter:
    """Bytes as they arrive → complete lines (each with its newline). A line that grows past ``MAX_LINE`` bytes
    is not kept: it is reported once, as ``None``, when it ends (at its newline, or at :meth:`cut`), so a
    10 MB line without a newline costs no memory and counts as one corrupted line."""

    def __init__(self, max_bytes: int = MAX_LINE):
        self.max_bytes = max_bytes
        self.pending = bytearray()
        self.overlong = False  # the current line passed max_bytes: skipping to its newline

    def feed(self, data: bytes) -> list[bytes | None]:
        out: list[bytes | None] = []
        start = 0
        while (end := data.find(b"\n", start)) >= 0:
            if self.overlong:
                out.append(None)
            else:
                self.pending += data[start:end + 1]
                out.append(bytes(self.pending))
            self.pending.clear()
            self.overlong = False
            start = end + 1
        if not self.overlong:
            self.pending += data[start:]
            if len(self.pending) > self.max_bytes:
                self.pending.clear()
                self.overlong = True
        return out

    def cut(self) -> bool:
        """The stream ended (a drop, a stop, end of file): True if it ended inside a line, which is then dropped."""
        partial = bool(self.pending) or self.overlong
        self.pending.clear()
        self.overlong = False
        return partial


def checksum(body: str) -> str:
    x = 0
    for b in body.encode("ascii"):
        x ^= b
    return f"{x:02X}"


def frame(fields: list) -> str:
    body = ",".join(str(f) for f in fields)
    return f"${body}*{checksum(body)}\n"


def encode(record) -> str:
    if isinstance(record, Header):
        if record.robot is None:
            return frame(["LFH", 1, record.sensors, round(record.dt_s * 1e6), record.every])
        return frame(["LFH", 2, record.robot, record.sensors, round(record.dt_s * 1e6), record.every, record.gains_seq or 0])
    if isinstance(record, Boot):
        return frame(["LFE", round(record.t * 1000), "BOOT", record.source, record.seq, record.bad])
    if isinstance(record, Command):
        return frame(["LFC", record.seq, record.op, *(record.gains if record.op == "SET" else ())])
    if isinstance(record, Reply):
        extra = ([record.reason] if record.kind == "NAK" else
                 [record.in_force, *record.gains] if record.kind == "GAINS" else [])
        return frame(["LFR", record.seq, record.kind, *extra])
    if isinstance(record, KeepAlive):
        return frame(["LFK", record.n])
    if isinstance(record, Sample):
        return frame(["LFS", round(record.t * 1000), record.pos, record.seen, round(record.wl * 100), round(record.wr * 100)])
    if isinstance(record, Event):
        extra = [round(record.lap_time_s * 1000)] if record.event == "LAP" else [record.reason] if record.event == "FAIL" else []
        return frame(["LFE", round(record.t * 1000), record.event, *extra])
    raise TypeError(f"not a telemetry record: {record!r}")


def _int(fields: list[str], i: int, lo: int, hi: int, line: str) -> int:
    try:
        v = int(fields[i])
    except (IndexError, ValueError):
        raise WireError(f"field {i} of {line!r} is not an integer") from None
    if not lo <= v <= hi:
        raise WireError(f"field {i} of {line!r} is out of range [{lo}, {hi}]")
    return v


def _gains(f: list[str], first: int, line: str) -> tuple[int, ...]:
    return tuple(_int(f, i, -GAIN_LIMIT, GAIN_LIMIT, line) for i in range(first, first + len(GAIN_ADDRESSES)))


def decode(raw: bytes | str):
    """One wire line → :class:`Header`, :class:`Sample`, :class:`Event`, :class:`Boot`, :class:`Command`,
    :class:`Reply` or :class:`KeepAlive`; :class:`WireError` if corrupted."""
    if isinstance(raw, bytes):
        if len(raw) > MAX_LINE:
            raise WireError(f"line of {len(raw)} bytes is too long")
        try:
            raw = raw.decode("ascii")
        except UnicodeDecodeError:
            raise WireError("line is not ASCII") from None
    line = raw.strip()
    if len(line) > MAX_LINE:
        raise WireError(f"line of {len(line)} bytes is too long")
    if not line.startswith("$") or len(line) < 4 or line[-3] != "*":
        raise WireError(f"not a framed line: {line!r}")
    body, cs = line[1:-3], line[-2:]
    if checksum(body) != cs.upper():
        raise WireError(f"checksum mismatch in {line!r}")
    f = body.split(",")
    kind = f[0]
    if kind == "LFS" and len(f) == 6:
        return Sample(_int(f, 1, 0, 2**32, line) / 1000, _int(f, 2, 0, 15000, line), _int(f, 3, 0, 1, line),
                      _int(f, 4, -100000, 100000, line) / 100, _int(f, 5, -100000, 100000, line) / 100)
    if kind == "LFH" and len(f) >= 2:
        version = _int(f, 1, 0, 1000, line)
        if version == 1 and len(f) == 5:
            return Header(_int(f, 2, 1, 32, line), _int(f, 3, 1, 10**6, line) / 1e6, _int(f, 4, 1, 1000, line))
        if version == 2 and len(f) == 7:
            if not valid_robot_id(f[2]):
                raise WireError(f"robot id {f[2]!r} in {line!r} is not 1-16 of A-Z a-z 0-9 _ -")
            return Header(_int(f, 3, 1, 32, line), _int(f, 4, 1, 10**6, line) / 1e6, _int(f, 5, 1, 1000, line),
                          f[2], _int(f, 6, 0, SEQ_MAX, line))
        if version not in (1, 2):
            raise WireError(f"wire version {f[1]} is not supported (this reads 1 and {WIRE_VERSION})")
    if kind == "LFK" and len(f) == 2:
        return KeepAlive(_int(f, 1, 1, SEQ_MAX, line))
    if kind == "LFC" and len(f) >= 2:
        seq = _int(f, 1, 1, SEQ_MAX, line)
        if len(f) >= 3 and f[2] == "SET" and len(f) == 3 + len(GAIN_ADDRESSES):
            return Command(seq, "SET", _gains(f, 3, line))
        if len(f) == 3 and f[2] in COMMANDS and f[2] != "SET":
            return Command(seq, f[2])
        raise UnknownCommand(f"unknown or malformed command {line!r}", seq)
    if kind == "LFR" and len(f) >= 3:
        seq = _int(f, 1, 1, SEQ_MAX, line)
        if f[2] == "ACK" and len(f) == 3:
            return Reply(seq, "ACK")
        if f[2] == "NAK" and len(f) == 4 and f[3].isalnum():
            return Reply(seq, "NAK", reason=f[3])
        if f[2] == "GAINS" and len(f) == 4 + len(GAIN_ADDRESSES):
            return Reply(seq, "GAINS", in_force=_int(f, 3, 0, SEQ_MAX, line), gains=_gains(f, 4, line))
    if kind == "LFE" and len(f) >= 3:
        t = _int(f, 1, 0, 2**32, line) / 1000
        if f[2] == "BOOT" and len(f) == 6 and f[3] in BOOT_SOURCES:
            return Boot(t, f[3], _int(f, 4, 0, SEQ_MAX, line), _int(f, 5, 0, 255, line))
        if f[2] == "START" and len(f) == 3:
            return Event(t, "START")
        if f[2] == "LAP" and len(f) == 4:
            return Event(t, "LAP", lap_time_s=_int(f, 3, 1, 10**7, line) / 1000)
        if f[2] == "FAIL" and len(f) == 4:
            return Event(t, "FAIL", reason=f[3])
    raise WireError(f"unknown or malformed record {line!r}")
