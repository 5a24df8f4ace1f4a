"""The telemetry log on disk: exactly the bytes received, and beside it, out of band, where each stream ended.

* **Those bytes and no others.** The log is appended unbuffered as bytes arrive, locked (``flock``, exclusive,
  non-blocking: a second reader is refused) and fsynced at least every ``FSYNC_INTERVAL_S``. Nothing is ever
  added to it: not a newline at a drop, a stop or after a crash.
* **Where a stream ended.** A link that drops, a stop, or a crash can leave a line half received; the next
  connection's bytes would continue it. The break index ``<log>.breaks`` (JSON Lines: a header of this program,
  then ``{"offset": N, "why": …}`` per end of a stream) records the byte offset of each end, so that a reader
  of the log (:func:`log_lines`: replay, resume) ends the line there instead of gluing it to the next one.
  A crash leaves no mark: the next run adds it at the log's end before appending anything. The index is created
  whole (its header in one step, before the log) or not at all: a full disk leaves nothing that blocks the next run.
* **Only a log of this program is appended to.** The log cannot carry a header (it is the robot's bytes alone);
  the break index beside it, which every run creates, is what marks it as ours (:func:`log_is_ours`). A file at
  ``--log`` without one is the user's: refused, untouched (:func:`check_log`).
* **A log being written is locked**: :func:`unlocked_for_reading` refuses it (``history --rebuild``); the lock dies
  with the process that held it, so a crashed run leaves nothing stale.
* **A log that cannot be written stops the reading** (:class:`LogWriteError`, naming the file and the cause): the
  log is the record, and bytes that cannot be kept are not decoded either.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import json
import logging
import os
import stat
import time
from typing import Iterator

from lf_common.errors import OutputError
from lf_common.appended import create_whole, ends_with_newline
from lf_common.files import GENERATOR, jsonl_is_ours
from twin.errors import TwinError
from twin.telemetry.wire import LineSplitter

log = logging.getLogger(__name__)

FSYNC_INTERVAL_S = 0.25  # [s] at most this much of what was read is only in the OS's cache
BREAKS_KIND = "telemetry log breaks"
_CHUNK = 1 << 16  # [bytes] read at a time when a log is read back


class LogWriteError(OutputError):
    """The log (or its break index) could not be written: the reading stops, nothing more is decoded."""


def breaks_path(log_path: str) -> str:
    return f"{log_path}.breaks"


def _why(e: OSError) -> str:
    return e.strerror or str(e)


def _check_log_path(path: str) -> None:
    """A regular file, or none yet: a folder or a device (``/dev/full``) cannot be a durable, lockable log."""
    try:
        st = os.stat(path)
    except FileNotFoundError:
        return
    except OSError as e:
        raise TwinError(f"{path}: cannot open the telemetry log ({_why(e)})") from None
    if stat.S_ISDIR(st.st_mode):
        raise TwinError(f"{path}: is a folder; name a file for the telemetry log")
    if not stat.S_ISREG(st.st_mode):
        raise TwinError(f"{path}: is not a regular file; name a file for the telemetry log")


def _index_is_ours(index_path: str) -> bool:
    if not (os.path.isfile(index_path) and not os.path.islink(index_path)):
        return False
    try:
        with open(index_path, "rb") as f:
            head = json.loads(f.readline(2**16))
    except (OSError, ValueError):
        return False
    return isinstance(head, dict) and head.get("generator") == GENERATOR and head.get("kind") == BREAKS_KIND


def log_is_ours(path: str) -> bool:
    """A telemetry log this program wrote: its break index (which every run creates first) carries the header."""
    return _index_is_ours(breaks_path(path))


def check_log(path: str) -> None:
    """``--log`` can be appended to: no file yet, or a log of ours (see :func:`log_is_ours`). A file there that
    this program did not write is refused, left as it is; a folder or a device is refused too."""
    _check_log_path(path)
    if os.path.exists(path) and not log_is_ours(path):
        raise TwinError(f"{path}: exists and is not a telemetry log of {GENERATOR} (it has no break index "
                        f"{os.path.basename(breaks_path(path))} of this program beside it); it is left as it is: "
                        "choose another --log or move it away")


def _is_locked_error(e: OSError) -> bool:
    return e.errno in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES)


@contextlib.contextmanager
def unlocked_for_reading(path: str, why: str):
    """Hold a shared lock on the log while reading it; a log that ``live`` is writing (its exclusive lock) is
    refused, naming ``why`` the whole log is needed."""
    try:
        f = open(path, "rb")
    except OSError as e:
        raise TwinError(f"{path}: cannot read the telemetry log ({_why(e)})") from None
    with f:
        try:
            fcntl.flock(f.fileno(), fcntl.LOCK_SH | fcntl.LOCK_NB)
        except OSError as e:
            if _is_locked_error(e):
                raise TwinError(f"{path}: live is still writing it (it is locked); {why}") from None
            raise TwinError(f"{path}: cannot lock the telemetry log ({_why(e)})") from None
        yield  # (the lock goes with the file)


class DurableLog:
    """An append-only, locked, periodically fsynced log of the bytes received, with its break index."""

    def __init__(self, path: str):
        self.path, self.index_path, self.failed = path, breaks_path(path), None
        _check_log_path(path)
        created = self._create_index()  # first: a log of ours always has one (a crash between leaves no stranger)
        try:
            self.file = open(path, "ab", buffering=0)  # unbuffered: a write is in the OS before anything else
        except OSError as e:
            self._remove_index(created)
            raise TwinError(f"{path}: cannot open the telemetry log ({_why(e)})") from None
        try:
            fcntl.flock(self.file.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError as e:
            self.file.close()
            self._remove_index(created)
            if _is_locked_error(e):
                raise TwinError(f"{path}: another process is logging to it (it is locked); give each link its own --log") from None
            raise TwinError(f"{path}: cannot lock the telemetry log ({_why(e)})") from None
        try:
            self.index = self._open_index()
        except BaseException:
            self.file.close()
            self._remove_index(created)
            raise
        self.size = os.fstat(self.file.fileno()).st_size
        self.marked = max(read_breaks(path), default=0)
        self.synced = time.monotonic()
        if self.size > self.marked and self._ends_mid_line():
            log.warning("%s: the last line was cut off (a crash?); marked in %s so it stays one corrupted line",
                        path, self.index_path)
            self.end_stream("the previous run ended inside a line")

    def _create_index(self) -> bool:
        """The break index with its header, created whole if there is none; one that this program did not write is
        refused. Whether this call created it."""
        if os.path.lexists(self.index_path):
            if not _index_is_ours(self.index_path):
                raise TwinError(f"{self.index_path}: exists and was not written by {GENERATOR} (the break index of "
                                f"{self.path}); move it away")
            return False
        header = {"generator": GENERATOR, "kind": BREAKS_KIND, "log": os.path.basename(self.path)}
        try:
            return create_whole(self.index_path, _json_line(header))
        except OSError as e:
            raise TwinError(f"{self.index_path}: cannot write the telemetry log's break index ({_why(e)})") from None

    def _remove_index(self, created: bool) -> None:
        if created:
            with contextlib.suppress(OSError):
                os.remove(self.index_path)

    def _open_index(self):
        """The break index, appended (a torn last mark ended first)."""
        try:
            index = open(self.index_path, "ab", buffering=0)
            if not ends_with_newline(self.index_path):
                index.write(b"\n")  # a mark torn by a power loss: ours, so it is ended rather than continued
        except OSError as e:
            raise TwinError(f"{self.index_path}: cannot write the telemetry log's break index ({_why(e)})") from None
        return index

    def _ends_mid_line(self) -> bool:
        return not ends_with_newline(self.path)

    def _failed(self, path: str, e: OSError) -> LogWriteError:
        self.failed = LogWriteError(f"{path}: cannot write the telemetry log{' break index' if path != self.path else ''} "
                                    f"({_why(e)}); stopped reading")
        return self.failed

    def write(self, data: bytes) -> None:
        view = memoryview(data)
        try:
            while view:  # a raw write may take less than all
                n = self.file.write(view)
                self.size += n
                view = view[n:]
        except OSError as e:
            raise self._failed(self.path, e) from None

    def end_stream(self, why: str) -> None:
        """The stream that was being logged ended here (a drop, a stop): mark its end in the break index, so that
        a line it cut off is not continued by the next stream. Nothing is written to the log itself."""
        if self.failed is not None or self.size <= self.marked:
            return
        self.sync()
        try:
            self.index.write(_json_line({"offset": self.size, "why": why, "time": round(time.time(), 3)}))
            os.fsync(self.index.fileno())
        except OSError as e:
            raise self._failed(self.index_path, e) from None
        self.marked = self.size

    def sync(self) -> None:
        if self.failed is not None:
            return
        try:
            os.fsync(self.file.fileno())
        except OSError as e:
            raise self._failed(self.path, e) from None
        self.synced = time.monotonic()

    def maybe_sync(self) -> None:
        if time.monotonic() - self.synced >= FSYNC_INTERVAL_S:
            self.sync()

    def close(self) -> None:
        with contextlib.suppress(OSError, LogWriteError):
            self.sync()
        self.index.close()
        self.file.close()  # releases the lock


def _json_line(doc: dict) -> bytes:
    return (json.dumps(doc, separators=(",", ":")) + "\n").encode()



def read_breaks(log_path: str) -> list[int]:
    """The offsets in the log where a stream ended, sorted; [] without a break index. A damaged mark is skipped
    (with a warning); an index this program did not write is ignored (with a warning)."""
    path = breaks_path(log_path)
    if not os.path.isfile(path):
        return []
    if not jsonl_is_ours(path):
        log.warning("%s: not a break index written by %s; ignored", path, GENERATOR)
        return []
    offsets, bad = set(), 0
    with open(path, "rb") as f:
        f.readline()  # the header
        for raw in f:
            try:
                offset = json.loads(raw)["offset"]
                if isinstance(offset, int) and not isinstance(offset, bool) and offset > 0:
                    offsets.add(offset)
                    continue
            except (ValueError, KeyError, TypeError):
                pass
            bad += raw.strip() != b""
    if bad:
        log.warning("%s: %d damaged marks skipped", path, bad)
    return sorted(offsets)


def log_lines(path: str) -> Iterator[bytes | None]:
    """The log's lines as they were received: each complete line (with its newline), or None for a line that is
    junk (longer than any wire line) or was cut off by the end of its stream (a break, or the end of the log).
    Read in chunks: a line of any length costs no more memory than a chunk."""
    breaks = read_breaks(path)
    lines, pos = LineSplitter(), 0
    with open(path, "rb") as f:
        while True:
            upto = next((b for b in breaks if b > pos), None)
            chunk = f.read(_CHUNK if upto is None else min(_CHUNK, upto - pos))
            if not chunk:
                break
            pos += len(chunk)
            yield from lines.feed(chunk)
            if pos == upto and lines.cut():
                yield None
    if lines.cut():
        yield None
