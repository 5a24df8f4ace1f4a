"""The twin as the model of a sensitivity analysis: a sample of parameter values → one lap each, in batches.

Outputs of each lap (:data:`OUTPUTS`):

* ``completed``: 1 for a completed lap, 0 for a failed one: whether the lap completes is its own output;
* ``lap_time_s``: the lap time;
* ``energy_j``: the motors' electrical energy drawn in the lap;
* ``max_cross_track_m``: the largest distance of the centre of rotation from the line.

A failed lap has no lap time, and its energy and cross-track error stop where it failed (a failed calibration turn:
0 J and 0 m), so these three are NaN for a failed lap, never a value written in: ``completed`` says what makes laps
fail (Sobol' indices of a 0/1 output: shares of the variance of failing), and the analysis measures the other three
over the laps that complete with a method fit for an output some runs do not give (Morris over the steps whose two
laps complete, Borgonovo's δ over the completed laps: :mod:`tuner.sensitivity.analysis`). (Writing in the completed
laps' median would decompose the variance of a made-up function, flattened wherever laps fail; the tuner's
penalised cost would make one failed lap in ten dominate every variance.)

Every lap runs with the same noise seed (common random numbers): the outputs differ by the parameters alone. Laps
run in batches of at most :data:`CHUNK_LAPS`: each lap with its own motor and friction values holds its own copy of
the model (~17 MB with the default track's texture), so a batch holds at most :data:`MEMORY_BUDGET` bytes of them
(fewer laps for a larger texture); each lap is bit-identical to running it alone, so neither the batch size nor the
thread count changes a result.
"""

from __future__ import annotations

import dataclasses
import math
import time
from typing import Callable, Mapping, Sequence

import numpy as np

from twin.core.closed_loop import MAX_LAPS, run_laps
from twin.core.digital_twin import DigitalTwin
from twin.core.lap import LapResult
from tuner.search.space import TunerError
from tuner.sensitivity.analysis import Analysis, analyse
from tuner.sensitivity.ranges import Factor, default_factors

OUTPUTS = ("lap_time_s", "completed", "energy_j", "max_cross_track_m")
CHUNK_LAPS = 64
MEMORY_BUDGET = 1.5e9  # [bytes] of model copies in one batch
SAMPLES = 256  # Saltelli's N of the default analysis
TRAJECTORIES = 12  # Morris trajectories of the default analysis
MAX_SOBOL = 8  # factors that get Sobol' indices at most


def lap_outputs(r: LapResult) -> dict[str, float]:
    """The four outputs of one lap as run: NaN where a failed lap has no value."""
    if not r.completed:
        return {"lap_time_s": math.nan, "completed": 0.0, "energy_j": math.nan, "max_cross_track_m": math.nan}
    return {"lap_time_s": float(r.lap_time_s), "completed": 1.0, "energy_j": float(r.energy_j),
            "max_cross_track_m": float(r.max_cross_track_m)}


