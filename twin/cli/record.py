"""``record``: a stand-in for the physical robot's log: one lap of a twin with hidden parameters, written as
telemetry (lf-telemetry JSON Lines) for ``align --telemetry``."""

from __future__ import annotations

import argparse

from lf_common.files import check_output_file, jsonl_is_ours
from twin.cli import options as o
from twin.cli import twin_options as tw
from twin.cli.output import Output
from twin.cli.startup import loading

HELP = "run one lap of a twin with hidden parameters and write it as robot telemetry (JSON Lines)"


def add_parser(sub) -> None:
    p = sub.add_parser("record", help=HELP, description=HELP + ". The hidden parameters come from --set/--params and "
                       "the robot's own noise seed.")
    o.add_world(p)
    o.add_values(p, "a hidden model-space parameter, repeatable")
    o.add_seed(p, 7, "the robot's noise seed (differs from the twin's 0)")
    p.add_argument("--every", type=o.number(1, 1000, integer=True), default=2, metavar="N",
                   help="one sample every N control ticks")
    o.add_out(p, "the telemetry", "LAP.jsonl", required=True)
    o.add_json(p)
    o.add_verbose(p)
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    with loading():
        from twin.core.closed_loop import run_laps
        from twin.telemetry.jsonl import lap_lines, telemetry_header, write_telemetry

    out = Output(args.json)
    check_output_file(args.out, jsonl_is_ours, "telemetry")
    twin = tw.twin_from_args(args)
    lap = run_laps(twin, [{}], seed=args.seed)[0]
    path = write_telemetry(args.out, lap_lines(lap, telemetry_header(twin, args.track, args.seed), args.every))
    samples = len(lap.trace.records[:: args.every])
    out.document({"out": path, "samples": samples, **lap.summary()})
    what = f"lap {lap.lap_time_s:.3f} s" if lap.completed else f"not completed ({lap.failure})"
    out.say(f"wrote {path}: {what}, {samples} samples")
    return 0
