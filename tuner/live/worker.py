"""The decision thread of ``live --act``: the reader hands over each line as it arrives (logged already) and goes
on reading, while this thread feeds them, in order, to the live twin, which may take seconds between two laps
(an alignment, a re-tuning). Each record keeps the time it arrived, against which answer deadlines are judged.
While one record takes longer than :data:`twin.telemetry.wire.KEEPALIVE_S` (1 s), a second thread has the actor
send a keep-alive every second: a robot that waits for the twin (in lockstep) knows it is there."""

from __future__ import annotations

import logging
import queue
import threading
import time
from typing import Callable

from tuner.live.live_twin import LiveTwin
from twin.telemetry.wire import KEEPALIVE_S

log = logging.getLogger(__name__)

IDLE_S = 0.1  # [s] with nothing to do, the twin is told so this often (answer deadlines)


class Worker:
    """Feeds ``live`` from a queue, in a thread of its own, until :meth:`finish`. ``stop()`` true: what is still
    queued is not fed (it is in the log; a restart replays it)."""

    def __init__(self, live: LiveTwin, stop: Callable[[], bool]):
        self.live, self.stop = live, stop
        self.queue: queue.Queue = queue.Queue()
        self.error: BaseException | None = None
        self.busy_since: float | None = None  # when the record being fed began (None: waiting for one)
        self.done = threading.Event()
        self.thread = threading.Thread(target=self._run, name="live-act", daemon=True)
        self.ticker = threading.Thread(target=self._keep_alive, name="live-keep-alive", daemon=True)
        self.thread.start()
        self.ticker.start()

    def _keep_alive(self) -> None:
        last = 0.0
        while not self.done.wait(IDLE_S):
            since, now = self.busy_since, time.monotonic()
            if since is not None and now - max(since, last) >= KEEPALIVE_S and self.live.actor is not None:
                self.live.actor.keep_alive()
                last = now

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
            self.busy_since = time.monotonic()
            try:
                self.live.feed(rec, arrival=arrival)
            except BaseException as e:  # reported by finish(), in the main thread
                self.error = e
                log.exception("the live twin failed")
                return
            finally:
                self.busy_since = None

    def finish(self) -> None:
        """Feed what is queued (unless stopped), then end; a failure in the thread is raised here."""
        self.queue.put(StopIteration)
        while self.thread.is_alive():
            self.thread.join(0.2)
        self.done.set()
        self.ticker.join()
        if self.error is not None:
            raise self.error
