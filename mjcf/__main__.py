"""``python -m mjcf``: generate the default robot's URDF, or convert any diff-drive URDF to MJCF.

  python -m mjcf generate -o robot/ [--set cad.L=0.05]
  python -m mjcf convert robot.urdf -o robot.xml [--track default|track.png]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile

from lf_common.files import output_dir
from mjcf import track as track_mod
from mjcf.cad import write_robot
from mjcf.cli import parse_assignments, run_guarded
from mjcf.design import RobotDesign
from mjcf.errors import MjcfError
from mjcf.robot_config import RobotConfig
from mjcf.track_image import track_from_png
from mjcf.world import build_world, compile_world, save_xml, write_texture_png
from motors import POLOLU_MP_6V_30_1


def _design(assignments: dict) -> RobotDesign:
    values = {}
    for address, value in assignments.items():
        if not address.startswith("cad.") or address[4:] not in RobotDesign.__dataclass_fields__:
            raise MjcfError(f"{address}: unknown CAD parameter; known: {', '.join('cad.' + f for f in RobotDesign.__dataclass_fields__)}")
        try:
            values[address[4:]] = float(value)
        except ValueError:
            raise MjcfError(f"{address}: not a number: {value!r}") from None
    return RobotDesign(**values)


def cmd_generate(args: argparse.Namespace) -> int:
    design = _design(parse_assignments(args.set))
    with output_dir(args.out, "robot folder") as tmp:
        write_robot(design, tmp)
    urdf = os.path.join(os.path.abspath(args.out), "robot.urdf")
    if args.json:
        print(json.dumps({"urdf": urdf, "design": design.__dict__}))
    else:
        print(f"wrote {urdf}")
    return 0


def cmd_convert(args: argparse.Namespace) -> int:
    wheels = None
    if args.wheel_joints:
        parts = args.wheel_joints.split(",")
        if len(parts) != 2:
            raise MjcfError(f"--wheel-joints {args.wheel_joints!r}: expected LEFT,RIGHT")
        wheels = (parts[0], parts[1])
    packages = []
    for p in args.package or ():
        name, sep, path = p.partition("=")
        if not sep:
            raise MjcfError(f"--package {p!r}: expected NAME=DIR")
        packages.append((name, path))
    config = RobotConfig(wheel_joints=wheels, caster=args.caster, sensor_link=args.sensor_link, package_dirs=tuple(packages))
    if args.track.lower().endswith(".png"):
        track, texture = track_from_png(args.track, metres_per_pixel=args.metres_per_pixel)
    else:
        track = track_mod.builtin(args.track)
        texture = track.rasterise()
    with tempfile.TemporaryDirectory() as tmp:
        png = os.path.join(tmp, f"{track.name}.png")
        write_texture_png(texture, png)
        spec, info = build_world(args.urdf, texture, png, track.start_pose(), POLOLU_MP_6V_30_1.constants(), config=config)
        model = compile_world(spec, args.urdf)
        out = save_xml(spec, args.out)
    summary = {
        "xml": out,
        "bodies": model.nbody - 1,
        "mass_kg": float(model.body_subtreemass[1]),
        "wheel_joints": list(info.wheel_joints),
        "wheel_radius_m": info.wheel_radius,
        "half_track_m": info.half_track,
        "caster_geoms": list(info.caster_geoms),
        "sensor_body": info.sensor_body,
        "notes": list(info.notes),
    }
    if args.json:
        print(json.dumps(summary))
    else:
        print(f"wrote {out}: {summary['bodies']} bodies, {summary['mass_kg']:.4f} kg, wheels {', '.join(info.wheel_joints)} "
              f"(R = {info.wheel_radius * 1000:.1f} mm, L = {info.half_track * 1000:.1f} mm)")
        for n in info.notes:
            print(f"note: {n}")
    return 0


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m mjcf", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="command", required=True)
    g = sub.add_parser("generate", help="write the parametric robot's URDF and meshes")
    g.add_argument("-o", "--out", required=True, help="output folder (robot.urdf + meshes/)")
    g.add_argument("--set", action="append", metavar="cad.NAME=VALUE", help="design parameter, repeatable")
    g.add_argument("--json", action="store_true", help="print one JSON object")
    g.add_argument("-v", "--verbose", action="store_true")
    g.set_defaults(func=cmd_generate)
    c = sub.add_parser("convert", help="convert a differential-drive URDF to MJCF on a track")
    c.add_argument("urdf", help="robot URDF (relative and package:// mesh paths are resolved)")
    c.add_argument("-o", "--out", required=True, help="output MJCF path; assets go to <stem>_assets/ beside it")
    c.add_argument("--track", default="default", help=f"built-in track ({', '.join(track_mod.BUILTIN_SEGMENTS)}) or a PNG")
    c.add_argument("--metres-per-pixel", type=float, help="scale of a PNG track without DPI metadata [m]")
    c.add_argument("--wheel-joints", metavar="LEFT,RIGHT", help="drive wheel joints (auto-detected if unambiguous)")
    c.add_argument("--caster", help="caster link or collision name (default: names containing 'caster')")
    c.add_argument("--sensor-link", help="link the line sensor mounts on (default: a link named *sensor*)")
    c.add_argument("--package", action="append", metavar="NAME=DIR", help="where package://NAME lives, repeatable")
    c.add_argument("--json", action="store_true", help="print one JSON object")
    c.add_argument("-v", "--verbose", action="store_true")
    c.set_defaults(func=cmd_convert)
    return p


def main(argv: list[str] | None = None) -> int:
    args = parser().parse_args(argv)
    return run_guarded(args.func, args)


if __name__ == "__main__":
    sys.exit(main())
