"""Sensitivity sweeps: where a set of gains stops working.

One or two batchable parameters (``motion.*``, ``motor.*``, ``control.*``, ``sensor.*`` responses) are varied over
a grid, each grid point raced with several noise seeds; all laps run as one batch. Per grid point: the lap
time (median and spread over the seeds that completed), the completion rate, the largest cross-track error and
the median energy. One parameter gives a line chart with the failure region shaded; two give heat maps.
Outputs (CSV, PNG, JSON) are written into a folder of their own, atomically (``lf_common.files.output_dir``).

With a program for the robot's MCU (:func:`sweep_firmware`: the twin's own firmware, or any 3pi program on the
board) every lap runs cycle by cycle in simavr, one after another on one core (about 5 s a lap), so such a sweep
holds at most ``MAX_FIRMWARE_LAPS`` laps; a program other than the twin's own keeps its own gains, so ``control.*``
cannot be swept with it.
"""

from __future__ import annotations

import csv
import dataclasses
import itertools
import json
import math
import os
from typing import Callable, Sequence

import matplotlib

matplotlib.use("Agg")  # files only, no display
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from lf_common.files import GENERATOR, json_safe, output_dir  # noqa: E402
from twin.core.closed_loop import MAX_LAPS, run_laps  # noqa: E402
from twin.core.lap import LapLimits, LapResult  # noqa: E402
from twin.core.digital_twin import DigitalTwin  # noqa: E402
from twin.errors import TwinError  # noqa: E402
from twin.pil import run_pil_lap  # noqa: E402
from twin.pil.board import run_program_lap  # noqa: E402
from twin.telemetry.wire import GAIN_ADDRESSES  # noqa: E402
from twin.model.space import ChangeCost  # noqa: E402

MAX_FIRMWARE_LAPS = 500  # laps on the emulated MCU, one after another: ~5 s each, under an hour


@dataclasses.dataclass(frozen=True)
class Axis:
    """One swept parameter: ``count`` evenly spaced values from ``lower`` to ``upper`` (inclusive)."""

    address: str
    lower: float
    upper: float
    count: int

    def __post_init__(self) -> None:
        if not (math.isfinite(self.lower) and math.isfinite(self.upper)):
            raise TwinError(f"sweep {self.address}: LO and HI must be finite numbers")
        if not self.lower < self.upper:
            raise TwinError(f"sweep {self.address}: LO {self.lower:g} must be below HI {self.upper:g}")
        if self.count < 2:
            raise TwinError(f"sweep {self.address}: N must be at least 2, got {self.count}")

    @property
    def values(self) -> np.ndarray:
        return np.linspace(self.lower, self.upper, self.count)


@dataclasses.dataclass(frozen=True)
class Point:
    """One grid point: its values and what its laps (one per seed) did."""

    values: dict[str, float]
    lap_times_s: tuple[float, ...]  # the completed laps
    laps: int
    failures: tuple[str, ...]  # the failure of each lap that did not complete
    max_cross_track_m: float  # the largest over all its laps
    energy_j: float  # median over the completed laps (NaN if none)

    @property
    def completion(self) -> float:
        return len(self.lap_times_s) / self.laps

    @property
    def median_s(self) -> float:
        return float(np.median(self.lap_times_s)) if self.lap_times_s else math.nan

    def row(self) -> dict:
        t = self.lap_times_s
        return {**self.values, "completion_rate": self.completion, "median_lap_time_s": self.median_s,
                "min_lap_time_s": min(t) if t else math.nan, "max_lap_time_s": max(t) if t else math.nan,
                "max_cross_track_m": self.max_cross_track_m, "median_energy_j": self.energy_j,
                "laps": self.laps, "failures": ";".join(sorted(set(self.failures)))}


def check_axes(twin: DigitalTwin, axes: Sequence[Axis]) -> None:
    """One or two distinct parameters that can differ between the laps of one batch, inside their ranges."""
    if not 1 <= len(axes) <= 2:
        raise TwinError(f"sweep: give one or two parameters, got {len(axes)}")
    if len({a.address for a in axes}) != len(axes):
        raise TwinError("sweep: the same parameter twice")
    for a in axes:
        p = twin.space.parameter(a.address)
        if p.cost is ChangeCost.REBUILD or p.integer:
            raise TwinError(f"sweep {a.address}: rebuilds the robot or track (or is a whole number), so it cannot vary "
                            "between the laps of one batch; sweep it with a design study")
        p.check(f"sweep {a.address} LO", a.lower)
        p.check(f"sweep {a.address} HI", a.upper)


def grid_points(axes: Sequence[Axis]) -> list[dict[str, float]]:
    """The sweep's grid points in order (the first axis slowest)."""
    return [dict(zip([a.address for a in axes], map(float, combo))) for combo in itertools.product(*(a.values for a in axes))]


