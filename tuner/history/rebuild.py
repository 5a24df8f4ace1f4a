"""``history --rebuild``: a telemetry log (and the journal beside it) back into the history database, in one
transaction: every row that came from that log is deleted, then written again from the files, so rebuilding twice
gives the same database, and a database that missed part of a run (it was down) gets all of it."""

from __future__ import annotations

import os

from tuner.history.ingest import LogIngest
from tuner.history.journal import actions_path, read_journal
from tuner.history.store import History
from twin.link import log_lines
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


def rebuild_log(history: History, log_path: str) -> dict:
    """Rebuild the rows of one log; what was done (counts)."""
    log_path = os.path.abspath(log_path)
    laps = log_laps(log_path)
    journal = read_journal(actions_path(log_path))
    ingest = LogIngest(history, log_path)
    pending = list(laps)
    with history.begin() as c:
        forgotten = history.forget_log(c, log_path)

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
