"""The robot's serial link, read so that nothing it sends is lost, and nothing waits forever.

* **Open without flushing.** pyserial's ``open()`` discards what arrived before the port was opened
  (``tcflush(TCIFLUSH)`` on a tty or pty, a ``recv`` loop on ``socket://``): a robot that talks first lost its
  first lines on every (re)connection. The flush is suppressed during ``open()``; a device path is opened with
  an exclusive lock, so a second reader cannot split the stream.
* **Every byte reaches the log, durably, and nothing else.** Bytes are appended to the log
  (:class:`twin.link.telemetry_log.DurableLog`) exactly as received, unbuffered, before any line is decoded, so a
  killed process (even SIGKILL) loses nothing it had read; a link that ends keeps its last bytes (pyserial's
  ``read(n)`` dropped what it had read when the link ended). The log is fsynced at least every
  ``FSYNC_INTERVAL_S`` (0.25 s) and after every lap event, so an OS crash or power loss costs at most the last
  quarter second. One reader per log: it is locked.
* **No glued lines.** Where a connection ends (mid-line or not), the log's break index records the offset, out
  of band: a line it cut off stays one corrupted line instead of joining the next one, when the log is read back.
* **A log that cannot be written stops the reading** (:class:`LogWriteError`): the log is the record.
* **Responsive.** A read returns what has arrived within ``READ_TIMEOUT_S`` (0.1 s), newline or not, so a stop
  request or ``--duration`` is seen within that; a line longer than :data:`twin.telemetry.wire.MAX_LINE` is logged but not
  kept in memory, and counts as one corrupted line.
* **Commands go out between reads.** What the twin has queued for the robot (:class:`Outbox`) is written after each
  read, while the link is open, within ``READ_TIMEOUT_S`` of being queued; a command still queued when its
  deadline passes (the link was down) is dropped, not sent late. Nothing the twin sends reaches the log: the log
  is what the robot sent.
* **Bounded retries.** A link that stays down (cannot be opened, or keeps dropping without delivering a byte)
  for ``retry_s`` wall seconds (default ``RETRY_S`` = 30 s) gives up with :class:`LinkGaveUp`, unless retrying
  forever is asked for; reopening backs off exponentially from 0.05 s up to 2 s. A URL pyserial cannot parse,
  or a path that is not a device, is bad input (:class:`TwinError`).
"""

from __future__ import annotations

import contextlib
import dataclasses
import io
import logging
import os
import select
import stat
import threading
import time
from typing import Callable

from lf_common.errors import LineFollowerError
from twin.errors import TwinError
from twin.link.telemetry_log import FSYNC_INTERVAL_S, DurableLog, LogWriteError  # noqa: F401  (part of this face)
from twin.telemetry.wire import LineSplitter

log = logging.getLogger(__name__)

READ_TIMEOUT_S = 0.1  # [s] the longest a read waits: how late a stop request or --duration is seen
READ_CHUNK = 65536  # [bytes] per read at most
WRITE_TIMEOUT_S = 1.0  # [s] a robot that takes no command for this long: the link counts as dropped
RETRY_S = 30.0  # [s] without a link before giving up
BACKOFF_S = (0.05, 2.0)  # [s] first and longest wait between attempts to reopen
BAUD = 115200


class LinkGaveUp(LineFollowerError):
    """The link could not be (re)opened within the retry budget: a negative outcome, not bad input."""


@dataclasses.dataclass
class LinkStats:
    lines: int = 0  # lines received and logged (a line cut off by a drop counts, as a corrupted one)
    corrupted: int = 0  # lines that did not decode, were too long, or were cut off
    reconnects: int = 0  # failed opens and drops
    opened: int = 0  # times the link opened
    robot_laps: int = 0  # LAP and FAIL events received
    implausible_laps: int = 0  # laps that failed the plausibility checks (see twin.telemetry.laps)


