"""The bytes between the twin and its controller FMU's process (:mod:`twin.fmi.wall`, :mod:`twin.fmi.host`).

Requests, twin to host, each a kind byte first: ``L`` a new lap (the folder to extract a fresh instance into, its
length first, uint32, UTF-8): the host closes the lap before, loads and initialises the FMU at time 0 and answers
``R``; ``S`` one step: ``t`` and ``h`` [s] and the mapped inputs' values (as the FMU takes them: sign, scale and offset
applied), all float64 (an integer or a flag travels
exactly as a double). The end of the requests (end of file) closes the FMU and ends the host. Replies, host to twin:
a kind byte, then ``R`` ready, ``K`` the step's (left, right) outputs as two float64, or ``E`` a UTF-8 error line
(its length first, uint32). Native byte order: both ends are one machine.
"""

from __future__ import annotations

import os
import struct

LAP, STEP = b"L", b"S"
READY, OUTPUTS, ERROR = b"R", b"K", b"E"
OUT = struct.Struct("=dd")
LENGTH = struct.Struct("=I")
MAX_ERROR = 4096  # [bytes] of an error line


def request(n: int) -> struct.Struct:
    """A step request's body with ``n`` inputs: t, h, then the inputs."""
    return struct.Struct(f"={n + 2}d")


def lap_request(folder: str) -> bytes:
    text = folder.encode("utf-8")
    return LAP + LENGTH.pack(len(text)) + text


def read_exact(fd: int, n: int) -> bytes | None:
    """``n`` bytes (blocking: the host's side), or None at the end of the requests."""
    parts, got = [], 0
    while got < n:
        chunk = os.read(fd, n - got)
        if not chunk:
            return None
        parts.append(chunk)
        got += len(chunk)
    return b"".join(parts)


def write_all(fd: int, data: bytes) -> None:
    view = memoryview(data)
    while view:
        view = view[os.write(fd, view):]


def send_ready(fd: int) -> None:
    write_all(fd, READY)


def send_outputs(fd: int, left: float, right: float) -> None:
    write_all(fd, OUTPUTS + OUT.pack(left, right))


def send_error(fd: int, line: str) -> None:
    text = " ".join(line.split()).encode("utf-8", "replace")[:MAX_ERROR]
    write_all(fd, ERROR + LENGTH.pack(len(text)) + text)
