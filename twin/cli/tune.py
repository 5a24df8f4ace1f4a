"""``python -m tuner`` (also ``python -m twin.run tune``): tune the control gains (Eq. 13) of a robot on a track
by gradient descent on the lap time (Eq. 12).

With no options it tunes v_max, K_B, K_P, K_I, K_D of the default robot on the default track from the default
gains, on one noise seed. With --robust (or --scenario/--seeds/--risk) every step judges the gains over an
envelope of conditions (tyre grip, battery, noise seeds; see tuner.search.envelope) in one batch of laps. At the end the
gains are raced on noise seeds never used in tuning (--held-out), so the generalisation gap shows. Ctrl-C stops
after the current iteration, reports, and writes the best values found so far.
"""

from __future__ import annotations

import argparse
import signal
import sys
import time
from typing import TYPE_CHECKING

from lf_common.files import check_output_file, json_is_ours
from twin.cli import library_values as lib
from twin.cli import options as o
from twin.cli import progress
from twin.cli import twin_options as tw
from twin.cli.guard import run_command
from twin.cli.output import Output
from twin.cli.startup import loading

if TYPE_CHECKING:
    from tuner.search.envelope import Envelope, Risk

HELP = "tune the gains (default: v_max, K_B, K_P, K_I, K_D) by gradient descent on the lap time"


class _StopRequest:
    """The first Ctrl-C asks the search to stop after the current iteration; a second one stops at once."""

    def __init__(self):
        self.requested = False

    def __call__(self, signum, frame):
        if self.requested:
            raise KeyboardInterrupt
        self.requested = True
        print("\nstopping after this iteration (Ctrl-C again to abort)", file=sys.stderr)


class _Stop(Exception):
    pass


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--method", choices=("batch", "sequential"), default="batch",
                   help="batch: gradient and line search as parallel batches; sequential: the paper's one lap at a time")
    o.add_search(p, "a parameter to tune, repeatable (default: control.v_max, kb, kp, ki, kd); any address that can "
                    "differ between the laps of one batch")
    o.add_world(p)
    o.add_values(p, "a fixed model-space parameter, repeatable")
    o.add_seed(p, 0, "the first sensor-noise seed; every point of the search uses the same seeds")
    p.add_argument("--scenario", action="append", metavar="ADDRESS=V1,V2,...",
                   help="judge the gains under each of these values too (repeatable: every combination)")
    p.add_argument("--seeds", type=o.count_type, metavar="N", help="noise seeds per scenario (default 1; --robust: "
                   f"{lib.ROBUST_SEEDS})")
    p.add_argument("--risk", metavar="mean|worst|cvar:ALPHA", help="how the laps of one gain vector add up (default "
                   f"mean; --robust: {lib.ROBUST_RISK})")
    p.add_argument("--robust", action="store_true", help="the realistic envelope of the default robot: "
                   + ", ".join(f"{a} in {{{', '.join(f'{v:g}' for v in vs)}}}" for a, vs in lib.ROBUST_AXES.items())
                   + f", {lib.ROBUST_SEEDS} seeds, {lib.ROBUST_RISK} lap (see tuner.search.envelope for the sources)")
    p.add_argument("--held-out", type=o.number(0, 1000, integer=True), default=20, metavar="N",
                   help="race the final gains on N seeds never used in tuning, in every corner of the envelope")
    p.add_argument("--max-iter", type=o.count_type, default=30, metavar="N", help="iteration cap")
    o.add_workers(p, "laps of a batch (threads)")
    p.add_argument("--threads", dest="workers", type=o.number(0, 1024, integer=True),
                   action=o.deprecated(argparse._StoreAction, "--workers"), help=argparse.SUPPRESS)
    o.add_out(p, "the best values: a gains file (--gains) for control.* parameters, else a parameter file (--params)",
              "FILE.json")
    o.add_db(p, "the tuned gains and their lap")
    o.add_json(p)
    o.add_recording(p, "the tuning run (lap time and parameters per iteration, best lap)")
    o.add_verbose(p, quiet=True)


def add_parser(sub) -> None:
    p = sub.add_parser("tune", help=HELP, description=__doc__)
    add_arguments(p)
    p.set_defaults(run=run)


def envelope_from(args: argparse.Namespace, twin) -> tuple[Envelope, Risk]:
    """The envelope and risk the flags describe: --robust's preset, overridden by --scenario/--seeds/--risk."""
    with loading():
        from tuner.search.envelope import ROBUST_AXES, ROBUST_RISK, ROBUST_SEEDS, Envelope, Risk
        from tuner.search.space import TunerError
        from twin.model.space import ChangeCost

    axes = dict(ROBUST_AXES) if args.robust else {}
    for address, values in o.parse_grid(args.scenario, "--scenario").items():
        axes[address] = values
    for address, values in axes.items():
        p = twin.space.parameter(address)
        if p.cost is ChangeCost.REBUILD:
            raise TunerError(f"--scenario {address}: rebuilds the robot or track, so it cannot vary within one batch")
        for v in values:
            p.check(f"--scenario {address}", v)
    count = args.seeds or (ROBUST_SEEDS if args.robust else 1)
    risk = Risk.parse(args.risk or (ROBUST_RISK if args.robust else "mean"))
    return Envelope.of(axes, range(args.seed, args.seed + count)), risk