class Outbox:
    """Lines for the robot, queued by the twin from any thread and written by the reader while the link is open.
    Each line has a deadline (wall clock, ``time.monotonic``): one still queued after it is dropped."""

    def __init__(self):
        self._lock = threading.Lock()
        self._queue: list[tuple[float, bytes]] = []
        self.sent = 0  # lines written
        self.dropped = 0  # lines whose deadline passed before the link could take them

    def put(self, line: bytes, deadline: float) -> None:
        with self._lock:
            self._queue.append((deadline, line))

    def take(self) -> bytes:
        now = time.monotonic()
        with self._lock:
            live = [line for deadline, line in self._queue if deadline >= now]
            self.dropped += len(self._queue) - len(live)
            self._queue.clear()
        self.sent += len(live)
        return b"".join(live)


def check_port(url: str) -> None:
    """Refuse, as bad input, what no retry can fix: an unknown scheme or a malformed URL, pyserial's loopback, or a
    path that exists and is not a device (a missing device path is fine: it may be plugged in later)."""
    import serial

    if url.lower().startswith("loop://"):  # it returns only what this process writes: no robot can ever reach it
        raise TwinError(f"{url}: pyserial's loopback carries only what the reader itself writes, so no robot can "
                        "reach it; give the robot's device, a pty path or socket://HOST:PORT")
    if "://" not in url:
        with contextlib.suppress(OSError):
            if not stat.S_ISCHR(os.stat(url).st_mode):
                raise TwinError(f"{url}: not a serial device (a character device or pty)")
        return
    try:
        port = serial.serial_for_url(url, do_not_open=True)
        if hasattr(port, "from_url"):  # socket://, rfc2217:// parse the rest of the URL only in open()
            port.from_url(url)
    except Exception as e:  # parsing only: any failure is the URL's (pyserial 3.5 even raises KeyError for some)
        why = _first_line(e) if isinstance(e, (ValueError, serial.SerialException)) else "malformed"
        raise TwinError(f"{url}: not a serial device or pyserial URL ({why})") from None


def open_port(url: str):
    """The port at ``url``, opened without discarding what it already received."""
    import serial

    check_port(url)
    device = "://" not in url
    port = serial.serial_for_url(url, do_not_open=True, baudrate=BAUD, timeout=READ_TIMEOUT_S, write_timeout=WRITE_TIMEOUT_S,
                                 **({"exclusive": True} if device else {}))
    # pyserial flushes the input in open() (posix: _reset_input_buffer; socket: reset_input_buffer); keep it
    port._reset_input_buffer = port.reset_input_buffer = lambda: None
    try:
        port.open()
    finally:
        del port._reset_input_buffer, port.reset_input_buffer
    return port


class _Backoff:
    """Waits between attempts to reopen, and the retry budget. The budget's clock runs while the link is down;
    it restarts when bytes arrive, and when a connection that stayed open at least ``MIN_UP_S`` ends (a silent
    robot is still there; a port that opens and closes at once, or a server that hangs up, is not a link)."""

    MIN_UP_S = BACKOFF_S[1]

    def __init__(self, retry_s: float | None):
        self.retry_s, self.wait_s = retry_s, BACKOFF_S[0]
        self.down_since = self.opened_at = time.monotonic()

    def opened(self) -> None:
        self.opened_at = time.monotonic()

    def received(self) -> None:
        self.wait_s, self.down_since = BACKOFF_S[0], time.monotonic()

    def closed(self) -> None:
        if time.monotonic() - self.opened_at >= self.MIN_UP_S:
            self.wait_s, self.down_since = BACKOFF_S[0], time.monotonic()

    def failed(self, url: str, why: str, stop: Callable[[], bool]) -> None:
        """Wait before the next attempt; :class:`LinkGaveUp` once the budget is spent."""
        if self.retry_s is not None and time.monotonic() - self.down_since >= self.retry_s:
            raise LinkGaveUp(f"{url}: no link for {self.retry_s:g} s ({why}); giving up")
        log.info("link %s: %s; retrying in %.2f s", url, why, self.wait_s)
        _sleep_unless(stop, self.wait_s)
        self.wait_s = min(BACKOFF_S[1], self.wait_s * 2)


