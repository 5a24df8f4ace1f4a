"""``design``: a design study: rebuild, tune and race every design of a grid over design parameters."""

from __future__ import annotations

import argparse
import time

from lf_common.files import check_output_dir
from twin.cli import options as o
from twin.cli import progress
from twin.cli import twin_options as tw
from twin.cli.library_values import DESIGN_GRID
from twin.cli.output import Output
from twin.cli.startup import loading
from twin.errors import TwinError

HELP = "design study: rebuild, tune and race every design of a grid over design parameters (cad.*, motor.model, …)"


def add_parser(sub) -> None:
    p = sub.add_parser("design", help=HELP, description=(
        "For each design: rebuild the robot, tune the gains from the same start until convergence (or --max-iter: each "
        "design says which), run the tuned gains for --laps laps with different noise seeds. Writes a box plot, a Pareto chart, a table and per-design "
        "gains to --out-dir."))
    default = " ".join(f"{a}={','.join(f'{v:g}' for v in vs)}" for a, vs in DESIGN_GRID.items())
    p.add_argument("--grid", action="append", metavar="ADDRESS=V1,V2,...",
                   help=f"a design parameter and its values, repeatable: cad.*, motor.model (catalogue names), or any "
                   f"model-space address (default: {default})")
    p.add_argument("--param", dest="grid", action=o.deprecated(argparse._AppendAction, "--grid"), help=argparse.SUPPRESS)
    o.add_world(p, robot=False)
    p.add_argument("--set", action="append", metavar="ADDRESS=VALUE", help="a fixed model-space parameter, repeatable")
    p.add_argument("--laps", type=o.count_type, default=20, metavar="N", help="laps per design after tuning, one noise seed each")
    p.add_argument("--max-iter", type=o.count_type, default=30, metavar="N", help="tuning iteration cap per design")
    p.add_argument("--robust", action="store_true", help="tune each design over the robust envelope (as tune --robust)")
    o.add_firmware(p, "each design's laps after tuning (avr or a program file: the laps run on the emulated MCU, "
                   "about 5 s each; the twin's own firmware is tuned on the C loop, which runs the same source; a 3pi "
                   "program keeps its own gains, so its designs are raced on the 3pi, not tuned)")
    o.add_workers(p, "designs (processes)")
    p.add_argument("--cluster", metavar="auto|ray://HOST:PORT", help="run the designs as Ray tasks on a cluster "
                   "(pip install -e '.[cluster]'; auto: the cluster this machine joined with 'ray start'); results "
                   "equal a local run")
    o.add_out_dir(p, "the charts, table and gains", "design_study")
    o.add_json(p)
    o.add_recording(p, "the charts")
    o.add_verbose(p, quiet=True)
    p.set_defaults(run=run)


def _check_firmware(args: argparse.Namespace, values: dict) -> tuple[dict, bool]:
    """What ``--firmware`` adds to the study's base (nothing for the C loop), checked on the base design before any
    work, and whether it is a 3pi program other than the twin's own firmware (then the designs start from the 3pi:
    the values given with --set win)."""
    program, _ = tw.program_from_args(args)  # a bad file, or an --operator script without a 3pi program: one line now
    if args.firmware == "c":
        return {}, False
    with loading():
        from twin.core.digital_twin import DigitalTwin
        from twin.model.motor_setup import MOTOR_MODEL
        from twin.model.robots import THREE_PI

    foreign = program is not None and not program.traced
    if foreign:
        values.update({**THREE_PI.values, MOTOR_MODEL: THREE_PI.motor_model, **values})
    twin = DigitalTwin(track=args.track, track_metres_per_pixel=args.metres_per_pixel)
    twin.update({a: v for a, v in values.items() if a not in o.CATEGORICAL})
    tw.check_program_runs(twin, program)
    return {"firmware": args.firmware if program is None else program.path, "operator": args.operator}, foreign


