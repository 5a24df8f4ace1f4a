"""Acting on an ageing robot: tyre grip drifting 0.9 → 0.55 over 80 laps on plainly tuned gains, plain ``live``
against ``live --act``, at real time (``emulate --speed 1``, no lockstep: the twin's re-tuning must keep up with a
robot that does not wait for it).

Measured, each run with its own emulated robot (the same seed, the same drift), both at once:
  * failed laps: laps the robot did not finish, plain and with --act (from the robot's own record, ``--echo``);
  * laps to recover: with --act, from the first lap the twin disagreed with (beyond --threshold) to the first lap
    the robot ran on re-tuned gains that were then confirmed;
  * the forecast's error: from the plain run's alignments and laps before its first failed lap, ``history``'s
    forecast (the median of the remaining life, :func:`tuner.history.forecast_failure`) of the lap they stop
    finishing, against the lap they first failed on; made at each alignment with at least one before it.

  python benchmarks/bench_act.py [--laps 80] [--speed 1] [--keep DIR] [--quick] [--json]

``--quick``: 4 laps (the same drift, compressed) at 20× real time (for CI: the script cannot rot; at that pace a
re-tuning lands after the last lap, so the figures are not the table's).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import subprocess
import sys
import tempfile
import time

from tuner.history import actions_path, forecast_failure, log_laps, read_journal
from twin.core.digital_twin import DigitalTwin

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tests"))
from reference_gains import set_flags, tuned_gains  # noqa: E402  (the one home of tuned gains)

PLAIN: dict[str, float] = {}  # the gains ``tune`` answers today for the robot as built, tuned by main
GAINS: list[str] = []  # the same, as --set flags
RUN = [sys.executable, "-m", "twin.run"]


def robot_laps(path: str) -> list[tuple[int | None, float | None]]:
    """(gains in force, lap time or None) of each lap, from the robot's own record."""
    return [(lap.gains_seq, lap.lap_time_s) for lap in log_laps(path)]


def start(folder: str, laps: int, drift: str, speed: float, act: bool) -> tuple[subprocess.Popen, subprocess.Popen]:
    emu = subprocess.Popen([*RUN, "emulate", "--tcp", "0", "--speed", str(speed), "--laps", str(laps), "--drift", drift,
                            "--echo", "echo.txt", "--json", *GAINS], cwd=folder, stdout=subprocess.PIPE,
                           stderr=subprocess.DEVNULL, text=True)
    url = json.loads(emu.stdout.readline())["link"]
    live = subprocess.Popen([*RUN, "live", "--port", url, "--laps", str(laps), "--json", *GAINS,
                             *(["--act"] if act else [])], cwd=folder, stdout=subprocess.PIPE,
                            stderr=open(os.path.join(folder, "live.err"), "w"), text=True)
    return emu, live


def recovery(folder: str, doc: dict, laps: list, threshold: float) -> int | None:
    """Laps from the first disagreement to the first lap on re-tuned gains that were confirmed."""
    compared = [r for _, r in read_journal(actions_path(os.path.join(folder, "live_telemetry.log")))
                if r.get("kind") == "lap"]
    first = next((e["lap"] for e in compared if e.get("robot_lap_time_s") is None
                  or e.get("discrepancy") is not None and abs(e["discrepancy"]) > threshold), None)
    confirmed = {c["seq"] for c in doc["changes"] if c["kind"] == "retune" and c["status"] == "confirmed"}
    on_new = next((k for k, (seq, _) in enumerate(laps) if seq in confirmed), None)
    return None if first is None or on_new is None else on_new - first


