"""Two causes at once (grip and battery wearing together): the twin's failure edge and observation model over the
plane of two parameters, (u, w) = (the first cause's value, the second's), built from rows: the first cause raced
along its ladder (:mod:`tuner.history.twin_edge`) at a few values of the second. Between rows both lie on a cubic
across the nearest rows, and straight on beyond the outer rows, as the one-parameter models are along u.

The same interface as the one-parameter models (:class:`tuner.prognostics.evidence.FailureModel`,
:class:`tuner.prognostics.evidence.ObservationModel`), on values of shape (n, 2): the particle filter and the Monte
Carlo carry both causes' values, rates and shapes at once (:mod:`tuner.prognostics.particle_filter`).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from tuner.prognostics.evidence import FailureModel, ObservationModel, mahalanobis


def _weights(rows: np.ndarray, w: np.ndarray, smooth: bool = True) -> np.ndarray:
    """(n, rows): how much each row counts at each of the values ``w`` (n,) of the second cause. Between the outer
    rows: the cubic through the four nearest (Lagrange; fewer rows, fewer); a line between the two nearest was
    0.03 s of lap time off mid-way (three times a lap's scatter: lap time is convex in the battery's voltage),
    and the filter moved grip to make up for it. Beyond the outer rows, and with ``smooth`` False: the line
    through the two nearest (held at the outer row beyond it without ``smooth``)."""
    w = np.asarray(w, float)
    k, n = len(rows), len(w)
    i = np.clip(np.searchsorted(rows, w) - 1, 0, k - 2)
    t = (w - rows[i]) / (rows[i + 1] - rows[i])
    out = np.zeros((n, k))
    out[np.arange(n), i] = 1 - (t if smooth else np.clip(t, 0.0, 1.0))
    out[np.arange(n), i + 1] += t if smooth else np.clip(t, 0.0, 1.0)
    m = min(4, k)
    inside = (w >= rows[0]) & (w <= rows[-1])
    if smooth and m > 2 and inside.any():
        first = np.clip(i - (m - 2) // 2, 0, k - m)[inside]
        idx = first[:, None] + np.arange(m)
        x, at = rows[idx], w[inside][:, None]
        lagrange = np.ones_like(x)
        for j in range(m):
            others = np.arange(m) != j
            lagrange[:, j] = np.prod((at - x[:, others]) / (x[:, [j]] - x[:, others]), axis=1)
        cubic = np.zeros((len(idx), k))
        np.put_along_axis(cubic, idx, lagrange, axis=1)
        out[inside] = cubic
    return out


@dataclasses.dataclass(frozen=True)
class PlaneFailure:
    """The gains in force fail a lap at (u, w) with probability Φ(d·(u − threshold(w) − shift)/width(w)): each row's
    edge along the first cause (``rows`` the second cause's values, ascending), between rows on a cubic across them
    (:func:`_weights`), beyond them the threshold straight on and the width held. ``shift`` is
    the robot's edge against the twin's, in the first cause's unit. ``directions``: the way each part wears.

    With ``second`` (the second cause's own edge, raced at the first's least worn value), a lap also fails as the
    second cause alone fails it, whatever the first: 1 − (1 − p_first)(1 − p_second). Near the second cause's own
    edge a row's laps fail as the second fails them at any value of the first (the default robot's battery: below
    4.0 V its calibration turn leaves a sensor short of the line, at grip 0.45 to 0.9 alike), and a fit along the
    first there is the race's noise (0.54 to 0.78 over four draws of the twin's races at five seeds a value, the
    end of the range at twenty): those rows are left to ``second`` (:func:`tuner.history.two_causes.race_plane`)."""
    rows: np.ndarray
    thresholds: np.ndarray
    widths: np.ndarray
    directions: tuple[float, float]
    second: FailureModel | None = None

    @classmethod
    def of(cls, rows: list[tuple[float, FailureModel]], second_direction: float,
           second: FailureModel | None = None) -> "PlaneFailure":
        rows = sorted(rows, key=lambda r: r[0])
        return cls(np.array([w for w, _ in rows]), np.array([f.threshold for _, f in rows]),
                   np.array([f.width for _, f in rows]), (rows[0][1].direction, second_direction), second)

    @property
    def direction(self) -> np.ndarray:
        return np.array(self.directions)

    @property
    def width(self) -> float:
        """The edge's typical width (the median row's) [the first cause's unit]."""
        return float(np.median(self.widths))

    def threshold(self, w: np.ndarray) -> np.ndarray:
        """Where half the laps fail along the first cause, at the second's values ``w``."""
        w = np.asarray(w, float)
        return (_weights(self.rows, w.ravel()) @ self.thresholds).reshape(w.shape)

    def p_fail(self, x: np.ndarray, shift: np.ndarray | float = 0.0) -> np.ndarray:
        """At values ``x`` (..., 2), for a robot whose edge lies ``shift`` beyond the twin's."""
        from scipy.special import ndtr

        x = np.asarray(x, float)
        w = x[..., 1].ravel()
        weights = _weights(self.rows, w)
        threshold = (weights @ self.thresholds).reshape(x.shape[:-1])
        # the width's logarithm (never negative) across the rows, held beyond them as the scatter is: on the line
        # it shrank or grew without end, to overflow for a future that runs far past the outer rows
        log_width = np.log(self.widths)
        held = np.where(w < self.rows[0], log_width[0], np.where(w > self.rows[-1], log_width[-1], weights @ log_width))
        width = np.exp(held).reshape(x.shape[:-1])
        first = ndtr(self.directions[0] * (x[..., 0] - threshold - shift) / width)
        if self.second is None:
            return first
        return 1.0 - (1.0 - first) * (1.0 - self.second.p_fail(x[..., 1]))


@dataclasses.dataclass(frozen=True)
class PlaneObservation:
    """What a finished lap shows at (u, w): each row's observation model along the first cause (``rows`` the second
    cause's values, ascending), between rows its features' means on a cubic across them (straight on beyond the
    outer rows), their covariance on a line (held beyond); with ``edges``, each row read at the same distance from
    its failure edge (:meth:`_blend`)."""
    rows: np.ndarray
    models: tuple[ObservationModel, ...]
    edges: np.ndarray | None = None  # each row's failure edge along the first cause; None: rows read at the same u

    def __post_init__(self):
        if len(self.rows) < 2 or len(self.rows) != len(self.models) or np.any(np.diff(self.rows) <= 0):
            raise ValueError("a plane needs two rows or more, at ascending values")
        if self.edges is not None and np.shape(self.edges) != np.shape(self.rows):
            raise ValueError("a plane's edges: one per row")

    @classmethod
    def of(cls, rows: list[tuple[float, ObservationModel]], edges=None) -> "PlaneObservation":
        """``edges``: each row's failure edge along the first cause, in the order of ``rows`` (None: none)."""
        order = sorted(range(len(rows)), key=lambda k: rows[k][0])
        return cls(np.array([rows[k][0] for k in order]), tuple(rows[k][1] for k in order),
                   None if edges is None else np.array([edges[k] for k in order], float))

    @property
    def names(self) -> tuple[str, ...]:
        return self.models[0].names

    def subset(self, names: tuple[str, ...]) -> "PlaneObservation":
        """The plane's model of the features ``names`` alone (:meth:`ObservationModel.subset`)."""
        return dataclasses.replace(self, models=tuple(m.subset(names) for m in self.models))

    def _blend(self, x: np.ndarray, of, smooth: bool) -> np.ndarray:
        """Each row read at the same distance from its own failure edge as ``x`` from the plane's (the edge at w
        on the cubic across the rows' edges, as :meth:`PlaneFailure.threshold`), then blended across rows: near
        the edge a lap slows steeply, and the edge moves with w, so rows read at the same u were up to 5 lap
        scatters off a race between them (issue 35, 7 battery rows; ≤ 2.2 read at the same distance)."""
        x = np.atleast_2d(np.asarray(x, float))
        blend = _weights(self.rows, x[:, 1], smooth)
        u = np.broadcast_to(x[:, 0], (len(self.models), len(x)))
        if self.edges is not None:  # the edge on the cubic: the blend's own weights when it is the cubic too
            edge = (blend if smooth else _weights(self.rows, x[:, 1])) @ self.edges
            u = x[:, 0][None, :] - edge[None, :] + self.edges[:, None]
        each = np.stack([of(m, u[k]) for k, m in enumerate(self.models)])  # (rows, n, …)
        return np.einsum("nk,kn...->n...", blend, each)

    def mean(self, x: np.ndarray) -> np.ndarray:
        """(n, d): the features the twin expects at ``x`` (n, 2)."""
        return self._blend(x, lambda m, u: m.mean(u), smooth=True)

    def covariance(self, x: np.ndarray) -> np.ndarray:
        """(n, d, d): one lap's scatter at ``x`` (n, 2)."""
        return self._blend(x, lambda m, u: m.covariance(u), smooth=False)

    def reads(self, features: tuple[float, ...]) -> bool:
        """Is this a lap some row describes (not one that lost the line and found it again)?"""
        return any(m.reads(features) for m in self.models)

    def distance(self, features: tuple[float, ...], x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(squared Mahalanobis distance of a lap's features from the twin's at each ``x`` (n, 2), log determinant of
        the covariance there), as :meth:`ObservationModel.distance`."""
        return mahalanobis(np.asarray(features)[None, :] - self.mean(x), self.covariance(x))

    def nearest(self, features: tuple[float, ...], span: tuple[np.ndarray, np.ndarray],
                points: int = 31) -> tuple[np.ndarray, float]:
        """(the values (2,) in the box ``span`` = (lows, highs) whose features the twin gives nearest a lap's, the
        squared Mahalanobis distance there): the best of a ``points``² grid over the box, then of a second one over
        the four coarse cells around it (a step of 1/225 of the box for 31; one 121² grid, 7.6 times the points
        for a coarser step, took a third of a two-cause forecast's time)."""
        lo, hi = np.asarray(span[0], float), np.asarray(span[1], float)
        best, d2 = self._nearest_on_grid(features, lo, hi, points)
        cell = (hi - lo) / (points - 1)
        return self._nearest_on_grid(features, np.maximum(lo, best - 2 * cell), np.minimum(hi, best + 2 * cell),
                                     points) if np.all(cell > 0) else (best, d2)

    def _nearest_on_grid(self, features, lo: np.ndarray, hi: np.ndarray, points: int) -> tuple[np.ndarray, float]:
        u, w = np.meshgrid(np.linspace(lo[0], hi[0], points), np.linspace(lo[1], hi[1], points))
        grid = np.stack([u.ravel(), w.ravel()], axis=1)
        d2, _ = self.distance(features, grid)
        k = int(np.argmin(d2))
        return grid[k], float(d2[k])

    def pins(self, x: np.ndarray) -> np.ndarray:
        """How far one lap pins each cause near ``x`` (2,) (one standard error each, their units): from the
        features' slopes along both and their covariance (Fisher information); inf where the laps cannot tell."""
        x = np.asarray(x, float)
        step = 1e-3 * np.maximum(np.abs(x), 1e-6)
        jac = np.stack([(self.mean(x + step * e)[0] - self.mean(x - step * e)[0]) / (2 * step[k])
                        for k, e in enumerate(np.eye(2))], axis=1)  # (features, 2)
        info = jac.T @ np.linalg.inv(self.covariance(x)[0]) @ jac
        if not np.all(np.isfinite(info)) or np.linalg.det(info) <= 0:
            return np.full(2, math.inf)
        return np.sqrt(np.maximum(np.diag(np.linalg.inv(info)), 0.0))
