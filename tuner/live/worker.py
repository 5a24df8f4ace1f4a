"""The decision thread of ``live --act``: the reader hands over each line as it arrives (logged already) and goes
on reading, while this thread feeds them, in order, to the live twin, which may take seconds between two laps
(an alignment, a re-tuning). Each record keeps the time it arrived, against which answer deadlines are judged."""

from __future__ import annotations

import logging
import queue
import threading
import time
from typing import Callable

from tuner.live.live_twin import LiveTwin

log = logging.getLogger(__name__)

IDLE_S = 0.1  # [s] with nothing to do, the twin is told so this often (answer deadlines)


class Worker:
    """Feeds ``live`` from a queue, in a thread of its own, until :meth:`finish`. ``stop()`` true: what is still
    queued is not fed (it is in the log; a restart replays it)."""

    def __init__(self, live: LiveTwin, stop: Callable[[], bool]):
        self.live, self.stop = live, stop
        self.queue: queue.Queue = queue.Queue()
        self.error: BaseException | None = None
        self.thread = threading.Thread(target=self._run, name="live-act", daemon=True)
        self.thread.start()

    def put(self, rec) -> None:
        self.queue.put((rec, time.monotonic()))

    def _run(self) -> None:
        while True:
            try:
                item = self.queue.get(timeout=IDLE_S)
            except queue.Empty:
                item = (None, time.monotonic())
            if item is StopIteration:
                return
            rec, arrival = item
            if rec is not None and self.stop():
                continue
            try:
                self.live.feed(rec, arrival=arrival)
            except BaseException as e:  # reported by finish(), in the main thread
                self.error = e
                log.exception("the live twin failed")
                return

    def finish(self) -> None:
        """Feed what is queued (unless stopped), then end; a failure in the thread is raised here."""
        self.queue.put(StopIteration)
        while self.thread.is_alive():
            self.thread.join(0.2)
        if self.error is not None:
            raise self.error
