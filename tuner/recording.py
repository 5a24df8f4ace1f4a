"""rerun recording of a tuning run: each iteration's parameters and lap time, and the best lap's path."""

from __future__ import annotations

import os
from typing import Sequence

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from twin.digital_twin import DigitalTwin
from twin.errors import TwinError
from twin.lap import LapResult
from twin.recording import APP_ID, log_lap, log_track
from tuner.gradient import Iteration
from tuner.space import SearchSpace


def save_tuning(out_path: str, twin: DigitalTwin, space: SearchSpace, iterations: Sequence[Iteration],
                best_lap: LapResult) -> str:
    """Write the tuning run to an .rrd file atomically; returns its path."""
    out_path = os.path.abspath(out_path)
    tmp = f"{out_path}.{os.getpid()}.tmp"
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
    rec = rr.RecordingStream(APP_ID)
    try:
        rec.save(tmp, default_blueprint=blueprint)
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
        rec.flush()
        rec.disconnect()
        os.replace(tmp, out_path)
    except OSError as e:
        raise TwinError(f"{out_path}: cannot write the recording ({e.strerror or e})") from None
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)
    return out_path
