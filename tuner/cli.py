"""``python -m tuner``: tune the control gains (Eq. 13) of a robot on a track by gradient descent (Eq. 12).

  python -m tuner [--method batch|sequential] [--param ADDRESS]... [--bounds ADDRESS=LO,HI]...
                  [--track NAME|PNG] [--robot URDF] [--gains FILE] [--set ADDRESS=VALUE]... [--seed N]
                  [--max-iter N] [--out gains.json] [--json] [--save tune.rrd] [--view]

With no options it tunes v_max, K_B, K_P, K_I, K_D of the default robot on the default track from the default
gains. Ctrl-C stops after the current iteration, reports, and writes the best gains found so far.
"""

from __future__ import annotations

import argparse
import json
import signal
import sys
import time


from mjcf.cli import run_guarded
from tuner.gradient import DescentOptions, descend, sequential
from tuner.objective import LapObjective
from tuner.space import SearchSpace, TunerError, parse_bounds
from twin.closed_loop import run_laps
from twin.errors import TwinError


class _Interrupt:
    """The first Ctrl-C asks the search to stop after the current iteration; a second one stops at once."""

    def __init__(self):
        self.requested = False

    def __call__(self, signum, frame):
        if self.requested:
            raise KeyboardInterrupt
        self.requested = True
        print("\nstopping after this iteration (Ctrl-C again to abort)", file=sys.stderr)


def cmd_tune(args: argparse.Namespace) -> int:
    from twin.run import _twin  # the twin the shared options describe: track, robot, gains file, --set

    twin = _twin(args)
    space = SearchSpace(twin.space, args.param or (), parse_bounds(args.bounds))
    x0 = space.start(twin.space)
    try:
        options = DescentOptions(max_iter=args.max_iter)
    except ValueError as e:
        raise TunerError(f"--max-iter: {e}") from None
    objective = LapObjective(twin, space, seed=args.seed, nthread=args.threads)
    stop = _Interrupt()
    previous = signal.signal(signal.SIGINT, stop)
    t0 = time.perf_counter()
    from tqdm import tqdm

    bar = tqdm(total=args.max_iter, desc=f"tuning ({args.method})", unit="it", file=sys.stderr, disable=args.quiet or None)

    class Stop(Exception):
        pass

    def on_iteration(it):
        bar.update(1)
        bar.set_postfix_str(f"lap {objective.best.cost:.3f} s, {objective.laps} laps")
        if stop.requested:
            raise Stop

    run = descend if args.method == "batch" else sequential
    iterations = []
    interrupted = False
    try:
        result = run(objective, space.to_unit(x0), options, on_iteration=lambda it: (iterations.append(it), on_iteration(it)))
        converged, reason = result.converged, result.reason
    except (Stop, KeyboardInterrupt):
        interrupted, converged, reason = True, False, "interrupted"
    finally:
        bar.close()
        signal.signal(signal.SIGINT, previous)
    wall = time.perf_counter() - t0
    best = objective.best
    if best is None:
        raise TunerError("interrupted before the first lap finished: nothing to report")
    gains = space.assignments(best.x)
    final = best.lap
    summary = {
        "method": args.method,
        "initial_lap_time_s": objective.first.lap.lap_time_s,
        "initial_cost_s": objective.first.cost,
        "final_lap_time_s": final.lap_time_s,
        "final_cost_s": best.cost,
        "completed": final.completed,
        "iterations": len(iterations),
        "laps_simulated": objective.laps,
        "wall_s": wall,
        "gains": gains,
        "converged": converged,
        "reason": reason,
        "interrupted": interrupted,
        "seed": args.seed,
        "track": twin.track.name,
    }
    if args.out:
        from twin.gains import save_gains

        summary["out"] = save_gains(args.out, gains, method=args.method, track=twin.track.name,
                                    lap_time_s=final.lap_time_s, seed=args.seed, converged=converged)
    if args.save or args.view:
        import os
        import tempfile

        from tuner.recording import save_tuning
        from twin import recording

        twin.update(gains)
        best_lap = run_laps(twin, [{}], seed=args.seed)[0]
        out = args.save or os.path.join(tempfile.mkdtemp(prefix="twin-tune-"), "tune.rrd")
        summary["recording"] = save_tuning(out, twin, space, iterations, best_lap)
        if args.view:
            recording.view([summary["recording"]])
    if args.json:
        print(json.dumps(summary))
    else:
        t_final = f"{final.lap_time_s:.3f} s" if final.completed else f"not completed ({final.failure})"
        print(f"{args.method}: lap {objective.first.cost:.3f} s → {t_final} in {len(iterations)} iterations, "
              f"{objective.laps} laps, {wall:.1f} s ({reason})")
        print("gains: " + ", ".join(f"{a}={v:.4g}" for a, v in gains.items()))
        if args.out:
            print(f"wrote {summary['out']}")
        if summary.get("recording"):
            print(f"recording: {summary['recording']}")
    return 130 if interrupted else 0


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m tuner", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--method", choices=("batch", "sequential"), default="batch",
                   help="batch: gradient and line search as parallel batches; sequential: the paper's one lap at a time")
    p.add_argument("--param", action="append", metavar="ADDRESS",
                   help="a parameter to tune, repeatable (default: control.v_max, kb, kp, ki, kd)")
    p.add_argument("--bounds", action="append", metavar="ADDRESS=LO,HI", help="search bounds of a tuned parameter")
    p.add_argument("--track", default="default", help="built-in track name or a PNG")
    p.add_argument("--metres-per-pixel", type=float, help="scale of a PNG track without DPI metadata [m]")
    p.add_argument("--robot", help="a diff-drive URDF instead of the generated robot")
    p.add_argument("--gains", metavar="FILE.json", help="start from these gains")
    p.add_argument("--set", action="append", metavar="ADDRESS=VALUE", help="fixed model-space parameter, repeatable")
    p.add_argument("--seed", type=int, default=0, help="sensor-noise seed, shared by every lap")
    p.add_argument("--max-iter", type=int, default=30, help="iteration cap")
    p.add_argument("--threads", type=int, default=0, help="batch threads (0: all cores)")
    p.add_argument("--out", metavar="GAINS.json", help="write the best gains (loadable by twin.run lap --gains)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--save", metavar="TUNE.rrd", help="rerun recording: parameters and lap time per iteration, best lap")
    p.add_argument("--view", action="store_true", help="open the recording in the rerun viewer")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    p.add_argument("-v", "--verbose", action="store_true")
    p.set_defaults(func=cmd_tune)
    return p


def main(argv: list[str] | None = None) -> int:
    args = parser().parse_args(argv)
    if args.seed < 0:
        print(f"error: --seed: must be >= 0, got {args.seed}", file=sys.stderr)
        return 2
    if args.max_iter < 1:
        print(f"error: --max-iter: must be >= 1, got {args.max_iter}", file=sys.stderr)
        return 2
    return run_guarded(args.func, args, errors=(TwinError,))
