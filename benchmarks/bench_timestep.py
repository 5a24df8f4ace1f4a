"""The physics step chosen by fidelity: laps at steps from 0.25 ms up against the same laps at 0.25 ms.

For several robots (the default 3pi-class robot, a wide one on faster HP motors, and a robot converted from a URDF
description written here), gains from tuned to poor, tyre grip μ ∈ {0.6, 0.9} and supply ∈ {4.8, 6.0} V, every lap
runs on ``--seeds`` noise seeds at every step; all steps divide the 5 ms control period (whole physics steps per
tick). Per configuration and step, against the 0.25 ms reference with the same seeds (paired):

  * decisions: laps whose completion (completed or not) differs from the reference's;
  * lap time: the median over seeds of the relative change; the seeds' own spread at the reference (max − min,
    relative) says how much the noise alone moves the lap;
  * max cross-track error [mm] and energy [%] (medians over seeds); CPU time per lap at each step.

A configuration is *chaotic* when the noise alone moves it (its seeds split the decision or spread the lap time by
more than 0.1 %): near the grip limit a lap's path depends on the noise. Gains are *raced* (the default, tuned by
the tuner, robust, or moderate by hand) or *poor* (weak steering that weaves 60–80 mm off the line, or too fast for
its steering). The rule (docs/performance.md, "The physics step"): the largest step at which every regular lap of
raced gains, on every robot, moves by at most 0.1 % against 0.25 ms and no decision the seeds agree on changes.
Which laps are regular depends on the seed count, so the verdict does too: 5/3 ms on 5 seeds, 1.25 ms on 10. The
default stays 1 ms, the step that also keeps the tuner's robust answer (docs/performance.md). Chaotic laps and poor
gains are reported beside the rule, against the same 0.25 ms reference: chaotic laps move by more than 0.1 % at
every step above it. ``--convergence`` adds the grip-limited case (robust gains, μ 0.6, 6 V) on 20 seeds down to
0.0625 ms. About 8 min on 2 cores with 5 seeds; 10 seeds and four steps take about 10 min.

  python benchmarks/bench_timestep.py [--seeds 5] [--steps-ms 0.25,0.5,1,1.25,1.6667,2.5] [--convergence] [--quick]
                                      [--json]

``--quick``: one seed, steps 0.5 and 1 ms, μ 0.9 and 6 V only, every tuning stopped after one iteration (for CI: the
script cannot rot; the figures are not the table's).
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import sys
import tempfile
import time
import warnings

import numpy as np

from mjcf.robot_config import RobotConfig
from tuner.search.gradient import DescentOptions, descend
from tuner.search.objective import LapObjective
from tuner.search.space import DEFAULT_BOUNDS, SearchSpace, robot_bounds
from twin.core.closed_loop import run_laps
from twin.core.digital_twin import DigitalTwin
from twin.model.motor_setup import catalogue_motor, motor_for_robot, use_motor

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tests"))
from reference_gains import tuned_gains  # noqa: E402  (the one home of tuned gains)

STEPS_MS = (0.25, 0.5, 1.0, 1.25, 5 / 3, 2.5)
GRIP = [0.6, 0.9]  # --quick: 0.9 only
SUPPLY = [4.8, 6.0]  # --quick: 6.0 only
LAP_TOLERANCE = 0.001  # relative
GAINS = ("control.v_max", "control.kb", "control.kp", "control.ki", "control.kd")
QUICK_TUNING: list[str] = []  # --quick: every tuning stops after one iteration
# deliberately arbitrary gains (not tuned: they span well damped to poor) for the default robot, scaled to other
# robots as the tuner's bounds are (tuner.search.space.robot_bounds)
MODERATE = (1.0, 0.5, 18.6, 0.0, 0.3)  # well damped, 14–20 mm off the line at most
SLOPPY = (1.0, 0.5, 10.0, 0.0, 0.05)  # weak steering, little damping: 60–80 mm off the line in the bends
RECKLESS = (1.2, 1.0, 20.0, 0.0, 0.3)  # fast for its steering: at μ 0.6 on 6 V some seeds circle until the timeout
POOR = ("sloppy", "reckless")

# a ROS-style description with primitives only: 0.25 kg, 21 mm wheels 100 mm apart, a front ball caster
URDF = """<?xml version="1.0"?>
<robot name="bench_bot">
  <link name="base_footprint"/>
  <joint name="base_joint" type="fixed"><parent link="base_footprint"/><child link="base_link"/>
    <origin xyz="0 0 0.021"/></joint>
  <link name="base_link">
    <collision><origin xyz="0.03 0 0.008"/><geometry><box size="0.13 0.08 0.008"/></geometry></collision>
    <inertial><origin xyz="0.02 0 0.008"/><mass value="0.22"/>
      <inertia ixx="1.2e-4" ixy="0" ixz="0" iyy="3.2e-4" iyz="0" izz="4.2e-4"/></inertial></link>
  <joint name="wheel_left_joint" type="continuous"><parent link="base_link"/><child link="wheel_left_link"/>
    <origin xyz="0 0.05 0" rpy="-1.5707963267948966 0 0"/><axis xyz="0 0 1"/></joint>
  <link name="wheel_left_link"><collision><geometry><cylinder radius="0.021" length="0.01"/></geometry></collision>
    <inertial><mass value="0.012"/><inertia ixx="1.4e-6" ixy="0" ixz="0" iyy="1.4e-6" iyz="0" izz="2.6e-6"/></inertial></link>
  <joint name="wheel_right_joint" type="continuous"><parent link="base_link"/><child link="wheel_right_link"/>
    <origin xyz="0 -0.05 0" rpy="1.5707963267948966 0 0"/><axis xyz="0 0 1"/></joint>
  <link name="wheel_right_link"><collision><geometry><cylinder radius="0.021" length="0.01"/></geometry></collision>
    <inertial><mass value="0.012"/><inertia ixx="1.4e-6" ixy="0" ixz="0" iyy="1.4e-6" iyz="0" izz="2.6e-6"/></inertial></link>
  <joint name="caster_joint" type="fixed"><parent link="base_link"/><child link="caster_link"/>
    <origin xyz="0.08 0 -0.015"/></joint>
  <link name="caster_link"><collision><geometry><sphere radius="0.006"/></geometry></collision>
    <inertial><mass value="0.004"/><inertia ixx="6e-8" ixy="0" ixz="0" iyy="6e-8" iyz="0" izz="6e-8"/></inertial></link>
