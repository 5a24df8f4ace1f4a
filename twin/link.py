"""The robot's serial link, read so that nothing it sends is lost, and nothing waits forever.

* **Open without flushing.** pyserial's ``open()`` discards what arrived before the port was opened
  (``tcflush`` on a tty, a ``recv`` loop on ``socket://``): a robot that talks first would lose its first lines
  on every (re)connection. The flush is suppressed during ``open()``.
* **Every byte reaches the log, durably.** Bytes are appended to the log exactly as received, before they are
  decoded; the log is flushed and fsynced at least every ``FSYNC_INTERVAL_S`` (0.25 s) and at every lap event,
  so a crash or SIGKILL loses at most the last quarter second that the OS had not yet written.
* **One reader per log.** The log is locked (``flock``, exclusive, non-blocking); a second process is refused.
* **A crash leaves no glued lines.** A log whose last line is partial (the process died mid-line) gets a newline
  first, so that line stays one corrupted line instead of joining the next one.
* **Responsive.** Reads return what has arrived within ``READ_TIMEOUT_S`` (0.1 s), newline or not, so a stop
  request or ``--duration`` is seen within that; a line longer than ``MAX_LINE_BYTES`` is logged but decoded
  as corrupted.
* **Bounded retries.** A link that cannot be (re)opened for ``retry_s`` wall seconds (default
  ``RETRY_S`` = 30 s) gives up with :class:`LinkGaveUp`, unless retrying forever is asked for; reopening backs off
  exponentially up to 2 s. A URL pyserial cannot parse is bad input (:class:`TwinError`).
"""

from __future__ import annotations

import contextlib
import dataclasses
import errno
import fcntl
import logging
import os
import time
from typing import Callable

from lf_common.errors import LineFollowerError
from twin.errors import TwinError

log = logging.getLogger(__name__)

FSYNC_INTERVAL_S = 0.25
READ_TIMEOUT_S = 0.1
READ_CHUNK = 65536  # bytes per read at most (a socket's in_waiting says only whether there is any)
MAX_LINE_BYTES = 4096  # the longest wire line is < 60 bytes: anything this long is junk
RETRY_S = 30.0
BACKOFF_MAX_S = 2.0
BAUD = 115200


class LinkGaveUp(LineFollowerError):
    """The link could not be (re)opened within the retry budget: a negative outcome, not bad input."""


@dataclasses.dataclass
class LinkStats:
    lines: int = 0  # complete lines received (and logged)
    corrupted: int = 0  # lines that did not decode, or were too long
    reconnects: int = 0  # failed opens and drops
    robot_laps: int = 0  # LAP and FAIL events received
    implausible_laps: int = 0  # laps that failed the plausibility checks (see tuner.live)


