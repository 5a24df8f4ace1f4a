"""A robot's life on one page (PNG, matplotlib, no display needed): its lap times lap by lap (failures marked, each
change of gains drawn where it came into force: confirmed, rolled back, refused), and below, the aligned parameter
with each alignment over the laps it measured, the filter's estimate lap by lap with its 90 % band, where the
gains in force start failing, the failed laps, and the forecast lap (median) with its 90 % interval."""

from __future__ import annotations

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
    if not entry["alignments"]:
        ax.text(0.5, 0.5, "no alignment yet", ha="center", va="center", transform=ax.transAxes)
        return
    f = entry.get("forecast")
    if f and f.get("causes"):  # both at once: the first cause's estimate (its edge moves with the other's value)
        address = next(iter(f["causes"]))
        f = {**f, "address": address, "band": f["causes"][address]["band"]}
    address = f["address"] if f else entry["alignments"][0]["address"]
    points = [a for a in entry["alignments"] if a["address"] == address and a["value"] is not None
              and not a.get("estimated")]
    for a in points:
        lo, hi = a["interval"] or (a["value"], a["value"])
        ax.errorbar((a.get("first_lap", a["lap"]) + a["lap"]) / 2, a["value"], yerr=[[a["value"] - lo], [hi - a["value"]]],
                    xerr=(a["lap"] - a.get("first_lap", a["lap"])) / 2, fmt="o", ms=4, color="tab:blue", capsize=2)
    if f and f.get("band"):
        laps, q05, med, q95 = zip(*f["band"])
        ax.fill_between(laps, q05, q95, color="tab:blue", alpha=0.15, label="estimate, 90 %")
        ax.plot(laps, med, "-", color="tab:blue", lw=1)
    if f and f.get("failing_value") is not None:
        ax.axhline(f["failing_value"], color="tab:red", lw=1, ls=":", label="the gains in force fail beyond")
        failed = [r["n"] for r in entry["lap_times"] if not r["completed"]]
        if failed:
            ax.plot(failed, [f["failing_value"]] * len(failed), "x", color="tab:red", label="failed lap")
        if f.get("laps_to_failure") is not None:
            at = f["now_lap"] + f["laps_to_failure"]
            ax.plot([at], [f["failing_value"]], "v", color="tab:red", label=f"forecast: lap {at:.0f} (median)")
            lo, hi = f["interval"] or (None, None)
            if lo is not None:
                end = f["now_lap"] + hi if hi is not None else ax.get_xlim()[1]
                ax.axvspan(f["now_lap"] + lo, end, color="tab:red", alpha=0.1, label="90 % of the futures fail here")
    ax.set_ylabel(address)
    if ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize=8, loc="best")