</robot>
"""
MOUNT = ("base_link", (0.085, 0.0, -0.017))  # the line array 4 mm above the floor, 85 mm ahead of the axle


def robots(folder: str) -> dict[str, DigitalTwin]:
    default = DigitalTwin()
    wide = DigitalTwin()
    wide.set("cad.L", 0.055)
    use_motor(wide, catalogue_motor("pololu-hp-6v-30"))
    path = os.path.join(folder, "bench_bot.urdf")
    with open(path, "w") as f:
        f.write(URDF)
    converted = DigitalTwin(robot_urdf=path, robot_config=RobotConfig(sensor_mount=MOUNT))
    use_motor(converted, motor_for_robot(converted, converted.space.get("motor.supply_voltage")).datasheet)
    return {"default": default, "wide HP": wide, "converted": converted}


def scaled(twin: DigitalTwin, gains: tuple[float, ...]) -> dict[str, float]:
    """Gains set for the default robot, scaled to this one as the tuner's bounds are."""
    bounds = robot_bounds(twin)
    return {a: g * bounds[a][1] / DEFAULT_BOUNDS[a][1] for a, g in zip(GAINS, gains)}


def tuned(twin: DigitalTwin) -> dict[str, float]:
    """Plain tuning (the tuner's defaults, seed 0, the twin's own step): gains on the knife edge of one seed."""
    space = SearchSpace(twin.space, (), robot_bounds(twin))
    objective = LapObjective(twin, space, seed=0)
    options = DescentOptions(max_iter=1) if QUICK_TUNING else DescentOptions()
    descend(objective, space.to_unit(space.start(twin.space)), options)
    return space.assignments(objective.best.x)


