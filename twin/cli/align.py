"""``align``: the value of a parameter (tyre μ by default) for which the simulated lap takes the measured time,
or the parameters that make the twin reproduce a recorded run's telemetry."""

from __future__ import annotations

import argparse
import os

from lf_common.files import check_output_file, json_is_ours
from twin.cli import options as o
from twin.cli import twin_options as tw
from twin.cli.library_values import ALIGN_ACCEPT, ALIGN_TOLERANCE
from twin.cli.output import Output
from twin.cli.startup import loading
from twin.errors import TwinError

HELP = "align a parameter (default motion.mu) to a measured lap time, or parameters to a recorded run"


def add_parser(sub) -> None:
    p = sub.add_parser("align", help=HELP, description=(
        f"With --measured-lap-time: find the value of one parameter (tyre friction μ by default) for which the "
        f"simulated lap is within {ALIGN_ACCEPT * 100:g} % of the measured one (it aims for "
        f"{ALIGN_TOLERANCE * 100:g} %), or say "
        "that none does. With --telemetry: fit parameters so the twin reproduces a recorded run's encoder traces and "
        "lap time: for each parameter the values that fit as well as the best fit, and a 95 % interval only where the "
        "run identifies it. Exit status 1 when the measurement is not explained or a parameter is not identifiable."))
    p.add_argument("--measured-lap-time", type=o.number(0.0, 3600.0, lo_open=True), metavar="S",
                   help="the robot's lap time [s]")
    p.add_argument("--telemetry", metavar="LAP.jsonl", help="a recorded run (lf-telemetry, see twin.telemetry.jsonl); its "
                   "track and gains are used unless --track/--gains say otherwise")
    o.add_search(p, "what to align, repeatable with --telemetry (default motion.mu; with --telemetry motion.mu and "
                    "motor.R_M)")
    o.add_world(p, track_default=None)
    o.add_values(p)
    o.add_seed(p, 0, "the twin's sensor-noise seed")
    o.add_out(p, "the aligned values as a parameter file (load it with --params)", "FILE.json")
    o.add_db(p, "the alignment")
    o.add_json(p)
    o.add_recording(p, "the alignment")
    o.add_verbose(p)
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    if (args.measured_lap_time is None) == (args.telemetry is None):
        raise TwinError("align: give either --measured-lap-time SECONDS or --telemetry FILE.jsonl")
    if args.out:
        check_output_file(args.out, json_is_ours, "parameter file")
    with loading():
        from twin.viz import recording

    recording.check_targets(args.save, args.view)
    o.check_db(args.db)
    return _telemetry(args) if args.telemetry is not None else _lap_time(args)


def _lap_time(args: argparse.Namespace) -> int:
    with loading():
        from tuner.align.lap_time import ACCEPT, align_lap_time
        from tuner.history import record_alignment
        from tuner.recording import save_alignment
        from tuner.sensitivity import lap_time_warning
        from twin.model.parameter_files import save_values

    out = Output(args.json)
    parameters = args.param or ["motion.mu"]
    if len(parameters) != 1:
        raise TwinError("--measured-lap-time aligns one parameter: one lap time cannot fix several")
    twin = tw.twin_from_args(args)
    address = parameters[0]
    bounds = o.parse_bounds(args.bounds, parameters).get(address)
    before = twin.space.get(address)
    r = align_lap_time(twin, args.measured_lap_time, address, bounds=bounds, seed=args.seed)
    summary = {**r.summary(), "recording": None, "out": None}
    # does the parameter move the lap time at all? (the learned influences, else this alignment's own laps)
    summary["sensitivity_warning"], summary["sensitivity_source"] = lap_time_warning(
        twin, address, [(p.value, p.lap_time_s) for p in r.trace], ACCEPT)
    if args.out and r.explained:
        summary["out"] = save_values(args.out, {address: r.value}, source="align --measured-lap-time",
                                     measured_lap_time_s=r.measured_lap_time_s, simulated_lap_time_s=r.simulated_lap_time_s)
    summary["recording"] = save_alignment(args.save, args.view, r, twin.space.parameter(address).unit)
    summary["history"] = o.keep_history(args.db, lambda h: record_alignment(h, r, before), out)
    out.document(summary)
    out.say(r.message)
    if summary["sensitivity_warning"]:
        out.say("warning: " + summary["sensitivity_warning"])
    if r.reachable_intervals_s:
        spans = " or ".join(f"{a:.3f}–{b:.3f} s" for a, b in r.reachable_intervals_s)
        out.say(f"lap times {r.parameter} in [{r.bounds[0]:g}, {r.bounds[1]:g}] can give with these gains: {spans}")
    out.say(f"{r.iterations} iterations, {r.laps} laps")
    for what in ("out", "recording"):
        if summary[what]:
            out.say(f"wrote {summary[what]}")
    return 0 if r.explained else 1