class LapModel:
    """``model(addresses, X)`` → the outputs of one lap per row of X, the rest of the twin as it is.

    Args:
      twin: the robot on its track; not changed.
      seed: every lap's noise seed.
      nthread: threads of each batch (0: all cores); results do not depend on it.
      on_laps: told how many laps just finished, after each chunk.
    """

    def __init__(self, twin: DigitalTwin, seed: int = 0, nthread: int = 0,
                 on_laps: Callable[[int], None] | None = None):
        self.twin, self.seed, self.nthread, self.on_laps = twin, seed, nthread, on_laps
        self.laps = 0
        self.failures: dict[str, int] = {}

    def __call__(self, addresses: Sequence[str], X: np.ndarray) -> dict[str, np.ndarray]:
        rows: list[dict[str, float]] = []
        chunk = min(CHUNK_LAPS, max(8, int(MEMORY_BUDGET // max(self.twin.model().nbuffer, 1))))
        for start in range(0, len(X), chunk):
            variants = [{a: float(v) for a, v in zip(addresses, x)} for x in X[start:start + chunk]]
            for r in run_laps(self.twin, variants, seed=self.seed, nthread=self.nthread, keep_traces=False):
                rows.append(lap_outputs(r))
                if not r.completed:
                    self.failures[r.failure] = self.failures.get(r.failure, 0) + 1
            self.laps += len(variants)
            if self.on_laps:
                self.on_laps(len(variants))
        return {o: np.array([row[o] for row in rows]) for o in OUTPUTS}


PROBE_LAPS = 4  # laps timed to say how long a refused analysis would take


def planned_laps(factors: int, samples: int, trajectories: int = TRAJECTORIES, max_sobol: int = MAX_SOBOL) -> int:
    """Laps of an analysis at most: Morris' r (k + 1), then Saltelli's N (k' + 2) for the k' ≤ max_sobol factors
    that matter."""
    return trajectories * (factors + 1) + samples * (min(factors, max_sobol) + 2)


def _duration(seconds: float) -> str:
    if seconds < 120:
        return f"{seconds:.0f} s"
    if seconds < 2 * 3600:
        return f"{seconds / 60:.0f} min"
    if seconds < 2 * 86400:
        return f"{seconds / 3600:.1f} h"
    return f"{seconds / 86400:.1f} days"


def check_size(twin: DigitalTwin, factors: Sequence[Factor], samples: int, trajectories: int = TRAJECTORIES,
               max_sobol: int = MAX_SOBOL, nthread: int = 0) -> int:
    """The analysis' laps at most, if within the :data:`twin.core.closed_loop.MAX_LAPS` a sweep may run too.

    Raises:
      TunerError: more laps than that: how many, and how long they would take on this machine (a few laps of this
        twin, timed).
    """
    laps = planned_laps(len(factors), samples, trajectories, max_sobol)
    if laps <= MAX_LAPS:
        return laps
    wall = time.perf_counter()
    run_laps(twin, [{}] * PROBE_LAPS, seed=list(range(PROBE_LAPS)), nthread=nthread, keep_traces=False)
    per_lap = (time.perf_counter() - wall) / PROBE_LAPS
    fits = [n for n in (2**i for i in range(3, 31)) if planned_laps(len(factors), n, trajectories, max_sobol) <= MAX_LAPS]
    advice = f"use --samples {fits[-1]} or fewer" if fits else "vary fewer parameters (--param)"
    raise TunerError(f"--samples {samples}: the analysis of {len(factors)} parameters would run up to {laps:,} laps, "
                     f"about {_duration(laps * per_lap)} on this machine ({per_lap * 1000:.0f} ms a lap, timed): more "
                     f"than the {MAX_LAPS:,} laps a command may run (sweep's limit too); {advice}")


def learn(twin: DigitalTwin, factors: Sequence[Factor] | None = None, samples: int = SAMPLES,
          trajectories: int = TRAJECTORIES, seed: int = 0, nthread: int = 0, max_sobol: int = MAX_SOBOL,
          on_stage: Callable[[str, int], None] | None = None, on_laps: Callable[[int], None] | None = None) -> Analysis:
    """Measure what governs the lap: :func:`tuner.sensitivity.analysis.analyse` over the twin's laps.

    Raises:
      TunerError: more laps than a sweep may run (:func:`check_size`).

    Args:
      factors: what to vary (default: :func:`tuner.sensitivity.ranges.default_factors`).
      samples, trajectories, max_sobol: the analysis' sizes (see :func:`analyse`).
      seed: the laps' noise seed and the analysis' sampling seed.
      nthread: threads of each batch; results do not depend on it.

    ``extra`` of the result: laps, wall and CPU time, the completion rate, failures by kind, the parameters left
    out (default factors only) and the twin's values of the varied parameters.
    """
    left_out: Mapping[str, str] = {}
    if factors is None:
        factors, left_out = default_factors(twin.space)
    twin.model()  # built before the clock starts: the build is not the analysis
    check_size(twin, factors, samples, trajectories, max_sobol, nthread)
    model = LapModel(twin, seed, nthread, on_laps)
    wall, cpu = time.perf_counter(), time.process_time()
    result = analyse(factors, model, OUTPUTS, samples, trajectories, seed, max_sobol, on_stage)
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    failed = sum(model.failures.values())
    extra = {"laps": model.laps, "wall_s": wall, "cpu_s": cpu, "completion_rate": 1 - failed / model.laps,
             "failures": dict(sorted(model.failures.items())), "left_out": dict(left_out),
             "nominal": {f.address: twin.space.get(f.address) for f in factors}, "track": twin.track.name,
             "laps_per_s": model.laps / wall if wall > 0 else math.inf}
    notes = result.notes
    if failed:
        kinds = ", ".join(f"{n} {k}" for k, n in extra["failures"].items())
        notes += (f"{failed} of {model.laps} laps failed ({kinds}): completed says what makes them fail; the lap time, "
                  "energy and cross-track error are analysed over the laps that completed",)
    return dataclasses.replace(result, extra=extra, notes=notes)