def robust_gains() -> dict[str, float]:
    """``python -m tuner --robust``'s answer for the default robot (at its default step, 1 ms)."""
    return tuned_gains("--robust", *QUICK_TUNING)


def gain_sets(name: str, twin: DigitalTwin) -> dict[str, dict[str, float]]:
    sets = {"default": {a: twin.space.get(a) for a in GAINS}, "tuned": tuned(twin)}
    if name == "default":
        sets["robust"] = robust_gains()
    sets["moderate"], sets["sloppy"], sets["reckless"] = (scaled(twin, g) for g in (MODERATE, SLOPPY, RECKLESS))
    return sets


def study(twin: DigitalTwin, gains: dict[str, dict[str, float]], steps_ms, seeds: int) -> tuple[list, dict]:
    """Every configuration × seed at every step: (rows, CPU seconds per lap by step)."""
    configs = [(g, mu, u) for g in gains for mu in GRIP for u in SUPPLY]
    laps: dict[float, list] = {}
    cost = {}
    for ms in steps_ms:
        variants = [{**gains[g], "motion.mu": mu, "motor.supply_voltage": u, "motion.timestep": ms * 1e-3}
                    for g, mu, u in configs for _ in range(seeds)]
        run_laps(twin, variants[:1], seed=0, keep_traces=False)  # warm: batch, calibration turn
        c0 = time.process_time()
        laps[ms] = run_laps(twin, variants, seed=[s for _ in configs for s in range(seeds)], keep_traces=False)
        cost[ms] = (time.process_time() - c0) / len(variants)
    rows = []
    ref = laps[steps_ms[0]]
    for k, (g, mu, u) in enumerate(configs):
        part = slice(k * seeds, (k + 1) * seeds)
        r0 = ref[part]
        t0 = [r.lap_time_s for r in r0 if r.completed]
        spread = (max(t0) - min(t0)) / float(np.median(t0)) if t0 else 0.0
        split = 0 < len(t0) < seeds
        for ms in steps_ms[1:]:
            r1 = laps[ms][part]
            both = [(a, b) for a, b in zip(r0, r1) if a.completed and b.completed]
            rows.append({
                "gains": g, "poor": g in POOR, "mu": mu, "supply_v": u, "step_ms": ms, "completed_ref": len(t0),
                "completed": sum(b.completed for b in r1), "flips": sum(a.completed != b.completed for a, b in zip(r0, r1)),
                "seed_spread": spread, "chaotic": split or spread > LAP_TOLERANCE,
                "lap_rel": float(np.median([b.lap_time_s / a.lap_time_s - 1 for a, b in both])) if both else None,
                "xte_mm": 1e3 * float(np.median([b.max_cross_track_m for b in r1]) - np.median([a.max_cross_track_m for a in r0])),
                "energy_rel": float(np.median([b.energy_j / a.energy_j - 1 for a, b in both])) if both else None,
                "lap_ref_s": float(np.median(t0)) if t0 else None,
            })
    return rows, cost


def keeps_fidelity(row: dict) -> bool:
    """The rule, for a regular configuration of raced gains: no decision changes and the lap moves ≤ 0.1 %."""
    return row["flips"] == 0 and (row["lap_rel"] is None or abs(row["lap_rel"]) <= LAP_TOLERANCE)


def ruled(row: dict) -> bool:
    return not row["poor"] and not row["chaotic"]


def convergence(twin: DigitalTwin, robust: dict[str, float], steps_ms, seeds: int = 20) -> list[dict]:
    """The grip-limited lap (robust gains, μ 0.6, 6 V) on ``seeds`` seeds at each step: mean and spread."""
    out = []
    for ms in steps_ms:
        v = {**robust, "motion.mu": 0.6, "motion.timestep": ms * 1e-3}
        laps = run_laps(twin, [v] * seeds, seed=list(range(seeds)), keep_traces=False)
        t = np.array([r.lap_time_s for r in laps if r.completed])
        out.append({"step_ms": ms, "seeds": seeds, "completed": len(t), "mean_s": float(t.mean()),
                    "sd_s": float(t.std(ddof=1))})
    return out


