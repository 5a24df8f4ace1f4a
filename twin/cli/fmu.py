"""``fmu``: the twin as a Co-Simulation FMU (FMI 2.0 or 3.0, linux64) for a co-simulation tool: the plant (motor
voltages in; pose, wheel speeds, line sensors and line position out) or the closed loop (the firmware drives; lap
time, status, cross-track error, pose and motor voltages out). Self-contained: the world, its track texture and
MuJoCo's library inside, built from the same C core as ``lap``; no Python needed to run it."""

from __future__ import annotations

import argparse

from twin.cli import options as o
from twin.cli import twin_options as tw
from twin.cli.library_values import FMU_CLOSED_LOOP, FMU_KINDS, FMU_PLANT
from twin.cli.output import Output
from twin.cli.startup import loading

HELP = "export the twin as a Co-Simulation FMU (FMI 2 or 3, linux64): the plant, or the closed loop with its firmware"


def add_parser(sub) -> None:
    p = sub.add_parser("fmu", help=HELP, description=__doc__)
    o.add_out(p, "the FMU", "F.fmu", required=True)
    p.add_argument("--kind", choices=FMU_KINDS, default=FMU_CLOSED_LOOP, help=f"{FMU_PLANT}: voltages in, the robot's "
                   f"state and sensors out; {FMU_CLOSED_LOOP}: the firmware drives, the lap's results out")
    p.add_argument("--fmi", type=int, choices=(2, 3), default=2, help="FMI version of the FMU")
    o.add_world(p)
    o.add_values(p, "a model-space parameter (see 'graph'), repeatable; the FMU's parameters start at these values")
    o.add_seed(p, 0, "the seed parameter's start value (the same seed as lap --seed gives the same lap)")
    p.add_argument("--lap-timeout", type=o.number(0.0, 3600.0, lo_open=True), default=60.0, metavar="SIM_S",
                   help="start value of the lap_timeout parameter: a lap not done by then ends as 'timeout'")
    o.add_json(p)
    o.add_verbose(p)
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    with loading():
        from twin.core.lap import LapLimits
        from twin.fmi import export_fmu

    out = Output(args.json)
    twin = tw.twin_from_args(args)
    warning = tw.gains_warning(args, twin)
    fmu = export_fmu(twin, args.out, args.kind, args.fmi, args.seed, LapLimits(timeout_s=args.lap_timeout))
    out.document({**fmu.summary(), "track": twin.track.name, "seed": args.seed, "gains_warning": warning})
    out.say(f"wrote {fmu.path}: {fmu.kind} FMU, FMI {fmu.fmi_version}.0 Co-Simulation for linux64, "
            f"{fmu.variables} variables ({fmu.parameters} parameters), {fmu.size_bytes / 1e6:.1f} MB")
    out.say(f"robot on track {twin.track.name}; seed {args.seed}; model identifier {fmu.model_identifier}")
    return 0
