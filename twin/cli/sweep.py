"""``sweep``: where a set of gains stops working: lap time, completion, cross-track error and energy against one
or two parameters, every grid point raced with several noise seeds, all in one batch."""

from __future__ import annotations

import argparse
import math
from typing import TYPE_CHECKING

from lf_common.files import check_output_dir
from twin.cli import options as o
from twin.cli import progress
from twin.cli import twin_options as tw
from twin.cli.output import Output
from twin.cli.startup import loading
from twin.errors import TwinError

if TYPE_CHECKING:
    from tuner.studies.sweep import Axis

HELP = "sensitivity sweep: lap time, completion, cross-track error and energy against one or two parameters"


def add_parser(sub) -> None:
    p = sub.add_parser("sweep", help=HELP, description=HELP + ". Writes sweep.csv, sweep.json and sweep.png (a line "
                       "chart with the failure region shaded, or heat maps for two parameters) into --out-dir.")
    p.add_argument("axes", nargs="+", metavar="ADDRESS=LO:HI:N", help="a parameter that can differ between the laps of "
                   "one batch, from LO to HI in N steps; one or two of them")
    o.add_world(p)
    o.add_values(p)
    o.add_seed(p, 0, "the first noise seed")
    p.add_argument("--seeds", type=o.number(1, 1000, integer=True), default=3, metavar="N", help="noise seeds per grid point")
    o.add_workers(p, "laps of the batch (threads)")
    o.add_firmware(p, "every lap (avr or a program file: each lap runs on the emulated MCU, one after another on one "
                   "core, about 5 s a lap; a 3pi program keeps its own gains, so control.* cannot be swept with it)")
    o.add_controller(p, "every lap (one after another, in the controller's own process)")
    o.add_lap_timeout(p)
    p.add_argument("--cluster", metavar="auto|ray://HOST:PORT", help="run each grid point's laps as a Ray task on a "
                   "cluster (pip install -e '.[cluster]'; the generated robot on a built-in track: nodes share no "
                   "files); the laps equal a local run's")
    o.add_out_dir(p, "sweep.csv, sweep.json and sweep.png", "sweep")
    o.add_json(p)
    o.add_recording(p, "the charts")
    o.add_verbose(p)
    p.set_defaults(run=run)


def parse_axis(text: str) -> Axis:
    with loading():
        from tuner.studies.sweep import Axis

    address, sep, spec = text.partition("=")
    parts = spec.split(":")
    if not sep or len(parts) != 3:
        raise TwinError(f"sweep {text!r}: expected ADDRESS=LO:HI:N, e.g. motion.mu=0.3:1.2:10")
    try:
        lo, hi, n = float(parts[0]), float(parts[1]), int(parts[2])
    except ValueError:
        raise TwinError(f"sweep {text!r}: LO and HI must be numbers and N a whole number") from None
    return Axis(address.strip(), lo, hi, n)


def _sweep_on_cluster(args, twin, axes, seeds, out: Output):
    with loading():
        from mjcf.track import BUILTIN_SEGMENTS
        from tuner.studies.cluster import sweep_on_ray
        from tuner.studies.sweep import grid_points, points_of
        from twin.model.robots import named_robot

    if getattr(args, "robot", None) and named_robot(args.robot) is None:
        raise TwinError("--cluster: the nodes get parameter values, not files; a --robot description cannot go with "
                        "them (sweep it locally)")
    if args.track not in BUILTIN_SEGMENTS:
        raise TwinError(f"--cluster: the nodes get parameter values, not files; track {args.track} is an image (use a "
                        f"built-in track: {', '.join(BUILTIN_SEGMENTS)}, or sweep it locally)")
    grid = grid_points(axes)
    twin.model()  # built here too: a robot or track that cannot be built fails before any task is sent
    base = {"track": args.track, "metres_per_pixel": args.metres_per_pixel, "values": dict(twin.space.values)}
    bar = progress.bar(args, len(grid), "sweep points", "point")
    try:
        laps = sweep_on_ray(grid, seeds, base, args.cluster, on_done=lambda _: bar.update(1))
    finally:
        bar.close()
    return points_of(grid, seeds, laps)