def verdict_of(out: dict, steps: list[float]) -> dict:
    """Per step: the ruled configurations failing the rule and the largest changes of each class; the largest step
    that keeps fidelity (it and every smaller step pass)."""
    verdict = {}
    for ms in steps[1:]:
        rows = [r for rob in out["robots"].values() for r in rob["rows"] if r["step_ms"] == ms]

        def largest(pick):
            return max((abs(r["lap_rel"]) for r in rows if pick(r) and r["lap_rel"] is not None), default=0.0)

        verdict[f"{ms:.4g}"] = {
            "ruled": sum(ruled(r) for r in rows), "failing": sum(ruled(r) and not keeps_fidelity(r) for r in rows),
            "flips": sum(r["flips"] for r in rows if ruled(r)), "flips_chaotic_or_poor": sum(r["flips"] for r in rows if not ruled(r)),
            "max_abs_lap_rel": largest(ruled), "max_abs_lap_rel_poor": largest(lambda r: r["poor"] and not r["chaotic"]),
            "max_abs_lap_rel_chaotic": largest(lambda r: r["chaotic"]),
            "max_abs_xte_mm": max(abs(r["xte_mm"]) for r in rows if ruled(r)),
            "max_abs_energy_rel": max((abs(r["energy_rel"]) for r in rows if ruled(r) and r["energy_rel"] is not None), default=0.0),
            "cpu_s_per_lap": {name: rob["cpu_s_per_lap"][f"{ms:.4g}"] for name, rob in out["robots"].items()},
        }
    passing = [ms for ms in steps[1:] if verdict[f"{ms:.4g}"]["failing"] == 0]
    chosen = max((ms for ms in passing if all(m in passing for m in steps[1:] if m < ms)), default=steps[0])
    return {"verdict": verdict, "largest_step_keeping_fidelity_ms": chosen}


