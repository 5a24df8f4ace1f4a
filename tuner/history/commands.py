"""Rows of the commands that run the twin alone (``lap``, ``tune``, ``align`` with ``--db``): one run each, under the
robot ``twin`` (kind twin), with its lap (energy and cross-track error included: the twin measures them) or its
alignment. Written in one transaction after the command's work; a database that cannot be used is reported in one
line by the caller and the command's result stands."""

from __future__ import annotations

import math
import os
import time
import uuid

from tuner.history import schema as s
from tuner.history.store import History
from twin.telemetry.wire import GAIN_ADDRESSES

TWIN = "twin"


def _run(c, command: str, settings: dict, result: dict) -> tuple[int, int, str]:
    now = time.time()
    robot_id = History.robot(c, TWIN, "twin", now)
    source = f"{command}:{uuid.uuid4().hex}"
    run_id = History.put(c, s.runs, source, robot_id=robot_id, command=command, log_path=None, started=now,
                         first_lap=0, settings=settings, result=result)
    return run_id, robot_id, source


def lap_row(c, run_id: int, robot_id: int, source: str, lap, gains: dict, values: dict) -> None:
    """One twin lap (a :class:`twin.core.lap.LapResult`)."""
    History.put(c, s.laps, f"{source}#lap0", run_id=run_id, robot_id=robot_id, lap=0, time=time.time(),
                completed=lap.completed, lap_time_s=lap.lap_time_s, failure=lap.failure, implausible=None,
                energy_j=lap.energy_j, xte_max_m=lap.max_cross_track_m, xte_mean_m=lap.mean_cross_track_m,
                gains_seq=None, gains=gains, twin_lap_time_s=lap.lap_time_s, discrepancy=None, values=values)


def record_lap(history: History, twin, lap, command: str = "lap", result: dict | None = None,
               gains: dict | None = None) -> str:
    """A lap of the twin (``lap``; ``tune``'s tuned lap, with the tuned ``gains``): its run and lap; the run's key."""
    gains = {**{a: twin.space.get(a) for a in GAIN_ADDRESSES}, **(gains or {})}
    values = {a: v for a, v in twin.space.values.items() if not a.startswith(("control.", "cad."))}
    with history.begin() as c:
        run_id, robot_id, source = _run(c, command, {"cwd": os.getcwd()}, result or lap.summary())
        lap_row(c, run_id, robot_id, source, lap, gains, values)
    return source


def record_alignment(history: History, alignment, before: float) -> str:
    """An alignment to a measured lap time (a :class:`tuner.align.lap_time.LapTimeAlignment`)."""
    lo, hi = alignment.consistent or (None, None)
    with history.begin() as c:
        run_id, robot_id, source = _run(c, "align", {"cwd": os.getcwd()},
                                        {"value": alignment.value, "explained": alignment.explained})
        History.put(c, s.alignments, f"{source}#align", run_id=run_id, robot_id=robot_id, lap=None, time=time.time(),
                    address=alignment.parameter, before=before, value=alignment.value, lo=lo, hi=hi,
                    explained=alignment.explained, identifiable=alignment.identifiable,
                    measured_lap_time_s=alignment.measured_lap_time_s, message=alignment.message, reason="align")
    return source


def record_fit(history: History, parameters, measured_lap_time_s: float | None) -> str:
    """A fit to a recorded run (``align --telemetry``): one alignment per parameter, with its 95 % interval."""
    with history.begin() as c:
        run_id, robot_id, source = _run(c, "align", {"cwd": os.getcwd()},
                                        {p.address: p.value for p in parameters})
        for p in parameters:
            lo, hi = p.ci95 if all(map(math.isfinite, p.ci95)) else (None, None)
            History.put(c, s.alignments, f"{source}#{p.address}", run_id=run_id, robot_id=robot_id, lap=None,
                        time=time.time(), address=p.address, before=None, value=p.value, lo=lo, hi=hi,
                        explained=True, identifiable=p.identifiable, measured_lap_time_s=measured_lap_time_s,
                        message=p.note, reason="align --telemetry")
    return source