def read_link(url: str, out: DurableLog, on_line: Callable[[bytes], bool], on_idle: Callable[[], None],
              stats: LinkStats, stop: Callable[[], bool], retry_s: float | None = RETRY_S,
              outbox: Outbox | None = None) -> None:
    """Read ``url`` until ``stop()`` says so: every byte to ``out``, every complete line to ``on_line`` (which
    returns True for a lap event: the log is then fsynced), ``on_idle`` when a read brings nothing; what the
    ``outbox`` holds is written to the robot between reads. Reopens a dropped link with backoff; raises
    :class:`LinkGaveUp` once the link has been down for ``retry_s`` wall seconds (None: never give up)."""
    import serial

    backoff = _Backoff(retry_s)
    while not stop():
        try:
            port = open_port(url)
        except (serial.SerialException, OSError) as e:
            stats.reconnects += 1
            backoff.failed(url, _first_line(e), stop)
            continue
        backoff.opened()
        stats.opened += 1
        lines, dropped = LineSplitter(), None
        try:
            _read_open_port(port, out, lines, on_line, on_idle, stats, stop, backoff, outbox)
        except (serial.SerialException, OSError) as e:
            log.warning("link %s dropped (%s); reopening", url, _first_line(e))
            stats.reconnects += 1
            dropped = _first_line(e)
        finally:
            if lines.cut():  # the link ended inside a line: one corrupted line
                stats.lines += 1
                stats.corrupted += 1
            with contextlib.suppress(Exception):
                port.close()
            # marked out of band (the log keeps only what came), so the next connection's bytes start a line
            out.end_stream(f"dropped: {dropped}" if dropped is not None else "stopped")
            backoff.closed()
        if dropped is not None and not stop():
            backoff.failed(url, f"dropped: {dropped}", stop)


def read_available(port) -> bytes:
    """What has arrived on ``port``, waiting at most ``READ_TIMEOUT_S``; b"" if nothing did. A link that has
    ended raises (on the call after its last bytes). pyserial's ``read(n)`` is not used where the port has a
    file descriptor: it keeps reading until n bytes or the timeout, and when the link ends on the way it raises
    and drops what it had already read."""
    import serial

    try:
        fd = port.fileno()
    except (AttributeError, NotImplementedError, io.UnsupportedOperation, serial.SerialException):  # rfc2217:// and
        # other ports without a file descriptor (UnsupportedOperation is an OSError: it is not a drop)
        return port.read(port.in_waiting or 1)
    ready, _, _ = select.select([fd], [], [], READ_TIMEOUT_S)
    if not ready:
        return b""
    try:
        data = os.read(fd, READ_CHUNK)
    except BlockingIOError:  # woken for nothing
        return b""
    if not data:
        raise serial.SerialException("the link was closed at the other end")
    return data


def _read_open_port(port, out: DurableLog, lines: LineSplitter, on_line, on_idle, stats: LinkStats, stop,
                    backoff: _Backoff, outbox: Outbox | None = None) -> None:
    while not stop():
        if outbox is not None:
            pending = outbox.take()
            if pending:
                port.write(pending)
                port.flush()
        data = read_available(port)
        if not data:
            out.maybe_sync()
            on_idle()
            continue
        out.write(data)  # in the OS before any of it is decoded
        backoff.received()
        lap_event = False
        for line in lines.feed(data):
            stats.lines += 1
            if line is None:  # longer than any wire line: junk
                stats.corrupted += 1
            elif not stop():  # (once stopped, the rest is only logged: a restart replays it from the log)
                lap_event |= bool(on_line(line))
        if lap_event:
            out.sync()
        else:
            out.maybe_sync()


def _first_line(e: BaseException) -> str:
    return str(e).splitlines()[0] if str(e) else type(e).__name__


def _sleep_unless(stop: Callable[[], bool], seconds: float) -> None:
    end = time.monotonic() + seconds
    while time.monotonic() < end and not stop():
        time.sleep(min(0.05, end - time.monotonic()))