def report(out: dict, steps: list[float]) -> None:
    seeds = out["seeds"]
    print(f"reference {steps[0]:g} ms, {seeds} seeds per configuration; Δ against the reference, paired by seed")
    for name, rob in out["robots"].items():
        print(f"\n{name} (motor electrical time constant {rob['motor_tau_e_ms']:.3f} ms); CPU per lap: "
              + ", ".join(f"{ms} ms {c * 1e3:.0f} ms" for ms, c in rob["cpu_s_per_lap"].items()))
        print(f"  {'gains':9s} {'μ':>4s} {'V':>4s} {'ref lap':>8s} {'spread':>7s} | "
              + " | ".join(f"{ms:>5.3g} ms: Δlap  flips Δxte Δenergy" for ms in steps[1:]))
        for k in range(0, len(rob["rows"]), len(steps) - 1):
            group = rob["rows"][k:k + len(steps) - 1]
            r0 = group[0]
            ref = f"{r0['lap_ref_s']:.3f}" if r0["lap_ref_s"] else "—"
            cells = []
            for r in group:
                lap = f"{r['lap_rel'] * 100:+.3f}%" if r["lap_rel"] is not None else "   —   "
                en = f"{r['energy_rel'] * 100:+.2f}%" if r["energy_rel"] is not None else "  —  "
                mark = "✗" if ruled(r) and not keeps_fidelity(r) else " "
                cells.append(f"{lap:>9s}{mark} {r['flips']:>2d} {r['xte_mm']:+5.1f} {en:>7s}")
            kind = "*" if r0["chaotic"] else ("p" if r0["poor"] else " ")
            print(f"  {r0['gains']:9s} {r0['mu']:4.1f} {r0['supply_v']:4.1f} {ref:>8s} {r0['seed_spread'] * 100:6.2f}%"
                  f"{kind}| " + " | ".join(cells) + f"   ({r0['completed_ref']}/{seeds} done)")
    print("\n* chaotic (seeds split the decision or spread the lap > 0.1 %); p: poor gains; ✗: a ruled lap fails the rule")
    print(f"{'step':>8s} {'ruled fail':>10s} {'flips':>5s} {'max|Δlap|':>9s} {'Δxte':>5s} {'Δenergy':>7s} | "
          f"{'poor':>7s} {'chaotic':>7s} {'flips':>5s} | CPU per lap (default / wide HP / converted)")
    for ms, v in out["verdict"].items():
        cpu = " / ".join(f"{c * 1e3:.0f}" for c in v["cpu_s_per_lap"].values())
        print(f"{ms:>5s} ms {v['failing']:>4d}/{v['ruled']:<5d} {v['flips']:>5d} {v['max_abs_lap_rel'] * 100:8.3f}% "
              f"{v['max_abs_xte_mm']:5.1f} {v['max_abs_energy_rel'] * 100:6.2f}% | {v['max_abs_lap_rel_poor'] * 100:6.3f}% "
              f"{v['max_abs_lap_rel_chaotic'] * 100:6.3f}% {v['flips_chaotic_or_poor']:>5d} | {cpu} ms")
    print(f"largest step keeping fidelity (regular laps of raced gains ≤ 0.1 %, no agreed decision changed): "
          f"{out['largest_step_keeping_fidelity_ms']:.4g} ms")
    if out.get("convergence"):
        print(f"\ngrip-limited lap (robust gains, μ 0.6, 6 V), {out['convergence'][0]['seeds']} seeds: mean lap ± sd")
        first = out["convergence"][0]["mean_s"]
        for c in out["convergence"]:
            print(f"  {c['step_ms']:7.4g} ms: {c['mean_s']:.4f} ± {c['sd_s']:.4f} s ({(c['mean_s'] / first - 1) * 100:+.2f} %), "
                  f"{c['completed']}/{c['seeds']} done")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", type=int, default=5, help="noise seeds per configuration and step")
    ap.add_argument("--steps-ms", default=",".join(f"{s:.6g}" for s in STEPS_MS),
                    help="physics steps [ms], the first is the reference; each must divide the 5 ms control period")
    ap.add_argument("--convergence", action="store_true", help="the grip-limited lap on 20 seeds down to 0.0625 ms")
    ap.add_argument("--quick", action="store_true",
                    help="one seed, steps 0.5 and 1 ms, μ 0.9 and 6 V, one tuning iteration (for CI)")
    ap.add_argument("--json", action="store_true", help="print one JSON object")
    args = ap.parse_args()
    if args.quick:
        args.seeds, args.steps_ms = 1, "0.5,1"
        GRIP[:], SUPPLY[:], QUICK_TUNING[:] = [0.9], [6.0], ["--max-iter", "1"]
    logging.disable(logging.WARNING)
    warnings.filterwarnings("ignore")
    steps = [5 / 3 if abs(float(s) - 5 / 3) < 1e-3 else float(s) for s in args.steps_ms.split(",")]
    out = {"reference_ms": steps[0], "seeds": args.seeds, "robots": {}}
    with tempfile.TemporaryDirectory() as folder:
        for name, twin in robots(folder).items():
            gains = gain_sets(name, twin)
            rows, cost = study(twin, gains, steps, args.seeds)
            motor = twin.motor()
            out["robots"][name] = {"rows": rows, "cpu_s_per_lap": {f"{ms:.4g}": c for ms, c in cost.items()},
                                   "gains": gains, "motor_tau_e_ms": 1e3 * motor.L_M / motor.R_M}
            if args.convergence and name == "default":
                out["convergence"] = convergence(twin, gains["robust"], [0.0625, 0.125] + list(steps))
    out.update(verdict_of(out, steps))
    if args.json:
        print(json.dumps(out))
        return
    report(out, steps)


if __name__ == "__main__":
    main()
