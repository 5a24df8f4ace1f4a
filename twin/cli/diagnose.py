"""``diagnose``: a robot slower (or faster) than its twin: which single change explains it best, ranked."""

from __future__ import annotations

import argparse
import dataclasses
import sys

from twin.cli import options as o
from twin.cli import progress
from twin.cli import twin_options as tw
from twin.cli.library_values import DIAGNOSE_CANDIDATES
from twin.cli.output import Output
from twin.cli.startup import loading
from twin.errors import TwinError

HELP = "rank the likely causes of a lap time the twin does not reproduce (grip, battery, motor, payload)"


def add_parser(sub) -> None:
    p = sub.add_parser("diagnose", help=HELP, description=HELP + ". For each candidate: the value that explains the "
                       "measurement, how far it is from nominal, and whether it lies in the documented physical range; "
                       "with --telemetry, how well that value reproduces the run's encoder traces. Exit status 1 when "
                       "no candidate explains it.")
    p.add_argument("--measured-lap-time", type=o.number(0.0, 3600.0, lo_open=True), metavar="S",
                   help="the robot's lap time [s] (default: the telemetry's)")
    p.add_argument("--telemetry", metavar="LAP.jsonl", help="a recorded run: ranks the causes by the encoder traces too")
    p.add_argument("--candidate", action="append", metavar="ADDRESS",
                   help="a possible cause, repeatable (default: the physical parameters that move the lap time most, "
                   "from this twin's learned influences (graph --learn); without them "
                   f"{', '.join(DIAGNOSE_CANDIDATES)})")
    o.add_world(p, track_default=None)
    o.add_values(p)
    o.add_seed(p, 0, "the twin's noise seed")
    o.add_workers(p, "laps of a batch (threads)")
    o.add_json(p)
    o.add_verbose(p, quiet=True)
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    out = Output(args.json)
    if args.measured_lap_time is None and args.telemetry is None:
        raise TwinError("diagnose: give --measured-lap-time SECONDS, --telemetry FILE.jsonl, or both")
    with loading():
        from tuner.align.diagnose import default_candidates, diagnose
        from twin.telemetry.jsonl import read_telemetry

    tel = read_telemetry(args.telemetry) if args.telemetry else None
    track = args.track or (tel.header.get("track") if tel else None) or "default"
    twin = tw.twin_from_args(args, track=track)
    if tel is not None and not args.gains and tel.gains:
        fixed = o.parse_assignments(args.set)
        twin.update({a: v for a, v in tel.gains.items() if a not in fixed})
    candidates, source = (args.candidate, "given (--candidate)") if args.candidate else default_candidates(twin)
    out.say(f"candidates: {source}")
    for a in candidates:
        twin.space.parameter(a)  # unknown address: one line before any lap
    # a step per candidate's alignment, and the joint fit of the best two with telemetry (if two explain it)
    bar = progress.bar(args, len(candidates) + (tel is not None), "diagnosis (candidates, joint fit)", "step")

    def on_candidate(d) -> None:
        bar.write(f"  {d.address}: {d.message}", file=sys.stderr if args.json else sys.stdout)
        bar.update(1)

    try:
        report = diagnose(twin, args.measured_lap_time, candidates, tel, seed=args.seed, nthread=args.workers,
                          on_candidate=on_candidate)
    finally:
        progress.finish(bar)
    doc = {"measured_lap_time_s": report.measured_lap_time_s, "nominal_lap_time_s": report.nominal_lap_time_s,
           "candidates": [dataclasses.asdict(d) for d in report.candidates], "skipped": list(report.skipped),
           "candidates_from": source,
           "joint": None}
    if report.joint is not None:
        doc["joint"] = {"parameters": [p.__dict__ for p in report.joint.parameters],
                        "rms_wheel_speed_radps": report.joint.rms_wheel_radps}
    out.document(doc)
    nominal = f"{report.nominal_lap_time_s:.3f} s" if report.nominal_lap_time_s else "no lap"
    out.say(f"measured {report.measured_lap_time_s:.3f} s; the twin as it is: {nominal}")
    out.say(f"{'rank':>4}  {'cause':52s} {'value':>10} {'95 % interval':>21} {'change':>8}  {'plausible range':>20}"
            + ("  trace rms" if tel is not None else ""))
    for i, d in enumerate(report.candidates, start=1):
        if not d.explained:
            out.say(f"{i:>4}  {d.cause + ' (' + d.address + ')':52s} {'–':>10} {'':>21} {'':>8}  does not explain it")
            continue
        rng = f"[{d.plausible_range[0]:.3g}, {d.plausible_range[1]:.3g}]" + ("" if d.plausible else " ✗")
        rms = f"  {d.trace_rms_radps:.2f} rad/s" if d.trace_rms_radps is not None else ""
        ci = f"[{d.ci95[0]:.4g}, {d.ci95[1]:.4g}]" if d.ci95 else "not pinned"
        out.say(f"{i:>4}  {d.cause + ' (' + d.address + ')':52s} {d.value:>10.4g} {ci:>21} {d.change * 100:>+7.1f}%  "
                f"{rng:>20}{rms}")
    for s in report.skipped:
        out.say(f"skipped {s}")
    if report.joint is not None:
        for p in report.joint.parameters:
            ci = f"[{p.ci95[0]:.4g}, {p.ci95[1]:.4g}]" if p.ci95 is not None else "no interval"
            out.say(f"jointly: {p.address} = {p.value:.4g} {ci}: {p.note}")
    return 0 if any(d.explained for d in report.candidates) else 1
