"""What a twin keeps between runs of laps, each valid for one build of its world (``DigitalTwin.rebuilds``).

Both are keyed by the build count, not ``id(model)``: ids are reused after a rebuild.
"""

from __future__ import annotations

import mujoco
import mujoco.batch


class BatchCache:
    """The twin's ``mujoco.batch`` for one (build, size, threads): making one costs ~10 ms, a lap ~200 ms. Only the
    latest is kept, since a rebuilt model makes the old one useless."""

    def __init__(self) -> None:
        self._key: tuple | None = None
        self._held: tuple | None = None  # (model, batch): the model lives as long as its batch

    def get(self, build: int, model: mujoco.MjModel, nsim: int, nthread: int) -> mujoco.batch.Batch:
        key = (build, nsim, nthread)
        if key != self._key:
            self._key, self._held = key, (model, mujoco.batch.Batch(model, nsim=nsim, nthread=nthread))
        return self._held[1]


class CalibrationCache:
    """The calibration turns simulated on one build: {key: (min, max)}, so
    laps that differ only in gains turn once (bit-identical to turning again)."""

    def __init__(self) -> None:
        self._build: int | None = None
        self._done: dict[tuple, tuple] = {}

    def of(self, build: int) -> dict[tuple, tuple]:
        """The turns made on ``build``; a rebuilt robot or track calibrates anew."""
        if build != self._build:
            self._build, self._done = build, {}
        return self._done