def _sweep_on_mcu(args, twin, program, script, axes, seeds):
    """Each lap on the emulated MCU, one after another, with a progress bar."""
    import copy

    with loading():
        from tuner.studies.sweep import firmware_lap, sweep_firmware
        from twin.core.lap import LapLimits
        from twin.pil.board import Operator

    tw.check_program_runs(twin, program)
    operator = (lambda: copy.deepcopy(script)) if script else Operator  # a fresh operator for each lap
    lap = firmware_lap(program, operator, LapLimits(timeout_s=args.lap_timeout))
    bar = progress.bar(args, math.prod(a.count for a in axes) * len(seeds), "sweep laps on the MCU", "lap")
    try:
        return sweep_firmware(twin, axes, seeds, lap, on_lap=lambda _: bar.update(1))
    finally:
        bar.close()


def _sweep_with_controller(args, twin, controller, axes, seeds):
    """Each lap driven by the controller FMU, one after another, with a progress bar."""
    with loading():
        from tuner.studies.sweep import controller_lap, sweep_firmware
        from twin.core.lap import LapLimits

    twin.model()  # built here: a robot or track that cannot be built fails before the first lap
    lap = controller_lap(controller, LapLimits(timeout_s=args.lap_timeout))
    bar = progress.bar(args, math.prod(a.count for a in axes) * len(seeds), "sweep laps with the controller FMU", "lap")
    try:
        return sweep_firmware(twin, axes, seeds, lap, on_lap=lambda _: bar.update(1))
    finally:
        bar.close()
        controller.close()  # its process frees the FMU and ends


def run(args: argparse.Namespace) -> int:
    with loading():
        from tuner.studies.sweep import check_axes, check_controller_axes, check_program_axes, check_size, sweep, write_sweep
        from twin.fmi.multi_model import PLACED
        from twin.viz import recording

    out = Output(args.json)
    check_output_dir(args.out_dir, "sweep folder")
    recording.check_targets(args.save, args.view)
    axes = [parse_axis(a) for a in args.axes]
    on_mcu = args.firmware != "c"
    with_fmu = bool(args.controller_fmu or args.multi_model)
    # from the counts alone: refused at once, before any grid or twin
    check_size(axes, args.seeds, firmware=on_mcu, one_by_one="with a controller FMU, one by one," if with_fmu else None)
    if (on_mcu or with_fmu) and args.cluster:
        raise TwinError(f"--cluster: the nodes run the twin's C laps; a sweep with "
                        f"{'--firmware' if on_mcu else 'a controller FMU'} runs locally")
    program, script = tw.program_from_args(args)
    foreign = program is not None and not program.traced  # a 3pi program other than the twin's own firmware
    if foreign:
        check_program_axes(axes)
    twin = tw.twin_from_args(args, robot="3pi" if foreign else None)
    warning = tw.gains_warning(args, twin)
    if with_fmu:  # before the multi-model is read and says its notes: a refused axis is the one line
        check_controller_axes(axes, PLACED if args.multi_model else ())
    check_axes(twin, axes)
    seeds = list(range(args.seed, args.seed + args.seeds))
    controller, peer = tw.controller_from_args(args, twin, out)
    if controller:
        points = _sweep_with_controller(args, twin, controller, axes, seeds)
    elif on_mcu:
        points = _sweep_on_mcu(args, twin, program, script, axes, seeds)
    elif args.cluster:
        points = _sweep_on_cluster(args, twin, axes, seeds, out)
    else:
        points = sweep(twin, axes, seeds, nthread=args.workers)
    meta = {"track": twin.track.name, "seeds": seeds, "firmware": args.firmware,
            "base": None if foreign or controller else {a: twin.space.get(a) for a in twin.space.addresses
                                                        if a.startswith("control.")},
            "controller": controller.describe() if controller else None,
            "multi_model": {"file": args.multi_model, "stand_in": args.stand_in, "controller": peer.instance,
                            "twin_values": peer.values} if peer else None}
    paths = write_sweep(args.out_dir, axes, points, meta)
    paths["recording"] = recording.save_charts(args.save, args.view, {"sweep": paths["png"]})
    out.document({**meta, "outputs": paths, "points": [p.row() for p in points], "gains_warning": warning})
    failing = [p for p in points if p.completion < 1]
    for p in points:
        where = ", ".join(f"{a}={v:.4g}" for a, v in p.values.items())
        t = f"median {p.median_s:.3f} s" if p.lap_times_s else "no lap completed"
        out.say(f"{where}: {len(p.lap_times_s)}/{p.laps} laps, {t}, max cross-track {p.max_cross_track_m * 1000:.1f} mm")
    out.say(f"{len(points)} points × {len(seeds)} seeds; {len(failing)} points with failed laps; wrote {paths['folder']}")
    return 0
