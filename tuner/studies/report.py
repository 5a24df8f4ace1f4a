"""What a design study writes: lap-time distributions (box plot), the Pareto view, a table, tuned gains.

All files go to a temporary folder that replaces the output folder when complete (``lf_common.files.output_dir``),
so a crash leaves either the old results or the new ones, never a mixture; a folder holding anything this
program did not write is never replaced.
"""

from __future__ import annotations

import csv
import json
import math
import os
from typing import Sequence

import matplotlib

matplotlib.use("Agg")  # files only, no display
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from lf_common.files import GENERATOR, json_safe, output_dir  # noqa: E402
from tuner.studies.design import DesignResult  # noqa: E402


def slug(r: DesignResult) -> str:
    return "_".join(f"{a.replace('.', '-')}={v if isinstance(v, str) else format(v, 'g')}" for a, v in r.design.items())


def chart_label(r: DesignResult) -> str:
    """A design's label on the charts: its parameters, and a warning when its gains did not converge."""
    return r.label + ("" if r.converged or not r.ok else ", (not converged)")


def box_chart(path: str, results: Sequence[DesignResult], title: str) -> None:
    fig, ax = plt.subplots(figsize=(max(6.0, 1.1 * len(results) + 2), 4.5), dpi=120)
    data = [list(r.lap_times_s) if r.lap_times_s else [math.nan] for r in results]
    ax.boxplot(data, showfliers=True, widths=0.6)
    rng = np.random.default_rng(0)
    for i, d in enumerate(data, start=1):
        ax.plot(i + rng.uniform(-0.12, 0.12, len(d)), d, ".", color="tab:blue", alpha=0.5, ms=4)
    for i, r in enumerate(results, start=1):
        if not r.ok or not r.lap_times_s:
            ax.annotate("failed" if not r.ok else "no lap", (i, 0.5), xycoords=("data", "axes fraction"), ha="center",
                        color="tab:red")
    ax.set_xticks(range(1, len(results) + 1), [chart_label(r).replace(", ", "\n") for r in results], fontsize=8)
    ax.set_ylabel("lap time after tuning [s]")
    ax.set_title(title)
    ax.grid(axis="y", alpha=0.3)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def pareto_chart(path: str, results: Sequence[DesignResult], front: Sequence[bool]) -> None:
    fig, ax = plt.subplots(figsize=(6.5, 4.5), dpi=120)
    for r, on in zip(results, front):
        if not (r.ok and r.lap_times_s):
            continue
        ax.plot(r.median_s, r.mean_cross_track_m * 1000, "o", color="tab:red" if on else "tab:gray", ms=7)
        ax.annotate(chart_label(r), (r.median_s, r.mean_cross_track_m * 1000), fontsize=7, xytext=(4, 3),
                    textcoords="offset points")
    pts = sorted((r.median_s, r.mean_cross_track_m * 1000) for r, on in zip(results, front) if on)
    if pts:
        ax.plot(*zip(*pts), "-", color="tab:red", alpha=0.5, label="Pareto front")
        ax.legend()
    ax.set_xlabel("median lap time after tuning [s]")
    ax.set_ylabel("mean cross-track error [mm]")
    ax.set_title("lap time against tracking accuracy")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def write_report(out_dir: str, results: Sequence[DesignResult], front: Sequence[bool], trends: Sequence[str],
                 meta: dict) -> dict[str, str]:
    """Write charts, table and gains to ``out_dir`` (replaced as a whole); returns {what: path}."""
    with output_dir(out_dir, "design study folder") as tmp:
        box_chart(os.path.join(tmp, "lap_times.png"), results, f"converged lap times ({meta['track']} track)")
        pareto_chart(os.path.join(tmp, "pareto.png"), results, front)
        names = list(results[0].design) if results else []
        gain_names = sorted({g for r in results for g in r.gains})
        with open(os.path.join(tmp, "designs.csv"), "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(names + ["ok", "error", "median_lap_time_s", "min_lap_time_s", "max_lap_time_s", "iqr_s",
                                "laps_completed", "laps_failed", "mean_cross_track_m", "pareto", "converged",
                                "search", "tuning_iterations", "tuning_laps"] + gain_names)
            for r, on in zip(results, front):
                t = np.array(r.lap_times_s)
                stats = ([float(np.median(t)), float(t.min()), float(t.max()),
                          float(np.subtract(*np.percentile(t, [75, 25])))] if len(t) else [""] * 4)
                w.writerow([r.design[n] for n in names] + [r.ok, r.error or ""] + stats + [
                    len(t), r.failed_laps, "" if math.isnan(r.mean_cross_track_m) else r.mean_cross_track_m, on,
                    r.converged, r.search, r.tuning_iterations, r.tuning_laps] + [r.gains.get(g, "") for g in gain_names])
        os.makedirs(os.path.join(tmp, "gains"))
        for r in results:
            if r.ok and r.gains:  # (a 3pi program's designs are not tuned: no gains of theirs to write)
                with open(os.path.join(tmp, "gains", f"{slug(r)}.json"), "w") as f:
                    json.dump(json_safe({"generator": GENERATOR, "gains": r.gains, "design": r.design,
                                         "track": meta["track"], "median_lap_time_s": r.median_s,
                                         "converged": r.converged, "search": r.search,
                                         "tuned_for": r.tuned_for}), f, indent=2,
                              allow_nan=False)
        with open(os.path.join(tmp, "designs.json"), "w") as f:
            json.dump(json_safe({"generator": GENERATOR, **meta, "trends": list(trends),
                                 "designs": [{**r.__dict__, "median_lap_time_s": r.median_s, "pareto": on, "label": r.label}
                                             for r, on in zip(results, front)]}), f, indent=2, allow_nan=False)
    out_dir = os.path.abspath(out_dir)
    return {"folder": out_dir, **{k: os.path.join(out_dir, v) for k, v in (
        ("chart", "lap_times.png"), ("pareto", "pareto.png"), ("table", "designs.csv"), ("json", "designs.json"),
        ("gains", "gains"))}}
