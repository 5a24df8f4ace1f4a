"""What the twin did beside the robot, kept beside the telemetry log as ``<log>.actions``: one JSON line per action
(an alignment, a re-tuning, a command sent, its answer, a change confirmed or rolled back, a guard that held the
twin back), appended and fsynced as it happens. The telemetry log keeps what the robot sent; this keeps what the
twin sent and why, so that the two together rebuild the history (``history --rebuild``).

The first line is this program's header; a file at that path that does not carry it is refused, untouched.
"""

from __future__ import annotations

import json
import logging
import os
import threading

from lf_common.files import GENERATOR, ends_with_newline, json_safe, jsonl_is_ours
from twin.errors import TwinError

log = logging.getLogger(__name__)

ACTIONS_KIND = "live actions"
ACTIONS_LIMIT = 64 * 2**20  # [bytes] read back at most


def actions_path(log_path: str) -> str:
    return f"{log_path}.actions"


def check_journal(path: str) -> None:
    """The journal can be appended to: none yet, or one of ours."""
    if os.path.lexists(path) and not (os.path.isfile(path) and not os.path.islink(path) and jsonl_is_ours(path)):
        raise TwinError(f"{path}: exists and was not written by {GENERATOR} (the live actions of a telemetry log); "
                        "it is left as it is: move it away or choose another --log")


class Journal:
    """Append-only actions, one JSON object a line; thread-safe."""

    def __init__(self, path: str, log_name: str):
        check_journal(path)
        self.path = path
        self._lock = threading.Lock()
        self.lines = _count_lines(path)  # the next record's index: its line in the file (the header is line 0)
        try:
            self.file = open(path, "ab", buffering=0)
            if self.file.tell() == 0:
                self.file.write(_line({"generator": GENERATOR, "kind": ACTIONS_KIND, "log": log_name}))
                self.lines = 1
            elif not ends_with_newline(path):
                self.file.write(b"\n")  # a line torn by a crash: ended, so the next one stands alone
                self.lines += 1
        except OSError as e:
            raise TwinError(f"{path}: cannot write the live actions ({e.strerror or e})") from None

    def write(self, action: dict) -> int:
        """Append one record; its index (line number)."""
        with self._lock:
            index = self.lines
            try:
                self.file.write(_line(action))
                os.fsync(self.file.fileno())
                self.lines += 1
            except OSError as e:  # the telemetry log is the record; this one is reported and carried on without
                log.warning("%s: cannot append an action (%s)", self.path, e.strerror or e)
            return index

    def close(self) -> None:
        self.file.close()


def _line(doc: dict) -> bytes:
    return (json.dumps(json_safe(doc), separators=(",", ":"), default=str) + "\n").encode()


def _count_lines(path: str) -> int:
    try:
        with open(path, "rb") as f:
            return sum(chunk.count(b"\n") for chunk in iter(lambda: f.read(1 << 16), b""))
    except FileNotFoundError:
        return 0



def read_journal(path: str) -> list[tuple[int, dict]]:
    """(line, record) for each record of a journal (none without one); damaged lines (a torn last line) are
    skipped with a warning."""
    if not os.path.isfile(path):
        return []
    check_journal(path)
    out, bad = [], 0
    with open(path, "rb") as f:
        for index, raw in enumerate(f.read(ACTIONS_LIMIT).split(b"\n")):
            if index == 0:
                continue
            try:
                doc = json.loads(raw)
            except ValueError:
                bad += bool(raw.strip())
                continue
            if isinstance(doc, dict):
                out.append((index, doc))
    if bad:
        log.warning("%s: %d damaged lines skipped", path, bad)
    return out
