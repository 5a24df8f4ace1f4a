"""``python -m mjcf`` (also ``python -m twin.run generate|convert``): the parametric robot as URDF, or any
differential-drive URDF as MJCF on a textured track."""

from __future__ import annotations

import argparse
import os

from lf_common.files import check_output_file, first_line_is_ours, output_dir
from mjcf.design import RobotDesign
from mjcf.errors import MjcfError
from twin.cli import options as o
from twin.cli import twin_options as tw
from twin.cli.guard import run_command
from twin.cli.output import Output
from twin.cli.startup import loading

GENERATE_HELP = "write the parametric robot's URDF and meshes into a folder"
CONVERT_HELP = "convert a differential-drive URDF to MJCF on a track"


def add_generate(sub) -> None:
    g = sub.add_parser("generate", help=GENERATE_HELP, description=GENERATE_HELP + " (robot.urdf + meshes/*.stl).")
    o.add_out_dir(g, "robot.urdf and meshes/ (required)", None)
    g.add_argument("-o", "--out", dest="out_dir", action=o.deprecated(argparse._StoreAction, "--out-dir"),
                   help=argparse.SUPPRESS)
    g.add_argument("--set", action="append", metavar="cad.NAME=VALUE", help="a design parameter, repeatable")
    o.add_json(g)
    o.add_verbose(g)
    g.set_defaults(run=run_generate)


def add_convert(sub) -> None:
    c = sub.add_parser("convert", help=CONVERT_HELP, description=CONVERT_HELP + "; meshes and the floor texture go "
                       "to <stem>_assets/ beside the XML.")
    c.add_argument("urdf", metavar="DESCRIPTION", help="robot description: .urdf, .xacro or .urdf.xacro (relative and "
                   "package:// mesh paths are resolved)")
    o.add_out(c, "the MJCF (assets in <stem>_assets/ beside it)", "WORLD.xml", required=True)
    o.add_world(c, robot=False)
    o.add_description(c)
    o.add_json(c)
    o.add_verbose(c)
    c.set_defaults(run=run_convert)


def _design(assignments: dict) -> RobotDesign:
    with loading():
        from twin.model.partial_models import default_space

    space = default_space()
    values = {}
    for address, value in assignments.items():
        if not address.startswith("cad."):
            raise MjcfError(f"{address}: not a CAD parameter; known: {', '.join(a for a in space.addresses if a.startswith('cad.'))}")
        values[address[4:]] = space.parameter(address).check(address, value)
    return RobotDesign(**values)


def run_generate(args: argparse.Namespace) -> int:
    out = Output(args.json)
    if not args.out_dir:
        raise MjcfError("generate: give the folder to write with --out-dir DIR")
    with loading():
        from mjcf.cad import write_robot

    design = _design(o.parse_assignments(args.set))
    with output_dir(args.out_dir, "robot folder") as tmp:
        write_robot(design, tmp)
    urdf = os.path.join(os.path.abspath(args.out_dir), "robot.urdf")
    out.document({"urdf": urdf, "design": design.__dict__})
    out.say(f"wrote {urdf}")
    return 0


def run_convert(args: argparse.Namespace) -> int:
    with loading():
        from mjcf.world import save_xml
        from twin.core.digital_twin import DigitalTwin

    out = Output(args.json)
    check_output_file(args.out, first_line_is_ours, "MJCF file")
    # the world every other command runs, so the robot is checked as they check it (its sensor mount too)
    twin = DigitalTwin(track=args.track, robot_urdf=args.urdf, robot_config=tw.robot_config(args),
                       track_metres_per_pixel=args.metres_per_pixel)
    model = twin.model()
    info = twin.info
    xml = save_xml(twin.spec(), args.out)
    summary = {
        "xml": xml, "bodies": model.nbody - 1, "mass_kg": float(model.body_subtreemass[model.body(info.root_body).id]),
        "wheel_joints": list(info.wheel_joints), "wheel_radius_m": info.wheel_radius, "half_track_m": info.half_track,
        "caster_geoms": list(info.caster_geoms), "sensor_body": info.sensor_body, "notes": list(info.notes),
    }
    out.document(summary)
    out.say(f"wrote {xml}: {summary['bodies']} bodies, {summary['mass_kg']:.4f} kg, wheels {', '.join(info.wheel_joints)} "
            f"(R = {info.wheel_radius * 1000:.1f} mm, L = {info.half_track * 1000:.1f} mm)")
    for n in info.notes:
        out.say(f"note: {n}")
    return 0


def parser() -> o.Parser:
    """``python -m mjcf``'s parser: ``generate`` and ``convert``."""
    p = o.Parser(prog="python -m mjcf", description=__doc__)
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")
    add_generate(sub)
    add_convert(sub)
    return p


def main(argv: list[str] | None = None) -> int:
    """``python -m mjcf``."""
    args = parser().parse_or_exit_code(argv)
    if isinstance(args, int):
        return args
    return run_command(args.run, args)
