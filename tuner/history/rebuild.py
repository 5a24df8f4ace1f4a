"""``history --rebuild``: a telemetry log (and the journal beside it) back into the history database, in one
transaction: every row that came from that log is deleted, then written again from the files, so rebuilding twice
gives the same database, and a database that missed part of a run (it was down) gets all of it.

Rows are keyed by the log's id, not its path (:mod:`tuner.history.journal`): rebuilding a copy of a log replaces
its rows (the copy's content, as it was when copied) rather than adding a second life. A journal that is not the
log's is refused, and so is a log that ``live`` is still writing (its lock): a rebuild of a log is of all of it."""

from __future__ import annotations

import dataclasses
import os

from tuner.history.ingest import LogIngest, log_key
from tuner.history.journal import actions_path, check_belongs, log_id, read_journal
from tuner.history.store import History
from twin.link import log_lines, unlocked_for_reading
from twin.telemetry.laps import LapAssembler, RobotLap
from twin.telemetry.wire import WireError, decode


def log_laps(path: str) -> list[RobotLap]:
    """The robot laps of a telemetry log, numbered as the live twin numbered them."""
    assembler, out = LapAssembler(), []
    for raw in log_lines(path):
        if raw is None:
            continue
        try:
            lap = assembler.feed(decode(raw))
        except WireError:
            continue
        if lap is not None:
            out.append(lap)
    return out


@dataclasses.dataclass
class LogContent:
    """A log read for a rebuild: its laps, its journal's records (checked to be its own), its id."""
    path: str
    laps: list[RobotLap]
    journal: list[tuple[int, dict]]
    identity: str


def read_log(log_path: str) -> LogContent:
    """Read a log and its journal for a rebuild, under a shared lock: a log that live is writing, or a journal
    that is not the log's, is refused (TwinError, one line)."""
    log_path = os.path.abspath(log_path)
    with unlocked_for_reading(log_path, "rebuild it once live has stopped"):
        laps = log_laps(log_path)
        journal = read_journal(actions_path(log_path))
        check_belongs(actions_path(log_path), journal, laps, log_path)
        return LogContent(log_path, laps, journal, log_id(log_path))


def rebuild_log(history: History, log: str | LogContent) -> dict:
    """Rebuild the rows of one log (a path, or one already read); what was done (counts)."""
    content = log if isinstance(log, LogContent) else read_log(log)
    log_path, laps, journal = content.path, content.laps, content.journal
    ingest = LogIngest(history, log_path, content.identity)
    pending = list(laps)
    with history.begin() as c:
        forgotten = history.forget_log(c, log_key(content.identity), log_path)

        def flush(upto: int) -> None:
            while pending and pending[0].index < upto:
                ingest.lap(c, pending.pop(0), None)

        by_index = {lap.index: lap for lap in laps}
        for index, record in journal:
            kind = record.get("kind")
            if kind == "session":
                flush(int(record.get("lap") or 0))
                ingest.session(record, index)
            elif kind == "lap":
                i = record.get("lap")
                flush(i if isinstance(i, int) else 0)
                if pending and pending[0].index == i:
                    ingest.lap(c, pending.pop(0), record)
                elif i in by_index:  # a lap journaled twice (a restart mid-write): the last wins
                    ingest.lap(c, by_index[i], record)
            else:
                ingest.journal_record(c, record, index)
        flush(len(laps) + 1)
    return {"log": log_path, "laps": len(laps), "journal_records": len(journal), "runs_replaced": forgotten}