def run(args: argparse.Namespace) -> int:
    with loading():
        from tuner.studies.design import DEFAULT_GRID, grid, pareto, steps_per_design, study, trend
        from tuner.studies.evidence import describe
        from tuner.studies.report import write_report
        from twin.core.maze import refuse_maze
        from twin.model.environment import load_track
        from twin.model.partial_models import default_space
        from twin.viz import recording

    out = Output(args.json)
    check_output_dir(args.out_dir, "design study folder")  # before any work: refused now, not after the study
    recording.check_targets(args.save, args.view)
    params = o.parse_grid(args.grid) if args.grid else dict(DEFAULT_GRID)
    space = default_space()
    for address, values in params.items():
        if address.startswith("control."):
            raise TwinError(f"--grid {address}: each design's gains are tuned (control.*); vary the robot, its motor "
                            "or its world instead")
        if address not in o.CATEGORICAL:
            parameter = space.parameter(address)  # an unknown address: one-line error
            for v in values:  # outside its range: bad input now, not every design failing later
                parameter.check(f"--grid {address}", v)
    fixed = o.parse_assignments(args.set)
    for address, check in o.CATEGORICAL.items():
        if address in fixed:
            check(fixed[address])  # an unknown name: one line that lists the choices
    space.update({a: v for a, v in fixed.items() if a not in o.CATEGORICAL})  # checked now: bad input, not a failing design
    track, _ = load_track(args.track, space.get("environment.line_width"), space.get("environment.texture_resolution"),
                          args.metres_per_pixel)  # an unknown track or unreadable image: one-line error before any work
    designs = grid(params)
    values = {a: v if a in o.CATEGORICAL else float(v) for a, v in fixed.items()}
    firmware, foreign = _check_firmware(args, values)
    if not foreign:  # the twin's controller tunes every design (and drives them, but for a 3pi program)
        refuse_maze(track, "the twin's controller")
    base = {"track": args.track, "metres_per_pixel": args.metres_per_pixel, "values": values, "robust": args.robust,
            **firmware}
    t0 = time.perf_counter()
    per_design = steps_per_design(args.laps, args.max_iter)
    # counted in tuning iterations and laps, so the first design moves it too; a design that needs fewer (its
    # search converged) takes its unused steps off the total
    bar = progress.bar(args, len(designs) * per_design, f"{len(designs)} designs (tuning iterations, laps)", "step")
    finished = 0

    def on_done(r):
        nonlocal finished
        finished += 1
        if args.cluster:  # a Ray task reports nothing until it ends
            bar.update(per_design)
        bar.set_postfix_str(f"{finished}/{len(designs)} designs, {r.label}: "
                            + (f"{r.median_s:.3f} s" if r.ok else "failed"))

    def on_step(kind: str, n: int) -> None:
        if kind == "done":
            bar.update(n)
        else:
            progress.planned_steps(bar, -n)

    if args.cluster:
        if firmware:
            raise TwinError("--cluster: the nodes get parameter values, not files; a study with --firmware runs locally")
        with loading():
            from tuner.studies.cluster import study_on_ray

        results = study_on_ray(designs, base, args.laps, args.max_iter, args.cluster, on_done=on_done)
    else:
        results = study(designs, base, laps=args.laps, max_iter=args.max_iter, workers=args.workers, on_done=on_done,
                        on_step=None if bar.disable else on_step)
    progress.finish(bar)
    wall = time.perf_counter() - t0
    front = pareto(results)
    trends = [trend(results, a) for a in params]
    meta = {"track": args.track, "grid": {a: list(v) for a, v in params.items()}, "fixed": base["values"],
            "laps_per_design": args.laps, "wall_s": wall, "firmware": args.firmware}
    paths = write_report(args.out_dir, results, front, trends, meta)
    paths["recording"] = recording.save_charts(args.save, args.view, {"lap times": paths["chart"], "Pareto": paths["pareto"]})
    out.document({**meta, "outputs": paths, "trends": trends,
                  "designs": [{"design": r.design, "ok": r.ok, "error": r.error,
                               "median_lap_time_s": r.median_s if r.ok else None, "laps_completed": len(r.lap_times_s),
                               "mean_cross_track_m": r.mean_cross_track_m if r.ok else None, "pareto": on,
                               "gains": r.gains, "converged": r.converged, "search": r.search,
                               "evidence": r.evidence} for r, on in zip(results, front)]})
    for r, on in zip(results, front):
        if r.ok:
            t = sorted(r.lap_times_s)
            spread = f"{t[0]:.3f}–{t[-1]:.3f}" if t else "–"
            out.say(f"{r.label:28s} median {r.median_s:7.3f} s ({spread}, {len(t)}/{len(t) + r.failed_laps} laps), "
                    f"cross-track {r.mean_cross_track_m * 1000:.1f} mm{'  pareto' if on else ''}")
            if not r.converged:
                out.say(f"{'':28s} gains not converged: the search stopped at its {r.search}; these are the best it "
                        "had found (raise --max-iter)")
            if r.evidence:  # (none for a 3pi program's designs: the twin's C loop did not drive them)
                out.say(f"{'':28s} {describe(r.evidence)}")
        else:
            out.say(f"{r.label:28s} failed: {r.error}")
    for t in trends:
        out.say(t)
    stopped = sum(1 for r in results if r.ok and not r.converged)
    if stopped:
        out.say(f"warning: {stopped} of {len(results)} designs stopped at --max-iter {args.max_iter} before their gains "
                "converged: their lap times are not what those designs can reach")
    out.say(f"{len(designs)} designs in {wall:.0f} s; wrote {paths['folder']} (lap_times.png, pareto.png, designs.csv, "
            "designs.json, gains/)")
    return 0
