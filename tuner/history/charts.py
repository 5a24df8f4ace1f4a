"""A robot's life on one page (PNG, matplotlib, no display needed): its lap times lap by lap (failures marked, each
change of gains drawn where it came into force: confirmed, rolled back, refused), and below, the aligned parameter
with each alignment's interval, its trend, where the gains in force start failing, and the forecast lap with its
95 % interval."""

from __future__ import annotations

import math

import matplotlib

matplotlib.use("Agg")  # files only, no display
import matplotlib.pyplot as plt  # noqa: E402

STATUS_COLOUR = {"confirmed": "tab:green", "in_force": "tab:green", "rolled_back": "tab:red", "nak": "tab:orange",
                 "silent": "tab:orange", "superseded": "tab:gray"}


def robot_chart(entry: dict, path: str) -> str:
    """``entry``: one robot of :func:`tuner.history.report.report`."""
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(9, 6.5), sharex=True)
    laps = entry["lap_times"]
    done = [(r["n"], r["lap_time_s"]) for r in laps if r["completed"]]
    failed = [r["n"] for r in laps if not r["completed"]]
    if done:
        top.plot(*zip(*done), "o", ms=3, color="tab:blue", label="robot lap")
    twin = [(r["n"], r["twin_lap_time_s"]) for r in laps if r["twin_lap_time_s"]]
    if twin:
        top.plot(*zip(*twin), "-", lw=1, color="tab:gray", label="twin's prediction")
    if failed:
        y = max((t for _, t in done), default=1.0) * 1.02
        top.plot(failed, [y] * len(failed), "x", color="tab:red", label="failed lap")
    for ch in entry["changes"]:
        at = ch["first_lap"] if ch["first_lap"] is not None else ch["decided_lap"]
        if at is not None:
            top.axvline(at, color=STATUS_COLOUR.get(ch["status"], "tab:purple"), lw=1, ls="--")
            top.annotate(f"#{ch['seq']} {ch['status']}", (at, 0.98), xycoords=("data", "axes fraction"), fontsize=7,
                         rotation=90, va="top", ha="right")
    top.set_ylabel("lap time [s]")
    top.set_title(f"robot {entry['robot']}: {entry['laps']} laps, {entry['failed']} failed")
    if done or failed:
        top.legend(fontsize=8, loc="lower left")
    _parameter(bottom, entry)
    bottom.set_xlabel("lap (counted across runs)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _parameter(ax, entry: dict) -> None:
    trends = {a: t for a, t in entry["trends"].items() if t}
    if not entry["alignments"]:
        ax.text(0.5, 0.5, "no alignment yet", ha="center", va="center", transform=ax.transAxes)
        return
    address = next(iter(trends), entry["alignments"][0]["address"])
    points = [a for a in entry["alignments"] if a["address"] == address and a["value"] is not None]
    for a in points:
        lo, hi = a["interval"] or (a["value"], a["value"])
        ax.errorbar(a["lap"], a["value"], yerr=[[a["value"] - lo], [hi - a["value"]]], fmt="o", ms=4,
                    color="tab:blue", capsize=2)
    f, t = entry.get("forecast"), trends.get(address)
    if t:
        end = entry["laps"]
        if f and f.get("laps_to_failure") is not None and math.isfinite(f["laps_to_failure"]):
            end = max(end, f["now_lap"] + f["laps_to_failure"])
        xs = [t["first_lap"], end]
        ax.plot(xs, [t["intercept"] + t["slope"] * x for x in xs], "-", color="tab:blue", lw=1,
                label=f"trend {t['slope']:+.2g} per lap")
    if f and f.get("failing_value") is not None:
        ax.axhline(f["failing_value"], color="tab:red", lw=1, ls=":", label="the gains in force fail beyond")
        if f.get("laps_to_failure") is not None and math.isfinite(f["laps_to_failure"]):
            at = f["now_lap"] + f["laps_to_failure"]
            ax.plot([at], [f["failing_value"]], "v", color="tab:red", label=f"forecast: lap {at:.0f}")
            lo, hi = f["interval"] or (None, None)
            if lo is not None:
                ax.axvspan(f["now_lap"] + lo, f["now_lap"] + (hi if hi is not None else lo + 1e3), color="tab:red",
                           alpha=0.1)
    ax.set_ylabel(address)
    if t or (f and f.get("failing_value") is not None):
        ax.legend(fontsize=8, loc="best")
