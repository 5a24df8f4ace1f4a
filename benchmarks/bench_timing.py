"""The C loop against the robot's own firmware on the emulated MCU: the same gains, the same seeds (issue 33).

For each track, the default gains and the gains ``tune`` (plain) and ``tune --robust`` find on that track (each run
as a user runs it, ``python -m tuner``, in its own process) are raced on --seeds seeds by the C loop (with the
robot's timing: twin.model.timing) and by the firmware's binary on the emulated ATmega328P (``lap --firmware avr``),
which times its own reads and computes as the robot does. Laps of one seed draw the same sensor noise on both sides.

Each row prints the laps' mean difference (MCU − C: the bias the timing model must remove), the largest single-lap
difference and, for scale, the spread of the C loop's own laps over the seeds: gains near the edge of stability
(``tune``'s plain answer, K_P of 30–60 /s) make a lap's time depend on every microsecond, so single laps differ by
about as much as laps of different seeds do. Targets: |mean difference| ≤ 0.2 % on every row; the single-lap figure
is reported beside it. It also prints the MCU's measured release and compute times, the compute per code path (the
line off centre, at the centre, lost; calibration ticks), against the defaults of ``timing.release`` and
``timing.compute*``.

  python benchmarks/bench_timing.py [--tracks default,oval,circle,chicane] [--seeds 3] [--quick] [--json]

``--quick``: the default track, default and plainly tuned gains, one seed (for CI: the script cannot rot).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys

from twin.core.closed_loop import run_laps
from twin.core.digital_twin import DigitalTwin
from twin.model.timing import COMPUTE_ADDRESSES, COMPUTE_PATHS, RELEASE_US, Timing
from twin.pil.lap import run_pil_lap

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tests"))
from reference_gains import tuned_gains  # noqa: E402  (the one home of tuned gains)

TARGET_PERCENT = 0.2
TRACKS = ("default", "oval", "circle", "chicane")


def gains_for(track: str, kind: str) -> dict:
    """The gains tuned on ``track`` (kind plain or robust) as the tuner's CLI finds them, or {} for the defaults."""
    if kind == "default":
        return {}
    return tuned_gains("--track", track, *(["--robust"] if kind == "robust" else []))


def race(track: str, gains: dict, seeds: list[int]) -> dict:
    twin = DigitalTwin(track=track)
    for address, value in gains.items():
        twin.set(address, value)
    c_laps = run_laps(twin, [{}] * len(seeds), seed=seeds, keep_traces=False)
    diffs, mcu = [], []
    for seed, c in zip(seeds, c_laps):
        m, report = run_pil_lap(twin, seed=seed, keep_trace=False)
        mcu.append(report)
        if c.completed and m.completed:
            diffs.append(100.0 * (m.lap_time_s / c.lap_time_s - 1.0))
    c_times = [c.lap_time_s for c in c_laps if c.completed]
    return {
        "completed": len(diffs), "laps": len(seeds), "c_lap_s": statistics.fmean(c_times) if c_times else None,
        "mean_difference_percent": statistics.fmean(diffs) if diffs else None,
        "largest_difference_percent": max(diffs, key=abs) if diffs else None,
        "c_spread_percent": 100.0 * (max(c_times) - min(c_times)) / min(c_times) if c_times else None,
        "mcu_release_mean_us": statistics.fmean(r.release_mean_us for r in mcu),
        "mcu_compute_mean_us": statistics.fmean(r.compute_mean_us for r in mcu),
        "mcu_compute_range_us": [min(r.compute_min_us for r in mcu), max(r.compute_max_us for r in mcu)],
        "mcu_compute_path_mean_us": path_means(mcu),
    }


def path_means(reports: list) -> dict[str, float]:
    """Each code path's mean compute [µs] over the laps' timed ticks of that path."""
    means = {}
    for path in COMPUTE_PATHS:
        ticks = sum(r.compute_path_ticks[path] for r in reports)
        if ticks:
            means[path] = sum(r.compute_path_mean_us.get(path, 0.0) * r.compute_path_ticks[path] for r in reports) / ticks
    return means


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0], formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    p.add_argument("--tracks", default=",".join(TRACKS), help="built-in tracks, comma-separated")
    p.add_argument("--seeds", type=int, default=3, help="laps per row: seeds 0 … N-1")
    p.add_argument("--quick", action="store_true", help="default track; default and plainly tuned gains; one seed")
    p.add_argument("--json", action="store_true", help="one JSON document on stdout")
    args = p.parse_args()
    if args.seeds < 1:
        p.error(f"--seeds {args.seeds}: at least 1")
    tracks = ["default"] if args.quick else [t for t in args.tracks.split(",") if t]
    kinds = ("default", "plain") if args.quick else ("default", "plain", "robust")
    seeds = [0] if args.quick else list(range(args.seeds))
    rows = []
    for track in tracks:
        for kind in kinds:
            row = {"track": track, "gains": kind, **race(track, gains_for(track, kind), seeds)}
            rows.append(row)
            if not args.json:
                mean = row["mean_difference_percent"]
                verdict = "laps did not complete" if mean is None else (
                    f"mean {mean:+.3f} % {'ok' if abs(mean) <= TARGET_PERCENT else 'OVER'}, largest "
                    f"{row['largest_difference_percent']:+.3f} %, C's own spread {row['c_spread_percent']:.3f} %")
                print(f"{track:8s} {kind:8s} C {row['c_lap_s'] or float('nan'):.3f} s  {row['completed']}/"
                      f"{row['laps']} both completed  {verdict}  (MCU: release {row['mcu_release_mean_us']:.1f} µs, "
                      f"compute {row['mcu_compute_mean_us']:.0f} µs: "
                      + ", ".join(f"{k} {v:.0f}" for k, v in row["mcu_compute_path_mean_us"].items()) + ")", flush=True)
    timing = Timing()
    defaults = {f"timing.{address}": timing.compute_time_us(path) for path, address in COMPUTE_ADDRESSES.items()}
    means = [abs(r["mean_difference_percent"]) for r in rows if r["mean_difference_percent"] is not None]
    largest = [abs(r["largest_difference_percent"]) for r in rows if r["largest_difference_percent"] is not None]
    summary = {"rows": rows, "seeds": seeds, "target_percent": TARGET_PERCENT,
               "worst_mean_percent": max(means) if means else None, "worst_lap_percent": max(largest) if largest else None,
               "met": bool(means) and len(means) == len(rows) and max(means) <= TARGET_PERCENT,
               "defaults_us": {"timing.release": RELEASE_US, **defaults}}
    if args.json:
        print(json.dumps(summary))
    else:
        print(f"worst |mean difference| {summary['worst_mean_percent']:.3f} % (target {TARGET_PERCENT} %: "
              f"{'met' if summary['met'] else 'NOT met'}); worst single lap {summary['worst_lap_percent']:.3f} %; "
              f"timing defaults: release {RELEASE_US:g} µs, " + ", ".join(f"{k} {v:g}" for k, v in defaults.items())
              + " µs")
    return 0


if __name__ == "__main__":
    sys.exit(main())
