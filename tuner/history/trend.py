"""The trend of an aligned parameter over a robot's laps: a straight line through its alignments, with the slope's
standard error from both the scatter of the points and the width of each alignment's consistent interval (a value
the lap time pins only to a range weighs less)."""

from __future__ import annotations

import dataclasses
import math
from typing import Iterable

import numpy as np

MIN_POINTS = 2


@dataclasses.dataclass(frozen=True)
class Trend:
    address: str
    slope: float  # change per lap
    intercept: float  # value at lap 0
    slope_se: float  # standard error of the slope (per lap)
    points: int
    first_lap: int
    last_lap: int

    def at(self, lap: float) -> float:
        return self.intercept + self.slope * lap

    def summary(self) -> dict:
        return dataclasses.asdict(self)


def measured(a: dict) -> bool:
    """Is this alignment evidence: explained, with a value, and measured (not the live twin's estimate from failed
    laps, ``from_failures`` live or ``estimated`` in the history)?"""
    return bool(a.get("explained")) and a.get("value") is not None and not (a.get("from_failures")
                                                                           or a.get("estimated"))


def _points(alignments: Iterable[dict], address: str) -> list[tuple[float, float, float]]:
    """(lap, value, σ) of each explained alignment of ``address``; σ from its consistent interval (a 95 % range
    is ±2σ), at least 0.1 % of the value."""
    out = []
    for a in alignments:
        if a.get("address", address) != address or not measured(a):
            continue
        v = float(a["value"])
        interval = a.get("interval")
        width = abs(interval[1] - interval[0]) if interval else 0.0
        out.append((float(a["lap"]), v, max(width / 4, 1e-3 * abs(v), 1e-9)))
    return out


def trend_of(alignments: Iterable[dict], address: str, last: int | None = None) -> Trend | None:
    """The line through the alignments of ``address`` (the ``last`` of them, all by default); None with fewer than
    two at different laps."""
    pts = _points(alignments, address)
    if last is not None:
        pts = pts[-last:]
    if len(pts) < MIN_POINTS or len({p[0] for p in pts}) < MIN_POINTS:
        return None
    x, y, s = (np.array(c) for c in zip(*pts))
    w = 1 / s ** 2
    xm = float(np.sum(w * x) / np.sum(w))
    sxx = float(np.sum(w * (x - xm) ** 2))
    slope = float(np.sum(w * (x - xm) * (y - np.sum(w * y) / np.sum(w))) / sxx)
    intercept = float(np.sum(w * y) / np.sum(w) - slope * xm)
    se = math.sqrt(1 / sxx)  # from the intervals alone
    if len(pts) > 2:  # and from the scatter, when there is any to see
        resid = y - (intercept + slope * x)
        scatter = float(np.sum(w * resid ** 2) / (len(pts) - 2))
        se = max(se, math.sqrt(scatter / sxx))
    return Trend(address, slope, intercept, se, len(pts), int(x.min()), int(x.max()))
