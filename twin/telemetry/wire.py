"""The telemetry on the wire: the compact line form the robot's firmware sends over its serial link.

Same records as the file format (:mod:`twin.telemetry.jsonl`), as short ASCII lines an 8-bit MCU can ``printf``
at its loop rate, framed like NMEA 0183: ``$`` + comma-separated fields + ``*`` + checksum + newline, the
checksum being the XOR of the bytes between ``$`` and ``*`` as two hex digits. Integers only:

* ``$LFH,1,<sensors>,<dt_us>,<every>*CS``: header, wire version 1 (sent at power-up and every lap start)
* ``$LFS,<t_ms>,<pos>,<seen>,<wl_crad>,<wr_crad>*CS``: sample; time since power-up [ms], readLine position,
  line seen 0/1, encoder wheel speeds [0.01 rad/s]
* ``$LFE,<t_ms>,START*CS``, ``$LFE,<t_ms>,LAP,<lap_ms>*CS``, ``$LFE,<t_ms>,FAIL,<reason>*CS``: events

A sample every ``every`` control ticks (default 2: 100 lines/s at Δt = 5 ms, ≈ 3.5 kB/s, within a 115200-baud
Bluetooth SPP link). A line whose checksum or fields are wrong raises :class:`WireError`; readers count and
skip those. :class:`LineSplitter` cuts a byte stream into lines with a bounded memory: a line longer than
``MAX_LINE`` is junk however long it goes on, and is skipped up to its newline without being kept.
"""

from __future__ import annotations

import dataclasses

from twin.errors import TwinError

WIRE_VERSION = 1
MAX_LINE = 96  # bytes; longer is garbage (the longest valid line is < 60)


class WireError(TwinError):
    """A corrupted or truncated telemetry line."""


@dataclasses.dataclass(frozen=True)
class Header:
    sensors: int
    dt_s: float
    every: int


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
        return frame(["LFH", WIRE_VERSION, record.sensors, round(record.dt_s * 1e6), record.every])
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


def decode(raw: bytes | str):
    """One wire line → :class:`Header`, :class:`Sample` or :class:`Event`; :class:`WireError` if corrupted."""
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
    if kind == "LFH" and len(f) == 5:
        if _int(f, 1, 0, 1000, line) != WIRE_VERSION:
            raise WireError(f"wire version {f[1]} is not supported (this reads {WIRE_VERSION})")
        return Header(_int(f, 2, 1, 32, line), _int(f, 3, 1, 10**6, line) / 1e6, _int(f, 4, 1, 1000, line))
    if kind == "LFE" and len(f) >= 3:
        t = _int(f, 1, 0, 2**32, line) / 1000
        if f[2] == "START" and len(f) == 3:
            return Event(t, "START")
        if f[2] == "LAP" and len(f) == 4:
            return Event(t, "LAP", lap_time_s=_int(f, 3, 1, 10**7, line) / 1000)
        if f[2] == "FAIL" and len(f) == 4:
            return Event(t, "FAIL", reason=f[3])
    raise WireError(f"unknown or malformed record {line!r}")