def held_out(twin, values: dict, envelope: Envelope, count: int, workers: int, args: argparse.Namespace) -> dict | None:
    """The final values raced on ``count`` seeds never used in tuning, in every corner of the envelope: one batch,
    with a bar of its laps."""
    with loading():
        import numpy as np

        from tuner.search.envelope import held_out_seeds, label
        from twin.core.closed_loop import run_laps

    if count == 0:
        return None
    seeds = held_out_seeds(envelope, count)
    corners = envelope.corners or [{}]
    total = len(corners) * count
    b = progress.bar(args, total, "held-out race", "lap")
    try:
        laps = run_laps(twin, [{**values, **c} for c in corners for _ in seeds], seed=[s for _ in corners for s in seeds],
                        nthread=workers, keep_traces=False, on_chunk=lambda _s, running: b.update(total - running - b.n))
    finally:
        progress.finish(b)
    rows = []
    for j, c in enumerate(corners):
        part = laps[j * count:(j + 1) * count]
        done = [r.lap_time_s for r in part if r.completed]
        rows.append({"scenario": label(c), "values": c, "completed": len(done), "laps": count,
                     "median_lap_time_s": float(np.median(done)) if done else None,
                     "worst_lap_time_s": max(done) if done else None,
                     "failures": sorted({r.failure for r in part if not r.completed})})
    total = sum(r["completed"] for r in rows)
    return {"seeds": [seeds[0], seeds[-1]], "completion_rate": total / (count * len(corners)), "corners": rows}


