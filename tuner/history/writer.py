"""The live twin's history, written as it goes without ever holding it up: rows are written by a thread of their
own, one transaction per record; a database that cannot be reached or written is reported once, in one line, and
left alone for the rest of the run (the log and the journal beside it still hold everything:
``history --rebuild`` fills the database in later)."""

from __future__ import annotations

import logging
import queue
import threading
from typing import Callable

from tuner.history.ingest import LogIngest
from tuner.history.store import History, HistoryError, display

log = logging.getLogger(__name__)

CLOSE_TIMEOUT_S = 30.0  # [s] at most spent writing what is queued when the run ends


class HistoryWriter:
    """Records of one live session on ``log_path`` into the database at ``url``.

    Args:
      url: the database.
      log_path: the telemetry log whose rows these are.
      say: where the one warning about a database that cannot be used goes (it is given the text after
        ``warning: ``).
      log_id: the log's id (its journal's: :attr:`tuner.history.journal.Journal.log_id`).
    """

    def __init__(self, url: str, log_path: str, say: Callable[[str], None], log_id: str):
        self.url, self.say, self.failed = url, say, None
        self.queue: queue.Queue = queue.Queue()
        self.history, self.ingest = None, None
        self.written = 0
        self.thread = threading.Thread(target=self._run, args=(log_path, log_id), name="history", daemon=True)
        self.thread.start()

    def _fail(self, e: HistoryError) -> None:
        self.failed = str(e)
        self.say(f"{e}; the run goes on without it (fill it in later: history --rebuild --log LOG "
                 f"--db {display(self.url)})")

    def _run(self, log_path: str, log_id: str) -> None:
        try:
            self.history = History(self.url)
            self.ingest = LogIngest(self.history, log_path, log_id)
        except HistoryError as e:
            self._fail(e)
        while True:
            item = self.queue.get()
            if item is None:
                break
            if self.failed is not None:
                continue
            method, args = item
            try:
                if method == "session":
                    self.ingest.session(*args)
                else:
                    with self.history.begin() as c:
                        getattr(self.ingest, method)(c, *args)
                self.written += 1
            except HistoryError as e:
                self._fail(e)
            except Exception as e:  # a row the database refuses: reported like an unreachable database
                self._fail(HistoryError(f"--db {display(self.url)}: cannot write the history ({e})"))
        if self.history is not None:
            self.history.close()

    def journal_record(self, record: dict, index: int) -> None:
        self.queue.put(("session", (record, index)) if record.get("kind") == "session"
                       else ("journal_record", (record, index)))

    def lap(self, robot_lap, twin_side: dict | None) -> None:
        self.queue.put(("lap", (robot_lap, twin_side)))

    def close(self) -> None:
        self.queue.put(None)
        self.thread.join(CLOSE_TIMEOUT_S)
        if self.thread.is_alive():
            log.warning("history: still writing after %g s; left to finish in the background", CLOSE_TIMEOUT_S)
