"""The twin's races of a robot's gains, run ahead in a background process while the robot laps.

A forecast (:func:`tuner.history.forecast_failure`) rests on races of the gains in force on the twin, one per part
that wears: about 150 laps each, tens of seconds on 2 cores, where a forecast is to be ready within a lap; after
those, the rows a forecast of both at once asks for (:func:`tuner.history.two_causes.race_plane`); then each part's
race on more noise seeds a value, which forecasts from the robot's ``SEEDS_LATER_FROM``-th timed lap read
(:func:`tuner.history.forecast.edge_seeds`). The races depend on the twin and the gains, not on the robot's laps
(:func:`tuner.history.forecast.race_range`), so ``live`` starts them when it starts, in a process of its own at a
lower priority than its own work, and ``history``'s forecasts read them from the cache folder
(:mod:`tuner.history.twin_edge`). A robot needs ``MIN_TIMED_LAPS`` laps before a forecast: at real time the first
races are done by then, and the last before its ``SEEDS_LATER_FROM``-th.

  python -m tuner.history.race_ahead   (reads the twin, the gains and the seed, pickled, on stdin: for ``live``)
"""

from __future__ import annotations

import os
import pickle
import signal
import subprocess
import sys
import tempfile
import threading
import time

NICE = 10  # the races yield to live's own work (the link, the comparison, re-alignment)
STOP_WAIT_S = 30.0  # a stopped race ends after the batch of laps it is in (about 60 laps), or is killed


class RaceAhead:
    """The background process racing ``gains`` on ``twin`` (unbuilt, as :meth:`DigitalTwin.clone` gives it: it goes
    to the process pickled), seed ``seed`` (``history``'s default, 0)."""

    def __init__(self, twin, gains: dict, seed: int = 0):
        payload = pickle.dumps((twin, dict(gains), int(seed)))  # before the process: a twin that cannot go, no process
        self.started, self.ended = time.monotonic(), None
        self.err = tempfile.TemporaryFile()  # not a pipe: a chatty child never blocks on it
        self.proc = subprocess.Popen([sys.executable, "-m", "tuner.history.race_ahead"], stdin=subprocess.PIPE,
                                     stdout=subprocess.DEVNULL, stderr=self.err)
        try:
            self.proc.stdin.write(payload)
            self.proc.stdin.close()
        except OSError:  # it died at once: its status says so
            pass
        threading.Thread(target=self._wait, name="race-ahead", daemon=True).start()

    def _wait(self) -> None:
        self.proc.wait()
        self.ended = time.monotonic()

    def stop(self, wait_s: float = 0.0) -> dict:
        """What became of the races: {"state": ``done``, ``failed: …`` or, if still running after ``wait_s``,
        ``stopped unfinished`` (the first forecast then races the twin itself), "wall_s": how long they ran}."""
        try:
            self.proc.wait(timeout=wait_s)
        except subprocess.TimeoutExpired:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=STOP_WAIT_S)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
            self.err.close()
            return {"state": "stopped unfinished (the first forecast on these gains races the twin itself)",
                    "wall_s": round(time.monotonic() - self.started, 2)}
        self.err.seek(0)
        err = self.err.read().decode(errors="replace").strip().splitlines()
        self.err.close()
        state = "done" if self.proc.returncode == 0 else f"failed: {err[-1] if err else f'exit {self.proc.returncode}'}"
        return {"state": state, "wall_s": round((self.ended or time.monotonic()) - self.started, 2)}


class RacesAhead:
    """The races ``live`` runs ahead: of the gains in force when it starts and, with ``--act``, of each set that
    comes into force after (the one before, still running, is stopped: the forecast is of the gains in force),
    always on the twin as built (an alignment's value in it would be another race than ``history``'s)."""

    def __init__(self, twin, gains: dict, seed: int = 0):
        self.twin, self.seed = twin.clone(), seed
        self.gains = {a: float(v) for a, v in gains.items()}
        self.current = RaceAhead(self.twin, self.gains, seed)
        self.done: list[dict] = []

    def follow(self, gains: dict) -> None:
        """New gains in force (those not named keep their value)."""
        new = {a: float(gains.get(a, v)) for a, v in self.gains.items()}
        if new == self.gains:
            return
        self.done.append({"gains": self.gains, **self.current.stop()})
        self.gains = new
        self.current = RaceAhead(self.twin, new, self.seed)

    def stop(self, wait_s: float = 0.0) -> dict:
        """The last races' {"state", "wall_s", "gains"}, with those of earlier gains (``earlier``)."""
        return {**self.current.stop(wait_s), "gains": self.gains, "earlier": self.done}


def main() -> int:
    os.nice(NICE)
    # stopped: leave as an exception does, so a race half written into the cache is removed (between the twin's
    # batches of laps: STOP_WAIT_S)
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))
    twin, gains, seed = pickle.load(sys.stdin.buffer)
    from tuner.history.forecast import SEEDS_LATER, race_ahead
    from tuner.history.two_causes import race_ahead_both

    race_ahead(twin, gains, seed)
    race_ahead_both(twin, gains, seed)  # then the rows a forecast of both at once asks for
    race_ahead(twin, gains, seed, seeds=SEEDS_LATER)  # then each part's on more seeds, for forecasts later in life
    return 0


if __name__ == "__main__":
    sys.exit(main())
