"""Start-up: the CPU time a command takes to show its ``--help`` or to refuse a bad flag, against ``python -c pass``.

Every command of ``python -m twin.run`` (and ``python -m tuner``) runs in a fresh process twice: with ``--help``, and
with a bad flag it must refuse (``--seed abc`` where the command has a seed, else a flag it does not know). Each
child's CPU time (user + system, from ``getrusage(RUSAGE_CHILDREN)`` around it) is the median of ``--runs`` runs,
interleaved round by round with a bare ``python -c pass`` measured the same way, so a busy machine weighs on both
sides. The target (issue 37): at most 0.3 s of CPU above ``python -c pass`` for every one; the libraries (MuJoCo,
NumPy, SciPy, trimesh, rerun, matplotlib, SQLAlchemy, …) load only when a command does its work.

A help that does not exit 0, or a refusal that does not exit 2 with one ``error: …`` line, is reported and makes the
exit status 1.

Then the re-tune of ``live --act`` (issue 37: median within one lap's real time on 2 cores): an emulated robot in
lockstep whose grip wears (μ 0.84 → 0.6 over 16 laps, the gains ``tests/test_act.py`` holds on purpose, which fail
inside that range), watched by ``live --act --act-every 3``: each re-tune's wall time against the robot's median
lap, the changes and the laps that failed (``--no-retune``: start-up only).

  python benchmarks/bench_startup.py [--runs 5] [--no-retune] [--quick] [--json]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time

from twin.cli import main as front_door

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tests"))
from reference_gains import PLAIN_HELD  # noqa: E402  (the gains the tests hold fixed)

PY = sys.executable
TARGET_EXCESS_S = 0.3  # [s] CPU above a bare interpreter (issue 37)
QUICK = ("lap", "tune", "live", "python -m tuner")  # --quick: the CLI's heaviest modules before issue 37
ACT_GAINS = PLAIN_HELD  # the re-tune's robot: test_act's gains (held on purpose: they fail inside the drift's range)
RETUNE_LAPS, RETUNE_DRIFT = 16, "motion.mu=0.84:0.6@{laps}"


def retune_times(laps: int) -> dict:
    """``emulate --lockstep`` with a wearing grip, watched by ``live --act``: each re-tune's wall time [s]."""
    from tuner.history import log_laps

    flags = [w for a, v in ACT_GAINS.items() for w in ("--set", f"{a}={v!r}")]
    run = [PY, "-m", "twin.run"]
    with tempfile.TemporaryDirectory(prefix="bench-retune-") as folder:
        emu = subprocess.Popen([*run, "emulate", "--tcp", "0", "--speed", "1000", "--laps", str(laps), "--drift",
                                RETUNE_DRIFT.format(laps=laps), "--lockstep", "--json", *flags], cwd=folder,
                               stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
        try:
            url = json.loads(emu.stdout.readline())["link"]
            t0 = time.monotonic()
            live = subprocess.run([*run, "live", "--port", url, "--act", "--act-every", "3", "--laps", str(laps),
                                   "--json", *flags], cwd=folder, capture_output=True, text=True, timeout=900)
            wall = time.monotonic() - t0
        finally:
            emu.wait(timeout=60)
        doc = json.loads(live.stdout)
        robot = log_laps(os.path.join(folder, doc["log"]))
    times = [t.lap_time_s for t in robot if t.lap_time_s is not None]
    walls = [a["wall_s"] for a in doc["actions"] if a["kind"] == "retune"]
    return {"laps": laps, "drift": RETUNE_DRIFT.format(laps=laps), "retune_wall_s": walls,
            "median_s": statistics.median(walls) if walls else None, "max_s": max(walls) if walls else None,
            "robot_lap_s": statistics.median(times) if times else None,
            "in_time": [a.get("in_time") for a in doc["actions"] if a["kind"] == "retune"],
            "changes": [c["status"] for c in doc["changes"]], "failed_laps": sum(t.lap_time_s is None for t in robot),
            "reconnects": doc.get("reconnects"), "wall_s": round(wall, 1), "exit": live.returncode}


def cases() -> list[dict]:
    """(name, argv, expected exit status) for each command's --help and one refusal."""
    top = front_door.parser()
    commands = {name: p for a in top._actions if isinstance(a, argparse._SubParsersAction) for name, p in a.choices.items()}
    out = []
    for name, p in [*commands.items(), ("python -m tuner", commands["tune"])]:
        prefix = ["-m", "tuner"] if name == "python -m tuner" else ["-m", "twin.run", name]
        has_seed = any("--seed" in a.option_strings for a in p._actions)
        bad = ["--seed", "abc"] if has_seed else ["--no-such-flag"]
        out.append({"command": name, "kind": "help", "argv": [PY, *prefix, "--help"], "exit": 0})
        out.append({"command": name, "kind": "refusal", "argv": [PY, *prefix, *bad], "exit": 2})
    return out


def measure(argv: list[str]) -> tuple[float, float, int, str]:
    """One run of ``argv``: (CPU s of the child, wall s, exit status, stderr)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    with tempfile.TemporaryFile() as err:
        status = subprocess.run(argv, stdout=subprocess.DEVNULL, stderr=err, cwd=tempfile.gettempdir()).returncode
        wall = time.perf_counter() - t0
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        err.seek(0)
        text = err.read().decode(errors="replace")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return cpu, wall, status, text


def problem(case: dict, status: int, stderr: str) -> str | None:
    """Why a run did not end as it must (None: it did)."""
    if status != case["exit"]:
        return f"exit status {status}, not {case['exit']}: {stderr.strip()[-300:]}"
    lines = [line for line in stderr.splitlines() if line.strip()]
    if case["kind"] == "refusal" and (len(lines) != 1 or not lines[0].startswith("error: ")):
        return f"not one 'error:' line: {stderr.strip()[-300:]}"
    return None


def run(selected: list[dict], runs: int) -> dict:
    baseline = {"cpu": [], "wall": []}
    for case in selected:
        case.update(cpu=[], wall=[], problem=None)
    for round_ in range(runs + 1):  # round 0 warms the caches (bytecode, page cache) and is not counted
        cpu, wall, _, _ = measure([PY, "-c", "pass"])
        if round_:
            baseline["cpu"].append(cpu)
            baseline["wall"].append(wall)
        for case in selected:
            cpu, wall, status, stderr = measure(case["argv"])
            case["problem"] = case["problem"] or problem(case, status, stderr)
            if round_:
                case["cpu"].append(cpu)
                case["wall"].append(wall)
    base_cpu = statistics.median(baseline["cpu"])
    rows = []
    for case in selected:
        cpu = statistics.median(case["cpu"])
        rows.append({"command": case["command"], "kind": case["kind"], "argv": case["argv"][1:], "cpu_s": cpu,
                     "wall_s": statistics.median(case["wall"]), "excess_s": cpu - base_cpu,
                     "ratio": cpu / base_cpu if base_cpu > 0 else None,
                     "within_target": cpu - base_cpu <= TARGET_EXCESS_S, "problem": case["problem"]})
    return {"python": PY, "runs": runs, "baseline": {"argv": ["-c", "pass"], "cpu_s": base_cpu,
                                                     "wall_s": statistics.median(baseline["wall"])},
            "target_excess_s": TARGET_EXCESS_S, "cases": rows,
            "all_within_target": all(r["within_target"] for r in rows),
            "worst_excess_s": max(r["excess_s"] for r in rows)}


def report(doc: dict) -> None:
    b = doc["baseline"]
    print(f"python -c pass: {b['cpu_s'] * 1000:.0f} ms CPU, {b['wall_s'] * 1000:.0f} ms wall "
          f"(median of {doc['runs']}; {doc['python']})")
    print(f"{'command':18s} {'run':8s} {'CPU ms':>8s} {'above':>8s} {'ratio':>6s} {'wall ms':>8s}  target ≤ "
          f"{doc['target_excess_s'] * 1000:.0f} ms above")
    for r in doc["cases"]:
        verdict = "met" if r["within_target"] else "NOT met"
        print(f"{r['command']:18s} {r['kind']:8s} {r['cpu_s'] * 1000:8.0f} {r['excess_s'] * 1000:8.0f} "
              f"{r['ratio']:6.2f} {r['wall_s'] * 1000:8.0f}  {verdict}")
        if r["problem"]:
            print(f"  problem: {r['problem']}")
    print(f"worst: {doc['worst_excess_s'] * 1000:.0f} ms above python -c pass; target "
          f"{'met' if doc['all_within_target'] else 'NOT met'} for every command")
    r = doc.get("retune")
    if r:
        within = r["median_s"] is not None and r["robot_lap_s"] is not None and r["median_s"] <= r["robot_lap_s"]
        print(f"re-tune (live --act, emulate --lockstep, {r['drift']}): {len(r['retune_wall_s'])} re-tunes, wall "
              f"median {r['median_s']} s, max {r['max_s']} s against a {r['robot_lap_s']:.2f} s lap "
              f"({'within' if within else 'NOT within'} one lap); changes {r['changes']}; {r['failed_laps']} of "
              f"{r['laps']} laps failed; {r['reconnects']} reconnects; {r['wall_s']} s wall")


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--runs", type=int, metavar="N", help="runs of each case; the median counts (default 5; --quick: 3)")
    p.add_argument("--quick", action="store_true", help=f"only {', '.join(QUICK)} (for CI)")
    p.add_argument("--no-retune", action="store_true", help="start-up only, no re-tune run")
    p.add_argument("--json", action="store_true", help="print one JSON document on stdout")
    args = p.parse_args()
    runs = args.runs or (3 if args.quick else 5)
    if runs < 1:
        p.error("--runs: at least 1")
    selected = [c for c in cases() if not args.quick or c["command"] in QUICK]
    doc = run(selected, runs)
    if not args.no_retune:
        doc["retune"] = retune_times(8 if args.quick else RETUNE_LAPS)
    if args.json:
        print(json.dumps(doc, indent=1))
    else:
        report(doc)
    return 1 if any(r["problem"] for r in doc["cases"]) or (doc.get("retune") or {}).get("exit", 0) else 0


if __name__ == "__main__":
    sys.exit(main())