class DurableLog:
    """An append-only, locked, periodically fsynced log of the bytes received."""

    def __init__(self, path: str):
        self.path = path
        try:
            self.file = open(path, "ab")
        except IsADirectoryError:
            raise TwinError(f"{path}: is a folder; name a file for the telemetry log") from None
        except OSError as e:
            raise TwinError(f"{path}: cannot open the telemetry log ({e.strerror or e})") from None
        try:
            fcntl.flock(self.file.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError as e:
            self.file.close()
            if e.errno in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                raise TwinError(f"{path}: another process is logging to it (it is locked); give each link its own --log") from None
            raise TwinError(f"{path}: cannot lock the telemetry log ({e.strerror or e})") from None
        self._terminate_partial_line()
        self.synced = time.monotonic()

    def _terminate_partial_line(self) -> None:
        with open(self.path, "rb") as f:
            f.seek(0, os.SEEK_END)
            if f.tell() == 0:
                return
            f.seek(-1, os.SEEK_END)
            last = f.read(1)
        if last != b"\n":
            log.warning("%s: the last line was cut off (a crash?); ending it so it stays one corrupted line", self.path)
            self.write(b"\n")
            self.sync()

    def write(self, data: bytes) -> None:
        self.file.write(data)

    def sync(self) -> None:
        self.file.flush()
        os.fsync(self.file.fileno())
        self.synced = time.monotonic()

    def maybe_sync(self) -> None:
        if time.monotonic() - self.synced >= FSYNC_INTERVAL_S:
            self.sync()

    def close(self) -> None:
        with contextlib.suppress(OSError):
            self.sync()
        self.file.close()  # releases the lock


def open_port(url: str):
    """The port at ``url``, opened without discarding what it already received."""
    import serial

    try:
        port = serial.serial_for_url(url, do_not_open=True, baudrate=BAUD, timeout=READ_TIMEOUT_S)
    except ValueError as e:  # an unknown scheme or a malformed URL: no retry can fix it
        raise TwinError(f"{url}: not a serial device or pyserial URL ({e})") from None
    # pyserial flushes the input in open() (tty: _reset_input_buffer; socket: reset_input_buffer); keep it
    port._reset_input_buffer = port.reset_input_buffer = lambda: None
    try:
        port.open()
    finally:
        del port._reset_input_buffer, port.reset_input_buffer
    return port


def read_link(url: str, out: DurableLog, on_line: Callable[[bytes], bool], on_idle: Callable[[], None],
              stats: LinkStats, stop: Callable[[], bool], retry_s: float | None = RETRY_S) -> None:
    """Read ``url`` until ``stop()`` says so: every byte to ``out``, every complete line to ``on_line`` (which
    returns True for a lap event: the log is then fsynced before anything acts on it), ``on_idle`` when a read
    brings nothing. Reopens a dropped link with backoff; raises :class:`LinkGaveUp` after ``retry_s`` wall seconds
    without a link (None: never)."""
    import serial

    backoff, down_since = 0.05, time.monotonic()
    while not stop():
        try:
            port = open_port(url)
        except (serial.SerialException, OSError) as e:
            stats.reconnects += 1
            if retry_s is not None and time.monotonic() - down_since > retry_s:
                raise LinkGaveUp(f"{url}: no link for {retry_s:g} s ({e}); giving up") from None
            log.info("link %s not available (%s); retrying in %.2f s", url, e, backoff)
            _sleep_unless(stop, backoff)
            backoff = min(BACKOFF_MAX_S, backoff * 2)
            continue
        backoff = 0.05
        try:
            _read_open_port(port, out, on_line, on_idle, stats, stop)
        except (serial.SerialException, OSError) as e:
            log.warning("link %s dropped (%s); reopening", url, e)
            stats.reconnects += 1
        finally:
            out.sync()
            with contextlib.suppress(Exception):
                port.close()
        down_since = time.monotonic()


def _read_open_port(port, out: DurableLog, on_line, on_idle, stats: LinkStats, stop) -> None:
    pending = b""
    while not stop():
        data = port.read(max(READ_CHUNK, port.in_waiting))  # returns early, with what came, after READ_TIMEOUT_S
        if not data:  # (a closed socket or pty raises instead: pyserial reads EOF as a disconnection)
            out.maybe_sync()
            on_idle()
            continue
        out.write(data)
        pending += data
        *lines, pending = pending.split(b"\n")
        lap_event = False
        for line in lines:
            stats.lines += 1
            lap_event |= bool(on_line(line + b"\n"))
        if len(pending) > MAX_LINE_BYTES:  # no newline in sight: junk; what follows the next newline is decoded again
            stats.lines += 1
            stats.corrupted += 1
            pending = b""
        if lap_event:
            out.sync()  # a whole lap is on disk before anything acts on it
        else:
            out.maybe_sync()


def _sleep_unless(stop: Callable[[], bool], seconds: float) -> None:
    end = time.monotonic() + seconds
    while time.monotonic() < end and not stop():
        time.sleep(min(0.05, end - time.monotonic()))