def _telemetry(args: argparse.Namespace) -> int:
    with loading():
        from tuner.align.trace import align_telemetry
        from tuner.history import record_fit
        from tuner.recording import save_trace_alignment
        from twin.model.parameter_files import save_values
        from twin.telemetry.jsonl import read_telemetry

    out = Output(args.json)
    tel = read_telemetry(args.telemetry)
    # the run's own track and gains unless told otherwise: they are what the robot ran with
    twin = tw.twin_from_args(args, track=args.track or tel.header.get("track", "default"))
    if not args.gains and tel.gains:
        fixed = o.parse_assignments(args.set)
        twin.update({a: v for a, v in tel.gains.items() if a not in fixed})
    parameters = args.param or ["motion.mu", "motor.R_M"]
    r = align_telemetry(twin, tel, parameters, bounds=o.parse_bounds(args.bounds, parameters), seed=args.seed)
    summary = {
        "telemetry": os.path.abspath(args.telemetry), "parameters": [p.__dict__ for p in r.parameters],
        "rms_wheel_speed_radps": r.rms_wheel_radps, "simulated_lap_time_s": r.simulated_lap_time_s,
        "measured_lap_time_s": r.measured_lap_time_s, "iterations": r.iterations, "laps": r.laps,
        "correlation": r.correlation, "out": None, "recording": None,
    }
    if args.out:
        summary["out"] = save_values(args.out, {p.address: p.value for p in r.parameters}, source="align --telemetry",
                                     telemetry=os.path.abspath(args.telemetry),
                                     identifiable={p.address: p.identifiable for p in r.parameters})
    summary["recording"] = save_trace_alignment(args.save, args.view, tel, r)
    summary["history"] = o.keep_history(args.db, lambda h: record_fit(h, r.parameters, r.measured_lap_time_s), out)
    out.document(summary)
    for p in r.parameters:
        ci = f"95 % [{p.ci95[0]:.5g}, {p.ci95[1]:.5g}]" if p.ci95 is not None else "no interval"
        out.say(f"{p.address} = {p.value:.5g}  ({ci}): {p.note}")  # the note gives the consistent set
    lap = f"{r.simulated_lap_time_s:.3f} s" if r.simulated_lap_time_s else "not completed"
    meas = f"{r.measured_lap_time_s:.3f} s" if r.measured_lap_time_s else "no lap in the run"
    out.say(f"wheel speeds match to {r.rms_wheel_radps:.3f} rad/s rms; lap {lap} against {meas}; "
            f"{r.iterations} iterations, {r.laps} laps")
    unidentified = [p.address for p in r.parameters if not p.identifiable]
    if unidentified:
        out.say(f"exit status 1: this run does not identify {', '.join(unidentified)} (see the notes above)")
    for what in ("out", "recording"):
        if summary[what]:
            out.say(f"wrote {summary[what]}")
    return 0 if not unidentified else 1
