"""``python -m twin.run``: the twin's command line.

  python -m twin.run lap   [--track NAME|PNG] [--robot URDF] [--gains FILE] [--set ADDRESS=VALUE] [--seed N]
                           [--json] [--save run.rrd] [--view]        one closed-loop lap
  python -m twin.run view  run.rrd                                   open a saved recording in rerun
  python -m twin.run build [--track NAME|PNG] [--robot URDF] [--set ADDRESS=VALUE] [-o world.xml] [--json]
  python -m twin.run graph [--json] [--set ADDRESS=VALUE]            models, ports, parameters and relations
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile

from mjcf.cli import parse_assignments, run_guarded
from mjcf.world import save_xml
from twin.digital_twin import DigitalTwin
from twin.errors import TwinError
from twin.models import default_space


def _twin(args: argparse.Namespace) -> DigitalTwin:
    """The twin the command line describes: track, robot, gains file, then --set (which wins)."""
    twin = DigitalTwin(track=args.track, robot_urdf=args.robot, track_metres_per_pixel=args.metres_per_pixel)
    changes = {}
    if getattr(args, "gains", None):
        from twin.gains import load_gains

        changes.update(load_gains(args.gains, twin.space))
    changes.update(parse_assignments(args.set))
    twin.update(changes)
    return twin


def cmd_lap(args: argparse.Namespace) -> int:
    """Calibrate, then run one lap in closed loop (firmware in C) and report it."""
    from twin.closed_loop import run_laps
    from twin.lap import LapLimits
    from twin import recording

    if args.seed < 0:
        raise TwinError(f"--seed: must be >= 0, got {args.seed}")
    twin = _twin(args)
    limits = LapLimits(timeout_s=args.timeout)
    result = run_laps(twin, [{}], seed=args.seed, limits=limits, keep_traces=bool(args.save or args.view))[0]
    saved = None
    if args.save or args.view:
        out = args.save or os.path.join(tempfile.mkdtemp(prefix="twin-lap-"), "lap.rrd")
        saved = recording.save_laps(out, twin.track, twin.texture, [result], ["robot"])
    summary = {
        "lap_time_s": result.lap_time_s,
        "completed": result.completed,
        "failure": result.failure,
        "detail": result.detail,
        "max_cross_track_m": result.max_cross_track_m,
        "mean_cross_track_m": result.mean_cross_track_m,
        "energy_j": result.energy_j,
        "distance_m": result.distance_m,
        "simulated_s": result.simulated_s,
        "track": twin.track.name,
        "track_length_m": twin.track.length_m,
        "seed": args.seed,
        "calibration_min_us": list(result.calibration_min_us),
        "calibration_max_us": list(result.calibration_max_us),
        "parameters": result.parameters,
        "recording": saved,
    }
    if args.json:
        print(json.dumps(summary))
    else:
        if result.completed:
            print(f"lap completed in {result.lap_time_s:.3f} s on {twin.track.name} ({twin.track.length_m:.2f} m)")
        else:
            print(f"lap not completed: {result.failure} ({result.detail}) after {result.simulated_s:.2f} s, "
                  f"{result.distance_m:.2f} of {twin.track.length_m:.2f} m")
        print(f"cross-track error: max {result.max_cross_track_m * 1000:.1f} mm, mean {result.mean_cross_track_m * 1000:.1f} mm")
        print(f"energy drawn by the motors: {result.energy_j:.2f} J")
        p = result.parameters
        print(f"gains: v_max={p['control.v_max']:g} m/s, K_B={p['control.kb']:g}, K_P={p['control.kp']:g}, "
              f"K_I={p['control.ki']:g}, K_D={p['control.kd']:g}, Δt={p['control.dt'] * 1000:g} ms; seed {args.seed}")
        if saved:
            print(f"recording: {saved}")
    if args.view:
        recording.view([saved])
    return 0


def cmd_view(args: argparse.Namespace) -> int:
    from twin import recording

    recording.view(args.recordings)
    return 0


def cmd_build(args: argparse.Namespace) -> int:
    """Build the world through the model space: CAD → URDF → MJCF on the track, motors and friction set."""
    twin = _twin(args)
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


def _shared_world_options(p: argparse.ArgumentParser, track_default: str | None = "default") -> None:
    p.add_argument("--track", default=track_default,
                   help="built-in track name (default, oval, circle, chicane) or a PNG (default: default)")
    p.add_argument("--metres-per-pixel", type=float, help="scale of a PNG track without DPI metadata [m]")
    p.add_argument("--robot", help="a diff-drive URDF instead of the generated robot")


def _robot_options(p: argparse.ArgumentParser, gains: str, set_help: str, seed: int, seed_help: str,
                   track_default: str | None = "default") -> None:
    """The options every command that runs laps shares: world, gains, parameters, noise seed."""
    _shared_world_options(p, track_default)
    p.add_argument("--gains", metavar="FILE.json", help=gains)
    p.add_argument("--set", action="append", metavar="ADDRESS=VALUE", help=set_help)
    p.add_argument("--seed", type=int, default=seed, help=seed_help)


def _lazy(module: str, name: str):
    """A command implemented in a higher room (the tuner), imported only when it runs."""

    def run(args: argparse.Namespace) -> int:
        import importlib

        return getattr(importlib.import_module(module), name)(args)

    return run


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m twin.run", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="command", required=True)
    lap = sub.add_parser("lap", help="calibrate and run one closed-loop lap; print lap time and a summary",
                         description=cmd_lap.__doc__)
    _robot_options(lap, "control gains, e.g. written by python -m tuner --out",
                   "any model-space parameter (see 'graph'), repeatable; applied after --gains",
                   0, "sensor-noise seed (same seed, bit-identical lap)")
    lap.add_argument("--timeout", type=float, default=60.0, help="give up after this many simulated seconds")
    lap.add_argument("--json", action="store_true", help="print one JSON object")
    lap.add_argument("--save", metavar="RUN.rrd", help="write a rerun recording of the lap")
    lap.add_argument("--view", action="store_true", help="open the lap in the rerun viewer")
    lap.add_argument("-v", "--verbose", action="store_true")
    lap.set_defaults(func=cmd_lap)
    al = sub.add_parser("align", help="align a parameter (default motion.mu) to a measured lap time",
                        description="Find the value of one parameter (tyre friction μ by default) for which the "
                        "simulated lap equals the measured one within 0.5 %%, or say that none does. Exit status 1 "
                        "when the measurement is not explained.")
    al.add_argument("--measured-lap-time", type=float, metavar="SECONDS", help="the robot's lap time [s]")
    al.add_argument("--telemetry", metavar="LAP.jsonl", help="a recorded run (lf-telemetry, see twin.telemetry) to "
                    "match trace by trace; its track and gains are used unless --track/--gains say otherwise")
    al.add_argument("--parameter", action="append", metavar="ADDRESS",
                    help="what to align, repeatable with --telemetry (default motion.mu; with --telemetry motion.mu "
                         "and motor.R_M)")
    al.add_argument("--bounds", action="append", metavar="ADDRESS=LO,HI", help="search range of a parameter")
    _robot_options(al, "the robot's control gains (default: the twin's)", "model-space parameter, repeatable",
                   0, "sensor-noise seed", track_default=None)
    al.add_argument("--json", action="store_true", help="print one JSON object")
    al.add_argument("--save", metavar="ALIGN.rrd", help="rerun recording of the value and lap time per lap")
    al.add_argument("-v", "--verbose", action="store_true")
    al.set_defaults(func=_lazy("tuner.commands", "cmd_align"))
    rc = sub.add_parser("record", help="run one lap and write it as robot telemetry (lf-telemetry JSON Lines)",
                        description="A stand-in for the physical robot's log: one lap of a twin whose hidden "
                        "parameters you set with --set, its own noise seed, written as telemetry for align --telemetry.")
    _robot_options(rc, "the robot's control gains", "hidden model-space parameter, repeatable",
                   7, "the robot's noise seed (differs from the twin's 0)")
    rc.add_argument("--every", type=int, default=2, help="one sample every N control ticks")
    rc.add_argument("--out", required=True, metavar="LAP.jsonl", help="where to write the telemetry")
    rc.add_argument("-v", "--verbose", action="store_true")
    rc.set_defaults(func=_lazy("tuner.commands", "cmd_record"))
    em = sub.add_parser("emulate", help="a stand-in robot streaming wire telemetry on a pty or a TCP port",
                        description="A twin with hidden parameters (--set) and its own noise seed drives lap after "
                        "lap and streams its telemetry (twin.wire) at real-time pace on a pseudo-terminal it creates "
                        "(the path is printed) or on 127.0.0.1:--tcp PORT.")
    _robot_options(em, "the robot's control gains", "hidden model-space parameter, repeatable",
                   7, "the robot's noise seed (lap k uses seed + k)")
    em.add_argument("--speed", type=float, default=1.0, help="faster than real time by this factor")
    em.add_argument("--every", type=int, default=2, help="one sample line every N control ticks")
    em.add_argument("--laps", type=int, help="stop after this many laps (default: run until stopped)")
    em.add_argument("--tcp", type=int, metavar="PORT", help="serve on 127.0.0.1:PORT instead of a pty (0: any free port)")
    em.add_argument("--link", metavar="PATH", help="also make PATH a symlink to the pty, stable across restarts")
    em.add_argument("--echo", metavar="FILE", help="append every line sent to FILE")
    em.add_argument("-v", "--verbose", action="store_true")
    em.set_defaults(func=_lazy("tuner.commands", "cmd_emulate"))
    lv = sub.add_parser("live", help="run the twin beside the robot: compare laps, re-align when they disagree",
                        description="Reads wire telemetry from --port (a device path, socket://host:port, loop://, "
                        "or a pty path), appends every line to --log (flushed per lap), compares each lap with the "
                        "twin, and re-aligns --parameter in the background when the lap time differs by more than "
                        "--threshold for --k-laps laps. A restart resumes from the log and its state file.")
    lv.add_argument("--port", metavar="PATH_OR_URL", help="serial device, pty path or pyserial URL")
    lv.add_argument("--replay", metavar="LOG", help="instead of a link: a recorded telemetry log, as fast as it reads")
    _robot_options(lv, "the robot's control gains", "the twin's model-space parameter, repeatable",
                   0, "the twin's noise seed")
    lv.add_argument("--parameter", action="append", metavar="ADDRESS", help="what re-alignment adjusts (default motion.mu)")
    lv.add_argument("--bounds", action="append", metavar="ADDRESS=LO,HI", help="its search range")
    lv.add_argument("--threshold", type=float, default=0.005, help="relative lap-time difference that counts [-]")
    lv.add_argument("--k-laps", type=int, default=2, help="laps in a row above the threshold before re-aligning")
    lv.add_argument("--log", default="live_telemetry.log", help="telemetry log: every received line")
    lv.add_argument("--state", help="state file (default: <log>.state.json)")
    lv.add_argument("--laps", type=int, help="stop after this many robot laps")
    lv.add_argument("--duration", type=float, help="stop after this many seconds")
    lv.add_argument("--json", action="store_true", help="print one JSON object at the end")
    lv.add_argument("--save", metavar="LIVE.rrd", help="stream the comparison to a rerun recording")
    lv.add_argument("--view", action="store_true", help="stream the comparison to the rerun viewer")
    lv.add_argument("-v", "--verbose", action="store_true")
    lv.set_defaults(func=_lazy("tuner.commands", "cmd_live"))
    de = sub.add_parser("design", help="design study: tune and race every design of a grid over cad.* parameters",
                        description="For each design: rebuild the robot, tune the gains from the same start until "
                        "convergence, run the converged gains for --laps laps with different noise seeds. Writes a "
                        "box plot, a Pareto chart, a table and per-design gains to --out-dir.")
    de.add_argument("--grid", "--param", dest="param", action="append", metavar="ADDRESS=V1,V2,...",
                    help="a cad.* parameter and its values, repeatable (default cad.L=0.035,0.045,0.055 and "
                         "cad.S=0.04,0.06,0.08)")
    _shared_world_options(de)
    de.add_argument("--set", action="append", metavar="ADDRESS=VALUE", help="fixed model-space parameter, repeatable")
    de.add_argument("--laps", type=int, default=20, help="laps per design after tuning, one noise seed each")
    de.add_argument("--max-iter", type=int, default=30, help="tuning iteration cap per design")
    de.add_argument("--workers", type=int, default=0, help="designs in parallel (0: one per core)")
    de.add_argument("--out-dir", default="design_study", help="where the charts, table and gains go")
    de.add_argument("--json", action="store_true", help="print one JSON object")
    de.add_argument("--save", metavar="DESIGN.rrd", help="rerun recording of the charts")
    de.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    de.add_argument("-v", "--verbose", action="store_true")
    de.set_defaults(func=_lazy("tuner.commands", "cmd_design"))
    v = sub.add_parser("view", help="open saved rerun recordings (.rrd)")
    v.add_argument("recordings", nargs="+", metavar="RUN.rrd")
    v.set_defaults(func=cmd_view)
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
