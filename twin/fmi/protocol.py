"""The bytes between the twin and its controller FMU's process (:mod:`twin.fmi.wall`, :mod:`twin.fmi.host`).

Requests, twin to host: one step each, ``t`` and ``h`` [s] and the mapped inputs' values, all float64 (an integer or
a flag travels exactly as a double); the end of the requests (end of file) closes the FMU. Replies, host to twin: a
kind byte, then ``R`` ready (loaded and initialised), ``K`` the step's (left, right) outputs as two float64, or ``E``
a UTF-8 error line (its length first, uint32). Native byte order: both ends are one machine.
"""

from __future__ import annotations

import os
import struct

READY, OUTPUTS, ERROR = b"R", b"K", b"E"
OUT = struct.Struct("=dd")
LENGTH = struct.Struct("=I")
MAX_ERROR = 4096  # [bytes] of an error line


def request(n: int) -> struct.Struct:
    """A step request with ``n`` inputs: t, h, then the inputs."""
    return struct.Struct(f"={n + 2}d")


def _read_exact(fd: int, n: int) -> bytes | None:
    parts, got = [], 0
    while got < n:
        chunk = os.read(fd, n - got)
        if not chunk:
            return None
        parts.append(chunk)
        got += len(chunk)
    return b"".join(parts)


def read_request(fd: int, n: int) -> tuple[float, float, tuple[float, ...]] | None:
    """The next step request (t, h, inputs), or None at the end of the requests (blocking: the host's side)."""
    layout = request(n)
    raw = _read_exact(fd, layout.size)
    if raw is None:
        return None
    t, h, *values = layout.unpack(raw)
    return t, h, tuple(values)


def _write(fd: int, data: bytes) -> None:
    view = memoryview(data)
    while view:
        view = view[os.write(fd, view):]


def send_ready(fd: int) -> None:
    _write(fd, READY)


def send_outputs(fd: int, left: float, right: float) -> None:
    _write(fd, OUTPUTS + OUT.pack(left, right))


def send_error(fd: int, line: str) -> None:
    text = " ".join(line.split()).encode("utf-8", "replace")[:MAX_ERROR]
    _write(fd, ERROR + LENGTH.pack(len(text)) + text)
