"""``lap``: calibrate, then one closed-loop lap, reported as text or JSON. The firmware runs as C in the twin's
callback, or (``--firmware avr``) as the robot's ATmega328P binary in simavr, with the MCU's figures reported."""

from __future__ import annotations

import argparse

from twin.viz import recording
from twin.cli import options as o
from twin.cli.output import Output
from twin.core.closed_loop import run_laps
from twin.core.lap import LapLimits
from twin.errors import TwinError
from twin.fmi import ControllerFmu, parse_map, run_controller_lap
from twin.pil.lap import run_pil_lap

HELP = "calibrate and run one closed-loop lap; print the lap time and a summary"


def add_parser(sub) -> None:
    p = sub.add_parser("lap", help=HELP, description=HELP + ". A lap that leaves the track is a result "
                       "(completed: false, with the reason), not an error.")
    o.add_world(p)
    o.add_values(p)
    o.add_seed(p, 0)
    p.add_argument("--lap-timeout", type=o.number(0.0, 3600.0, lo_open=True), default=60.0, metavar="SIM_S",
                   help="a lap not done after this many simulated seconds ends as 'timeout'")
    p.add_argument("--timeout", dest="lap_timeout", type=o.number(0.0, 3600.0, lo_open=True),
                   action=o.deprecated(argparse._StoreAction, "--lap-timeout"), help=argparse.SUPPRESS)
    o.add_firmware(p, "the lap")
    p.add_argument("--controller-fmu", metavar="C.fmu", help="a controller FMU (FMI 2 or 3 Co-Simulation) drives "
                   "instead of the firmware, at its sample time: the line sensors' side in, motor voltages or wheel-speed "
                   "set-points out (the firmware still calibrates)")
    p.add_argument("--map", action="append", metavar="FMU_VARIABLE=TWIN_PORT", help="connect a variable of the "
                   "--controller-fmu to a twin port, repeatable (default: by name)")
    o.add_db(p, "the lap")
    o.add_json(p)
    o.add_recording(p, "the lap")
    o.add_verbose(p)
    p.set_defaults(run=run)


def lap_summary(result, twin, seed: int) -> dict:
    return {**result.summary(), "track": twin.track.name, "track_length_m": twin.track.length_m, "seed": seed}


def run(args: argparse.Namespace) -> int:
    out = Output(args.json)
    recording.check_targets(args.save, args.view)  # before the lap: a bad path fails now, not after
    o.check_db(args.db)
    twin = o.twin_from_args(args)
    warning = o.gains_warning(args, twin)
    limits, keep = LapLimits(timeout_s=args.lap_timeout), bool(args.save or args.view)
    mcu = controller = None
    if args.map and not args.controller_fmu:
        raise TwinError("--map: maps the variables of a --controller-fmu; give one")
    if args.controller_fmu:
        if args.firmware != "c":
            raise TwinError("--controller-fmu: the controller FMU drives instead of the firmware; leave out --firmware")
        controller = ControllerFmu(args.controller_fmu, parse_map(args.map), int(twin.space.get("sensor.count")),
                                   twin.space.get("control.dt"))
        result = run_controller_lap(twin, controller, seed=args.seed, limits=limits, keep_trace=keep)
    elif args.firmware == "c":
        result = run_laps(twin, [{}], seed=args.seed, limits=limits, keep_traces=keep)[0]
    else:
        result, mcu = run_pil_lap(twin, None if args.firmware == "avr" else args.firmware, seed=args.seed,
                                  limits=limits, keep_trace=keep)
    saved = recording.save_laps(args.save, args.view, twin.track, twin.texture, [result], ["robot"])
    summary = {**lap_summary(result, twin, args.seed), "firmware": args.firmware, "recording": saved,
               "gains_warning": warning}
    if mcu:
        summary["mcu"] = mcu.summary()
    if controller:
        summary["controller"] = controller.describe()
    from tuner.history import record_lap

    summary["history"] = o.keep_history(args.db, lambda h: record_lap(h, twin, result), out)
    out.document(summary)
    if result.completed:
        out.say(f"lap completed in {result.lap_time_s:.3f} s on {twin.track.name} ({twin.track.length_m:.2f} m)")
    else:
        out.say(f"lap not completed: {result.failure} ({result.detail}) after {result.simulated_s:.2f} s, "
                f"{result.distance_m:.2f} of {twin.track.length_m:.2f} m")
    out.say(f"cross-track error: max {result.max_cross_track_m * 1000:.1f} mm, mean {result.mean_cross_track_m * 1000:.1f} mm")
    out.say(f"energy drawn by the motors: {result.energy_j:.2f} J")
    p = result.parameters
    if controller:
        out.say(f"driven by {args.controller_fmu} (FMI {controller.fmi_version}, every "
                f"{controller.sample_time * 1000:g} ms; {controller.actuation}s out); seed {args.seed}")
    else:
        out.say(f"gains: v_max={p['control.v_max']:g} m/s, K_B={p['control.kb']:g}, K_P={p['control.kp']:g}, "
                f"K_I={p['control.ki']:g}, K_D={p['control.kd']:g}, Δt={p['control.dt'] * 1000:g} ms; seed {args.seed}")
    if mcu:
        out.say(f"MCU: {mcu.mcu} at {mcu.f_cpu_hz / 1e6:g} MHz ({mcu.board}): busy {mcu.busy_cycles_mean:.0f} cycles "
                f"per tick on average, {mcu.busy_cycles_max} at most, of {mcu.period_cycles} (headroom "
                f"{mcu.headroom * 100:.1f} %, {mcu.overruns} overruns); flash {mcu.flash_bytes} of {mcu.flash_total_bytes} B, "
                f"RAM {mcu.ram_bytes} of {mcu.ram_total_bytes} B (static); {mcu.telemetry_lines} telemetry lines")
        if mcu.overruns:
            out.say(f"warning: the firmware overran its {p['control.dt'] * 1000:g} ms period {mcu.overruns} times: the MCU "
                    "cannot keep up at this control.dt, so its ticks stretched")
    if saved:
        out.say(f"recording: {saved}")
    return 0
