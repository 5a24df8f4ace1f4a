"""``graph``: the common model space: models, ports, parameters (value, unit, change cost) and relations; with
``--learn``, the relations measured from batches of laps (global sensitivity) against the declared ones."""

from __future__ import annotations

import argparse

from lf_common.errors import LineFollowerError
from lf_common.files import check_output_dir
from twin.cli import options as o
from twin.cli import progress
from twin.cli import twin_options as tw
from twin.cli.library_values import SENSITIVITY_MAX_SOBOL, SENSITIVITY_SAMPLES, SENSITIVITY_TRAJECTORIES
from twin.cli.output import Output
from twin.cli.startup import loading
from twin.errors import TwinError

HELP = "print the common model space: models, ports, parameters and relations (--learn: measure them)"
OUT_DIR = "learned_graph"


def add_parser(sub) -> None:
    p = sub.add_parser("graph", help=HELP, description=HELP + " (paper §2, §3.8). With --learn: global sensitivity "
                       "from batches of laps (SALib): Morris screening over every parameter a batch can vary, each over "
                       "its documented physical range, then Sobol' indices for those that matter, for the lap time, "
                       "completion, energy and cross-track error (where laps fail: completion on its own, the others "
                       "over the completed laps with Borgonovo's δ; nothing is written in for a failed lap); the learned graph against the declared one (table, "
                       f"{OUT_DIR}/learned_graph.png, indices.png, influences.csv, learned_graph.json). A default "
                       "analysis is kept for this twin, where diagnose and align find it. It runs "
                       f"{SENSITIVITY_TRAJECTORIES} (k + 1) + N (k' + 2) laps for k parameters of which k' ≤ "
                       f"{SENSITIVITY_MAX_SOBOL} matter (the default robot: at most 2788 laps, a few minutes on 2 cores).")
    o.add_world(p)
    o.add_values(p)
    p.add_argument("--learn", action="store_true", help="measure the relations from laps (global sensitivity)")
    o.add_search(p, "a parameter to vary, repeatable (default: every one a batch can vary, each over its documented "
                    "physical range)")
    p.add_argument("--samples", type=o.number(8, 2**20, integer=True), metavar="N",
                   help=f"Saltelli's base sample for the Sobol' indices, a power of two (default {SENSITIVITY_SAMPLES}): "
                        "N × (k + 2) laps for k parameters that matter")
    o.add_seed(p, 0, "the laps' noise seed and the analysis' sampling seed (same seed, bit-identical indices)")
    o.add_workers(p, "laps of each batch (threads)")
    p.add_argument("--out-dir", metavar="DIR", help=f"with --learn, write the tables and charts into this folder (new, "
                   f"empty, or one this program wrote; default {OUT_DIR})")
    o.add_json(p)
    o.add_recording(p, "the learned graph and its indices")
    o.add_verbose(p, quiet=True)
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    out = Output(args.json)
    if not args.learn:
        given = [f for f, v in (("--param", args.param), ("--bounds", args.bounds), ("--samples", args.samples),
                                ("--out-dir", args.out_dir), ("--save", args.save), ("--view", args.view)) if v]
        if given:
            raise TwinError(f"{given[0]}: goes with --learn")
        space = tw.twin_from_args(args).space
        out.document(space.to_dict())
        if not args.json:
            out.say(space.describe())
        return 0
    return _learn(args, out)


def _learn(args: argparse.Namespace, out: Output) -> int:
    with loading():
        from tuner.sensitivity import (check_samples, chosen_factors, compare, document, learn, store, table,
                                       write_folder)
        from tuner.sensitivity.precision import TOO_FEW
        from tuner.sensitivity.laps import SAMPLES
        from twin.viz import recording

    out_dir = args.out_dir or OUT_DIR
    check_output_dir(out_dir, "learned graph folder")
    recording.check_targets(args.save, args.view)
    samples = check_samples(args.samples or SAMPLES)
    if args.bounds and not args.param:
        raise TwinError("--bounds: goes with --param (the default analysis varies each parameter over its physical range)")
    twin = tw.twin_from_args(args)
    warning = tw.gains_warning(args, twin)
    factors = chosen_factors(twin.space, args.param, o.parse_bounds(args.bounds, args.param)) if args.param else None
    bar = progress.bar(args, 0, "laps", "lap")

    def on_stage(name: str, runs: int) -> None:
        bar.set_description(name)
        progress.planned_steps(bar, runs)

    try:
        analysis = learn(twin, factors, samples=samples, seed=args.seed, nthread=args.workers, on_stage=on_stage,
                         on_laps=bar.update)
    finally:
        progress.finish(bar)
    relations = compare(twin.space, analysis)
    title = f"learned graph: {twin.track.name} track, {analysis.extra['laps']} laps, seed {args.seed}"
    files = write_folder(out_dir, twin.space, analysis, relations, title)
    files["recording"] = recording.save_charts(args.save, args.view, {"learned graph": files["graph_png"],
                                                                      "Sobol' indices": files["indices_png"]})
    stored, why = None, "a chosen --param set is not kept for diagnose and align (only the default analysis is)"
    if factors is None and samples < SAMPLES:  # (its intervals are too wide to steer diagnose and align)
        why = (f"an analysis with fewer --samples than the default {SAMPLES} is not kept for diagnose and align (only "
               "the default analysis, or a larger one, is)")
    elif factors is None:
        try:
            stored, why = store(twin, analysis), "kept for diagnose and align"
        except LineFollowerError as e:
            why = f"not kept: {e}"
    out.document({**document(twin.space, analysis, relations), "files": files, "stored": stored,
                  "gains_warning": warning})
    for line in table(twin.space, analysis, relations):
        out.say(line)
    for line in analysis.notes:
        if not line.startswith(TOO_FEW):  # those close the output, as warnings
            out.say(f"note: {line}")
    for o_name in analysis.outputs:
        out.say(governors(analysis, o_name))
    x = analysis.extra
    out.say(f"{x['laps']} laps ({analysis.morris_runs} Morris, {analysis.sobol_runs} Sobol'), "
            f"{100 * x['completion_rate']:.1f} % completed, in {x['wall_s']:.0f} s ({x['cpu_s']:.0f} s CPU); "
            f"wrote {files['folder']}" + (f" and {files['recording']}" if files["recording"] else ""))
    out.say(f"learned influences: {why}" + (f" ({stored})" if stored else ""))
    for line in analysis.notes:
        if line.startswith(TOO_FEW):
            out.warn(line)
    return 0


def governors(analysis, output: str) -> str:
    """What measurably governs one output (:attr:`Influence.measured`), the largest index first; or why nothing is
    named."""
    with loading():
        from tuner.sensitivity.precision import TOO_FEW

    measured = sorted((i for i in analysis.influences if i.output == output and i.measured), key=lambda i: -i.index)
    flagged = any(n.startswith(f"{TOO_FEW}: {output}") for n in analysis.notes)
    if measured:
        return f"{output} is governed by " + ", ".join(
            f"{i.parameter} ({i.index_name} {i.index:.2f} [{i.index_interval[0]:.2f}, {i.index_interval[1]:.2f}])"
            for i in measured[:3]) + (" (too few samples for these to mean much: see the warning)" if flagged else "")
    indexed = any(i.output == output and i.index is not None for i in analysis.influences)
    return (f"{output}: no parameter measurably governs it" +
            (" (every index below 0.05 or its interval reaching its floor)" if indexed else " (no indices measured)"))