def check_size(axes: Sequence[Axis], seeds: int, firmware: bool = False, one_by_one: str | None = None) -> None:
    """At most ``MAX_LAPS`` laps (``MAX_FIRMWARE_LAPS`` run one by one: on the emulated MCU, or ``one_by_one``
    saying what runs them), counted from the axes before any grid is built (a billion points would take all memory
    building it)."""
    laps = math.prod(a.count for a in axes) * seeds
    limit, what = (MAX_FIRMWARE_LAPS, f"laps {one_by_one} allowed") if one_by_one else \
        (MAX_FIRMWARE_LAPS, "laps on the emulated MCU (about 5 s each) allowed") if firmware else \
        (MAX_LAPS, "one batch holds")
    if laps > limit:
        points = " × ".join(f"{a.count:,}" for a in axes)
        raise TwinError(f"sweep: {points} points × {seeds} seeds is {laps:,} laps, more than the {limit:,} {what}; use "
                        "fewer points or seeds")


def check_program_axes(axes: Sequence[Axis]) -> None:
    """A 3pi program other than the twin's own firmware has its gains compiled in: ``control.*`` never reaches it."""
    for a in axes:
        if a.address.startswith("control."):
            raise TwinError(f"sweep {a.address}: a 3pi program keeps its own gains (only the twin's own firmware takes "
                            "control.* from the twin); sweep a parameter of the robot or its world")


def check_controller_axes(axes: Sequence[Axis], placed: Sequence[str] = ()) -> None:
    """A controller FMU has its own law: the firmware's gains never reach it; a multi-model's sensors stand where it
    puts them (``placed``: the addresses its stand-in file sets)."""
    for a in axes:
        if a.address in GAIN_ADDRESSES:
            raise TwinError(f"sweep {a.address}: the controller FMU drives with its own law (the firmware's gains "
                            f"{', '.join(GAIN_ADDRESSES)} never reach it); sweep a parameter of the robot or its world")
        if a.address in placed:
            raise TwinError(f"sweep {a.address}: the --stand-in file places the sensors where the multi-model puts "
                            "them; change the multi-model's sensor parameters instead")


def sweep(twin: DigitalTwin, axes: Sequence[Axis], seeds: Sequence[int], nthread: int = 0) -> list[Point]:
    """Every grid point × seed as one batch of laps; points in grid order (the first axis slowest)."""
    check_axes(twin, axes)
    check_size(axes, len(seeds))
    grid = grid_points(axes)
    laps = run_laps(twin, [g for g in grid for _ in seeds], seed=[s for _ in grid for s in seeds], nthread=nthread,
                    keep_traces=False)
    return points_of(grid, seeds, laps)


def sweep_firmware(twin: DigitalTwin, axes: Sequence[Axis], seeds: Sequence[int],
                   lap: Callable[[DigitalTwin, int], LapResult], on_lap: Callable[[LapResult], None] | None = None
                   ) -> list[Point]:
    """Every grid point × seed as a lap run one after another by ``lap(twin, seed)`` (on the emulated MCU:
    :func:`firmware_lap`; a controller FMU: :func:`controller_lap`); points in grid order, as :func:`sweep` gives
    them. The given twin is not changed."""
    check_axes(twin, axes)
    check_size(axes, len(seeds), firmware=True)
    grid = grid_points(axes)
    work = twin.clone()  # the grid's values go here, point after point (same addresses each time)
    laps = []
    for g in grid:
        work.update(g)
        for s in seeds:
            laps.append(lap(work, s))
            if on_lap:
                on_lap(laps[-1])
    return points_of(grid, seeds, laps)


def controller_lap(controller, limits: LapLimits = LapLimits()) -> Callable[[DigitalTwin, int], LapResult]:
    """One lap driven by a controller FMU (:class:`twin.fmi.ControllerFmu`; its process is started once and kept
    between laps, and every lap instantiates the FMU afresh)."""
    from twin.fmi import run_controller_lap

    def run(twin: DigitalTwin, seed: int) -> LapResult:
        return run_controller_lap(twin, controller, seed=seed, limits=limits, keep_trace=False)
    return run


def firmware_lap(program, operator: Callable[[], object] | None = None, limits: LapLimits = LapLimits()
                 ) -> Callable[[DigitalTwin, int], LapResult]:
    """One lap of ``program`` (None: the twin's own firmware built from its sources; else a loaded
    :class:`twin.pil.program.Program`, ELF or HEX) with a new operator from ``operator()`` for each lap (an operator
    remembers its presses)."""
    def run(twin: DigitalTwin, seed: int) -> LapResult:
        if program is None:
            return run_pil_lap(twin, None, seed=seed, limits=limits, keep_trace=False)[0]
        return run_program_lap(twin, program, seed=seed, limits=limits, keep_trace=False,
                               operator=operator() if operator else None)[0]
    return run


def points_of(grid: Sequence[dict], seeds: Sequence[int], laps: Sequence) -> list[Point]:
    """Each grid point's summary from its laps, which come point by point, seed by seed."""
    k = len(seeds)
    points = []
    for i, g in enumerate(grid):
        part = laps[i * k:(i + 1) * k]
        done = [r for r in part if r.completed]
        points.append(Point(g, tuple(r.lap_time_s for r in done), k, tuple(r.failure for r in part if not r.completed),
                            max(r.max_cross_track_m for r in part),
                            float(np.median([r.energy_j for r in done])) if done else math.nan))
    return points


