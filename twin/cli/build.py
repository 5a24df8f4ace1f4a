"""``build``: the world through the model space (CAD → URDF → MJCF on the track), summarised or saved."""

from __future__ import annotations

import argparse

from twin.cli import options as o
from twin.cli import twin_options as tw
from twin.cli.output import Output
from twin.cli.startup import loading

HELP = "build the world (robot, motors, track) from the model space; summarise it or save it as MJCF"


def add_parser(sub) -> None:
    p = sub.add_parser("build", help=HELP, description=HELP + ".")
    o.add_world(p)
    o.add_values(p)
    o.add_out(p, "the world as MJCF (assets in <stem>_assets/ beside it)", "WORLD.xml")
    o.add_json(p)
    o.add_verbose(p)
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    with loading():
        from mjcf.world import save_xml

    out = Output(args.json)
    twin = tw.twin_from_args(args)
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
        "xml": save_xml(twin.spec(), args.out) if args.out else None,
    }
    out.document(summary)
    out.say(f"track {track.name}: {track.length_m:.2f} m, texture {summary['texture_px'][0]}×{summary['texture_px'][1]} px "
            f"at {summary['metres_per_pixel'] * 1000:g} mm/px")
    out.say(f"robot: {summary['robot_mass_kg'] * 1000:.0f} g, R = {info.wheel_radius * 1000:.1f} mm, "
            f"L = {info.half_track * 1000:.1f} mm, wheels {', '.join(info.wheel_joints)}")
    out.say(f"model: nq={model.nq} nv={model.nv} nu={model.nu} (motor voltage) na={model.na} (winding voltage lags, L_M > 0), "
            f"timestep {model.opt.timestep * 1000:g} ms")
    for n in info.notes:
        out.say(f"note: {n}")
    if summary["xml"]:
        out.say(f"wrote {summary['xml']}")
    return 0