def run(args: argparse.Namespace) -> int:
    with loading():
        from tuner.history import record_lap
        from tuner.recording import save_tuning
        from tuner.search.envelope import label
        from tuner.search.gradient import DescentOptions, descend, sequential
        from tuner.search.objective import LapObjective
        from tuner.search.space import DEFAULT_BOUNDS, SearchSpace, TunerError, robot_bounds
        from tuner.search.start import rescue_start
        from twin.core.closed_loop import run_laps
        from twin.core.identity import tuned_for
        from twin.model.parameter_files import save_values
        from twin.viz import recording

    out = Output(args.json)
    if args.out:
        check_output_file(args.out, json_is_ours, "parameter file")
    recording.check_targets(args.save, args.view)
    o.check_db(args.db)
    twin = tw.twin_from_args(args)
    searched = args.param or list(DEFAULT_BOUNDS)
    derived = {a: b for a, b in robot_bounds(twin).items() if a in searched}
    if derived != {a: b for a, b in DEFAULT_BOUNDS.items() if a in searched}:
        out.say("search bounds for this robot: " + ", ".join(f"{a}=[{lo:.3g}, {hi:.3g}]" for a, (lo, hi) in derived.items()))
    space = SearchSpace(twin.space, args.param or (), {**derived, **o.parse_bounds(args.bounds)})
    x0 = space.start(twin.space)
    envelope, risk = envelope_from(args, twin)
    objective = LapObjective(twin, space, nthread=args.workers, envelope=envelope, risk=risk)
    stop = _StopRequest()
    previous = signal.signal(signal.SIGINT, stop)
    t0 = time.perf_counter()
    bar = progress.bar(args, args.max_iter, f"tuning ({args.method})", "it")
    iterations = []

    per_iteration = []

    def on_iteration(it):
        iterations.append(it)
        e = objective.at(it.z)
        per_iteration.append({"iteration": it.k, "cost_s": it.cost, "scenarios": objective.by_scenario(e) if e else []})
        bar.update(1)
        bar.set_postfix_str(f"cost {objective.best.cost:.3f} s, {objective.laps} laps")
        if stop.requested:
            raise _Stop

    search = descend if args.method == "batch" else sequential
    interrupted = False
    try:
        z0, note = rescue_start(objective, space.to_unit(x0))
        if note:
            bar.write(f"note: {note}", file=sys.stderr)
        result = search(objective, z0, DescentOptions(max_iter=args.max_iter), on_iteration=on_iteration)
        converged, reason = result.converged, result.reason
        progress.finish(bar)  # converged before the cap: that was the search's real end, so the bar ends full
    except (_Stop, KeyboardInterrupt):
        interrupted, converged, reason = True, False, "interrupted"
    finally:
        bar.close()
        signal.signal(signal.SIGINT, previous)
    wall = time.perf_counter() - t0
    best = objective.best
    if best is None:
        raise TunerError("interrupted before the first lap finished: nothing to report")
    values = space.assignments(best.x)
    hit = [{"address": a, "side": side, "bound": b, "unit": twin.space.parameter(a).unit}
           for a, side, b in space.bounds_hit(best.x)]
    final = best.lap
    held = held_out(twin, values, envelope, args.held_out, args.workers, args)
    summary = {
        "method": args.method, "initial_lap_time_s": objective.first.lap.lap_time_s, "initial_cost_s": objective.first.cost,
        "final_lap_time_s": final.lap_time_s, "final_cost_s": best.cost, "completed": final.completed,
        "iterations": len(iterations), "laps_simulated": objective.laps, "wall_s": wall, "values": values,
        "converged": converged, "reason": reason, "interrupted": interrupted, "seed": args.seed,
        "track": twin.track.name, "out": None, "recording": None, "risk": str(risk),
        "envelope": {"scenarios": [label(sc) for sc in envelope.scenarios], "seeds": list(envelope.seeds)},
        "final_scenarios": objective.by_scenario(best), "per_iteration": per_iteration, "held_out": held,
        "bounds_hit": hit,
        "loads_with": "--gains" if all(a.startswith("control.") for a in values) else "--params",
    }
    if all(a.startswith("control.") for a in values):
        summary["gains"] = values
    if args.out:
        summary["out"] = save_values(args.out, values, method=args.method, track=twin.track.name,
                                     lap_time_s=final.lap_time_s, seed=args.seed, converged=converged,
                                     tuned_for=tuned_for(twin))
    if args.save or args.view:
        twin.update(values)
        best_lap = run_laps(twin, [{}], seed=args.seed)[0]
        summary["recording"] = save_tuning(args.save, args.view, twin, space, iterations, best_lap, per_iteration)
    summary["history"] = o.keep_history(args.db, lambda h: record_lap(
        h, twin, final, "tune", {"values": values, "cost_s": best.cost, "converged": converged, "reason": reason},
        {a: v for a, v in values.items() if a.startswith("control.")}), out)
    out.document(summary)
    t_final = f"{final.lap_time_s:.3f} s" if final.completed else f"not completed ({final.failure})"
    out.say(f"{args.method}: lap {objective.first.cost:.3f} s → {t_final} in {len(iterations)} iterations, "
            f"{objective.laps} laps, {wall:.1f} s ({reason})")
    out.say("values: " + ", ".join(f"{a}={v:.4g}" for a, v in values.items()))
    for h in hit:
        unit = "" if h["unit"] == "-" else f" {h['unit']}"
        out.say(f"bound hit: {h['address']} ended on its {h['side']} bound ({h['bound']:g}{unit}): the best may lie "
                f"beyond it (widen it with --bounds {h['address']}=LO,HI)")
    if len(envelope) > 1:
        out.say(f"envelope: {len(envelope.scenarios)} scenarios × {len(envelope.seeds)} seeds, {risk} lap cost {best.cost:.3f} s")
        for row in summary["final_scenarios"]:
            t = row["lap_times_s"]
            out.say(f"  {row['scenario']}: {row['completed']}/{row['laps']} laps completed"
                    + (f", {min(t):.3f}–{max(t):.3f} s" if t else ""))
    if held and not envelope.axes:  # no envelope: the twin as it is, on new seeds
        row = held["corners"][0]
        med = f", median {row['median_lap_time_s']:.3f} s" if row["median_lap_time_s"] else ""
        out.say(f"held-out seeds {held['seeds'][0]}–{held['seeds'][1]}: {row['completed']}/{row['laps']} laps "
                f"completed{med}")
    elif held:
        out.say(f"held-out seeds {held['seeds'][0]}–{held['seeds'][1]}: {held['completion_rate'] * 100:.0f} % of laps "
                "completed over the envelope's corners")
        for row in held["corners"]:
            med = f", median {row['median_lap_time_s']:.3f} s" if row["median_lap_time_s"] else ""
            out.say(f"  {row['scenario']}: {row['completed']}/{row['laps']}{med}")
    if summary["out"]:
        out.say(f"wrote {summary['out']} (load it with {summary['loads_with']})")
    if summary["recording"]:
        out.say(f"recording: {summary['recording']}")
    return 130 if interrupted else 0


def parser() -> o.Parser:
    """``python -m tuner``'s parser."""
    p = o.Parser(prog="python -m tuner", description=__doc__)
    add_arguments(p)
    return p


def main(argv: list[str] | None = None) -> int:
    """``python -m tuner``."""
    with loading():  # Ctrl-C while the parsers are built or the flags checked: exit 130 at once, no traceback
        args = parser().parse_or_exit_code(argv)
    if isinstance(args, int):
        return args
    return run_command(run, args)
