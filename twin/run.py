"""``python -m twin.run``: the twin's command line.

  python -m twin.run build [--track NAME|PNG] [--robot URDF] [--set ADDRESS=VALUE] [-o world.xml] [--json]
  python -m twin.run graph [--json] [--set ADDRESS=VALUE]   models, ports, parameters and relations
"""

from __future__ import annotations

import argparse
import json
import sys

from mjcf.cli import parse_assignments, run_guarded
from mjcf.world import save_xml
from twin.digital_twin import DigitalTwin
from twin.errors import TwinError
from twin.models import default_space


def cmd_build(args: argparse.Namespace) -> int:
    """Build the world through the model space: CAD → URDF → MJCF on the track, motors and friction set."""
    twin = DigitalTwin(track=args.track, robot_urdf=args.robot, track_metres_per_pixel=args.metres_per_pixel)
    twin.update(parse_assignments(args.set))
    model = twin.model()
    info, track = twin.info, twin.track
    summary = {
        "track": track.name,
        "track_length_m": track.length_m,
        "texture_px": list(twin.texture.grey.shape[::-1]),
        "metres_per_pixel": twin.texture.metres_per_pixel,
        "robot_mass_kg": float(model.body_subtreemass[model.body(info.root_body).id]),
        "wheel_radius_m": info.wheel_radius,
        "half_track_m": info.half_track,
        "nq": model.nq, "nv": model.nv, "nu": model.nu, "na": model.na,
        "timestep_s": model.opt.timestep,
        "parameters": dict(twin.space.values),
        "notes": list(info.notes),
    }
    if args.out:
        summary["xml"] = save_xml(twin.spec(), args.out)
    if args.json:
        print(json.dumps(summary))
        return 0
    print(f"track {track.name}: {track.length_m:.2f} m, texture {summary['texture_px'][0]}×{summary['texture_px'][1]} px "
          f"at {summary['metres_per_pixel'] * 1000:g} mm/px")
    print(f"robot: {summary['robot_mass_kg'] * 1000:.0f} g, R = {info.wheel_radius * 1000:.1f} mm, "
          f"L = {info.half_track * 1000:.1f} mm, wheels {', '.join(info.wheel_joints)}")
    print(f"model: nq={model.nq} nv={model.nv} nu={model.nu} (dcmotor voltage) na={model.na} (motor currents), "
          f"timestep {model.opt.timestep * 1000:g} ms")
    for n in info.notes:
        print(f"note: {n}")
    if args.out:
        print(f"wrote {summary['xml']}")
    return 0


def cmd_graph(args: argparse.Namespace) -> int:
    space = default_space()
    space.update(parse_assignments(args.set))
    if args.json:
        print(json.dumps(space.to_dict(), indent=None if args.compact else 2))
    else:
        print(space.describe())
    return 0


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m twin.run", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="command", required=True)
    b = sub.add_parser("build", help="build the world (robot, motors, track) from the model space")
    b.add_argument("--track", default="default", help="built-in track name or a PNG image")
    b.add_argument("--metres-per-pixel", type=float, help="scale of a PNG track without DPI metadata [m]")
    b.add_argument("--robot", help="a diff-drive URDF instead of the generated robot")
    b.add_argument("--set", action="append", metavar="ADDRESS=VALUE", help="model-space parameter, repeatable")
    b.add_argument("-o", "--out", help="also save the world as MJCF (assets in <stem>_assets/)")
    b.add_argument("--json", action="store_true", help="print one JSON object")
    b.add_argument("-v", "--verbose", action="store_true")
    b.set_defaults(func=cmd_build)
    g = sub.add_parser("graph", help="print the common model space: models, ports, parameters, relations")
    g.add_argument("--json", action="store_true", help="export as JSON")
    g.add_argument("--compact", action="store_true", help="with --json: one line")
    g.add_argument("--set", action="append", metavar="ADDRESS=VALUE", help="show with a parameter changed, repeatable")
    g.add_argument("-v", "--verbose", action="store_true")
    g.set_defaults(func=cmd_graph)
    return p


def main(argv: list[str] | None = None) -> int:
    args = parser().parse_args(argv)
    return run_guarded(args.func, args, errors=(TwinError,))


if __name__ == "__main__":
    sys.exit(main())
