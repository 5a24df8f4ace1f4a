"""What the twin did beside the robot, kept beside the telemetry log as ``<log>.actions``: one JSON line per action
(an alignment, a re-tuning, a command sent, its answer, a change confirmed or rolled back, a guard that held the
twin back), appended and fsynced as it happens. The telemetry log keeps what the robot sent; this keeps what the
twin sent and why, so that the two together rebuild the history (``history --rebuild``).

The first line is this program's header; a file at that path that does not carry it is refused, untouched. It is
created whole (header in one step) or not at all, so a full disk leaves nothing that blocks the next run.

**Whose journal it is.** The header names its log and carries the log's id (``log_id``, random, made with the
journal), and each lap record carries the lap's digest
(:func:`lap_digest`, from the robot's own data: its samples, lap time, failure, id, gains). ``history --rebuild``
takes a journal only for a log whose laps have those digests (:func:`check_belongs`), whatever the files are
called; a copy of a log and its journal is the same log (the same id, the same digests), so its rows replace the
original's instead of doubling them.
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import threading
import uuid

import numpy as np

from lf_common.appended import create_whole, ends_with_newline
from lf_common.files import GENERATOR, json_safe, jsonl_is_ours
from twin.errors import TwinError
from twin.telemetry.laps import RobotLap

log = logging.getLogger(__name__)

ACTIONS_KIND = "live actions"
ACTIONS_LIMIT = 64 * 2**20  # [bytes] read back at most
CONTENT_ID_BYTES = 4096  # a log without an id of its own is known by its first bytes


def actions_path(log_path: str) -> str:
    return f"{log_path}.actions"


def check_journal(path: str) -> None:
    """The journal can be appended to: none yet, or one of ours."""
    if os.path.lexists(path) and not (os.path.isfile(path) and not os.path.islink(path) and jsonl_is_ours(path)):
        raise TwinError(f"{path}: exists and was not written by {GENERATOR} (the live actions of a telemetry log); "
                        "it is left as it is: move it away or choose another --log")


def content_id(log_path: str) -> str:
    """The id of a log that has none recorded: the SHA-256 of its first :data:`CONTENT_ID_BYTES` (a copy has the
    same)."""
    try:
        with open(log_path, "rb") as f:
            head = f.read(CONTENT_ID_BYTES)
    except OSError:
        head = b""
    return "sha256-" + hashlib.sha256(head).hexdigest()[:32]


def lap_digest(lap: RobotLap) -> str:
    """A lap's identity from what the robot sent of it (not the twin's judgement of it), the same whether read live
    or from the log."""
    h = hashlib.sha256(repr((lap.index, lap.robot, lap.gains_seq, lap.lap_time_s, lap.failure, lap.sensors)).encode())
    for a in (lap.t, lap.pos, lap.wl, lap.wr):
        h.update(np.ascontiguousarray(a, dtype="<f8").tobytes())
    return h.hexdigest()[:24]


def read_header(path: str) -> dict:
    """A journal's header (``{}`` without one)."""
    try:
        with open(path, "rb") as f:
            head = json.loads(f.readline(2**16))
    except (OSError, ValueError):
        return {}
    return head if isinstance(head, dict) else {}


def log_id(log_path: str) -> str:
    """The id of a log's rows in the history: its journal's ``log_id``, else (no journal, or one written before
    journals had ids) :func:`content_id`."""
    return read_header(actions_path(log_path)).get("log_id") or content_id(log_path)


def check_belongs(journal_path: str, records: list[tuple[int, dict]], laps: list[RobotLap], log_path: str) -> None:
    """The journal is this log's: every lap it journaled with a digest that the log holds has that digest, and at
    least one is there; a journal with no such lap (none yet, or one written before laps had digests) must name
    the log. Raises TwinError, naming the journal and the first lap or the name that differs."""
    digests = {lap.index: lap_digest(lap) for lap in laps}
    journaled = [(r["lap"], r["digest"]) for _, r in records if r.get("kind") == "lap" and r.get("digest")]
    refusal = "it is left as it is: rebuild each log with its own journal"
    for i, d in journaled:
        if i in digests and digests[i] != d:
            raise TwinError(f"{journal_path}: belongs to another log: its lap {i} is not lap {i} of {log_path}; {refusal}")
    if journaled and not any(i in digests for i, _ in journaled):
        raise TwinError(f"{journal_path}: belongs to another log: none of its {len(journaled)} laps is in {log_path}; "
                        f"{refusal}")
    named = read_header(journal_path).get("log")
    if not journaled and named not in (None, os.path.basename(log_path)):
        raise TwinError(f"{journal_path}: is the journal of {named}, not of {os.path.basename(log_path)}, and has no "
                        f"lap to tell them apart by; {refusal}")


class Journal:
    """Append-only actions, one JSON object a line; thread-safe. ``log_id``: the log's id (see the module
    docstring)."""

    def __init__(self, path: str, log_name: str):
        check_journal(path)
        self.path = path
        self._lock = threading.Lock()
        try:
            if not os.path.exists(path):
                create_whole(path, _line({"generator": GENERATOR, "kind": ACTIONS_KIND, "log": log_name,
                                          "log_id": uuid.uuid4().hex}))
            self.log_id = log_id(path.removesuffix(".actions"))
            self.lines = _count_lines(path)  # the next record's index: its line in the file (the header is line 0)
            self.file = open(path, "ab", buffering=0)
            if not ends_with_newline(path):
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