def _failure_spans(x: np.ndarray, failed: np.ndarray) -> list[tuple[float, float]]:
    """x-intervals to shade: each point with a failed lap, reaching half-way to its neighbours."""
    edges = np.concatenate([[x[0]], (x[1:] + x[:-1]) / 2, [x[-1]]])
    return [(edges[i], edges[i + 1]) for i in np.flatnonzero(failed)]


def line_chart(path: str, axis: Axis, points: Sequence[Point], title: str) -> None:
    x = axis.values
    med = np.array([p.median_s for p in points])
    lo = np.array([min(p.lap_times_s) if p.lap_times_s else np.nan for p in points])
    hi = np.array([max(p.lap_times_s) if p.lap_times_s else np.nan for p in points])
    panels = [("lap time [s]", med), ("laps completed [-]", np.array([p.completion for p in points])),
              ("max cross-track error [mm]", np.array([p.max_cross_track_m * 1000 for p in points])),
              ("energy per lap [J]", np.array([p.energy_j for p in points]))]
    fig, axes = plt.subplots(len(panels), 1, sharex=True, figsize=(7, 8), dpi=110)
    spans = _failure_spans(x, np.array([p.completion < 1 for p in points]))
    for ax, (name, y) in zip(axes, panels):
        for a, b in spans:
            ax.axvspan(a, b, color="tab:red", alpha=0.12, lw=0)
        ax.plot(x, y, "o-", ms=3)
        if name.startswith("lap time"):
            ax.fill_between(x, lo, hi, alpha=0.25, label="min–max over seeds")
            ax.legend(fontsize=8)
        ax.set_ylabel(name, fontsize=9)
        ax.grid(alpha=0.3)
    axes[0].set_title(title + ("  (shaded: some laps fail)" if spans else ""), fontsize=10)
    axes[-1].set_xlabel(axis.address)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def cell_edges(values: Sequence[float]) -> np.ndarray:
    """Edges of the cells centred on grid values: midway between neighbours, and as far beyond the ends (a single
    value gets a cell of ±half its size, or ±0.5 at zero)."""
    v = np.asarray(values, dtype=float)
    if len(v) == 1:
        half = 0.5 * abs(v[0]) or 0.5
        return np.array([v[0] - half, v[0] + half])
    mid = (v[1:] + v[:-1]) / 2
    return np.concatenate([[2 * v[0] - mid[0]], mid, [2 * v[-1] - mid[-1]]])


def heat_map_figure(axes: Sequence[Axis], points: Sequence[Point], title: str):
    """Median lap time and completion over a 2-D grid: each cell centred on its grid point (``pcolormesh`` on
    :func:`cell_edges`; an ``imshow`` extent at the axis limits would put cell edges on the grid values)."""
    a, b = axes
    shape = (a.count, b.count)
    maps = [("median lap time [s]", np.array([p.median_s for p in points]).reshape(shape)),
            ("laps completed [-]", np.array([p.completion for p in points]).reshape(shape))]
    fig, panels = plt.subplots(1, 2, figsize=(11, 4.5), dpi=110)
    for ax, (name, m) in zip(panels, maps):
        cmap = plt.get_cmap("viridis").with_extremes(bad="tab:red")  # red: no completed lap at all
        image = ax.pcolormesh(cell_edges(b.values), cell_edges(a.values), np.ma.masked_invalid(m), cmap=cmap)
        fig.colorbar(image, ax=ax, label=name)
        ax.set_xlabel(b.address)
        ax.set_ylabel(a.address)
        ax.set_title(name + " (red: no lap completed)" if name.startswith("median") else name, fontsize=9)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return fig


def heat_map(path: str, axes: Sequence[Axis], points: Sequence[Point], title: str) -> None:
    fig = heat_map_figure(axes, points, title)
    fig.savefig(path)
    plt.close(fig)


def write_sweep(out_dir: str, axes: Sequence[Axis], points: Sequence[Point], meta: dict) -> dict[str, str]:
    """``sweep.csv``, ``sweep.json`` and ``sweep.png`` into ``out_dir`` (new, empty, or ours), atomically."""
    title = f"{meta['track']}: " + " × ".join(f"{a.address} {a.lower:g}…{a.upper:g}" for a in axes)
    with output_dir(out_dir, "sweep folder") as tmp:
        rows = [p.row() for p in points]
        with open(os.path.join(tmp, "sweep.csv"), "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=list(rows[0]))
            w.writeheader()
            w.writerows(rows)
        with open(os.path.join(tmp, "sweep.json"), "w") as f:
            json.dump(json_safe({"generator": GENERATOR, **meta, "axes": [dataclasses.asdict(a) for a in axes],
                                 "points": rows}), f, indent=1, allow_nan=False)
        chart = os.path.join(tmp, "sweep.png")
        (line_chart(chart, axes[0], points, title) if len(axes) == 1 else heat_map(chart, axes, points, title))
    out = os.path.abspath(out_dir)
    return {"folder": out, **{k: os.path.join(out, f"sweep.{k}") for k in ("csv", "json", "png")}}
