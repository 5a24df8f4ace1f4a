"""rerun recording of a tuning run: each iteration's parameters and lap time, and the best lap's path."""

from __future__ import annotations

import os
from typing import Sequence

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from twin.digital_twin import DigitalTwin
from twin.lap import LapResult
from twin.recording import log_lap, log_track, recording_file
from tuner.gradient import Iteration
from tuner.space import SearchSpace


def save_tuning(out_path: str, twin: DigitalTwin, space: SearchSpace, iterations: Sequence[Iteration],
                best_lap: LapResult) -> str:
    """Write the tuning run to an .rrd file atomically; returns its path."""
    blueprint = rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(
                rrb.TimeSeriesView(name="lap time [s]", origin="/tuning/lap_time"),
                rrb.TimeSeriesView(name="parameters (fraction of their bounds)", origin="/tuning/normalised"),
            ),
            rrb.Spatial2DView(name="best lap", origin="/track"),
        ),
        collapse_panels=True,
    )
    with recording_file(out_path, blueprint) as rec:
        k = np.array([it.k for it in iterations])
        index = [rr.TimeColumn("iteration", sequence=k)]
        rr.send_columns("tuning/lap_time", indexes=index, columns=rr.Scalars.columns(scalars=[it.cost for it in iterations]),
                        recording=rec)
        for i, a in enumerate(space.addresses):
            z = np.array([it.z[i] for it in iterations])
            rr.send_columns(f"tuning/normalised/{a}", indexes=index, columns=rr.Scalars.columns(scalars=z), recording=rec)
            x = space.from_unit(np.array([it.z for it in iterations]))[:, i]
            rr.send_columns(f"tuning/value/{a}", indexes=index, columns=rr.Scalars.columns(scalars=x), recording=rec)
        log_track(rec, twin.track, twin.texture)
        log_lap(rec, twin.track, twin.texture, best_lap, "best")
    return os.path.abspath(out_path)