def forecasts(doc: dict, laps: list) -> list[dict]:
    """The forecast made at each alignment of the plain run (with one before it) before its first failed lap, from
    the alignments and laps seen up to it."""
    failed = next((k for k, (_, t) in enumerate(laps) if t is None), None)
    if failed is None:
        return []
    twin = DigitalTwin()
    twin.model()
    aligned = [a for a in doc["alignments"] if a.get("explained") and a.get("lap", failed) < failed]
    seen = [{"n": k, "completed": t is not None, "gains": PLAIN} for k, (_, t) in enumerate(laps)]
    out = []
    for i in range(1, len(aligned)):
        now = aligned[i]["lap"]
        f = forecast_failure(twin, PLAIN, aligned[:i + 1], seen[:now + 1], "motion.mu", now_lap=now)
        predicted = None if f.laps_to_failure is None else now + f.laps_to_failure
        out.append({"at_lap": now, "failing_mu": f.failing_value, "predicted_lap": predicted,
                    "interval": None if f.interval is None else [None if x is None else now + x for x in f.interval],
                    "first_failed_lap": failed, "error_laps": None if predicted is None else predicted - failed})
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--laps", type=int, default=80)
    ap.add_argument("--speed", type=float, default=1.0, help="the robot's pace against real time")
    ap.add_argument("--drift", default=None, help="default: motion.mu=0.9:0.55@LAPS")
    ap.add_argument("--keep", metavar="DIR", help="run in this new folder and keep it (logs, echoes, journals)")
    ap.add_argument("--quick", action="store_true", help="4 laps at 20× real time (for CI)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    if args.quick:
        args.laps, args.speed = 4, 20.0
    PLAIN.update(tuned_gains())
    GAINS[:] = set_flags(PLAIN)
    drift = args.drift or f"motion.mu=0.9:0.55@{args.laps}"
    runs, t0 = {}, time.monotonic()
    if args.keep:
        os.makedirs(args.keep)
    with (contextlib.nullcontext(args.keep) if args.keep else tempfile.TemporaryDirectory(prefix="bench-act-")) as tmp:
        procs = {}
        for name in ("plain", "act"):
            os.makedirs(os.path.join(tmp, name))
            procs[name] = start(os.path.join(tmp, name), args.laps, drift, args.speed, name == "act")
        for name, (emu, live) in procs.items():
            out, _ = live.communicate()
            with open(os.path.join(tmp, name, "live.json"), "w") as f:
                f.write(out)
            emu.wait(timeout=120)
            runs[name] = json.loads(out), robot_laps(os.path.join(tmp, name, "echo.txt"))
        wall = time.monotonic() - t0
        result = summarise(args, drift, wall, runs, tmp)
    report(result, args.json)


def summarise(args, drift: str, wall: float, runs: dict, tmp: str) -> dict:
    (plain, plain_laps), (act, act_laps) = runs["plain"], runs["act"]
    changes = act["changes"]
    return {
        "drift": drift, "laps": args.laps, "speed": args.speed, "wall_s": round(wall, 1),
        "failed_laps": {"plain": sum(t is None for _, t in plain_laps), "act": sum(t is None for _, t in act_laps)},
        "first_failed_lap": {"plain": next((k for k, (_, t) in enumerate(plain_laps) if t is None), None),
                             "act": next((k for k, (_, t) in enumerate(act_laps) if t is None), None)},
        "laps_to_recover": recovery(os.path.join(tmp, "act"), act, act_laps, 0.005),
        "changes": {s: sum(c["status"] == s for c in changes) for s in sorted({c["status"] for c in changes})},
        "retune_wall_s": [a.get("wall_s") for a in act["actions"] if a["kind"] == "retune"],
        "forecasts": forecasts(plain, plain_laps),
    }


def report(result: dict, as_json: bool) -> None:
    drift, laps, speed, wall = result["drift"], result["laps"], result["speed"], result["wall_s"]
    if as_json:
        print(json.dumps(result, indent=1))
        return
    print(f"{drift}, {laps} laps at {speed:g}× real time ({wall:.0f} s wall)")
    print(f"failed laps: plain {result['failed_laps']['plain']} (first at lap {result['first_failed_lap']['plain']}), "
          f"--act {result['failed_laps']['act']}")
    print(f"laps to recover after the first disagreement (--act): {result['laps_to_recover']}")
    print(f"changes of gains: {result['changes']}; re-tuning wall time [s]: {result['retune_wall_s']}")
    for f in result["forecasts"]:
        print(f"forecast at lap {f['at_lap']}: fails at μ = {f['failing_mu']}, lap {f['predicted_lap']} "
              f"(interval {f['interval']}), first failed lap {f['first_failed_lap']}: error {f['error_laps']} laps")


if __name__ == "__main__":
    main()
