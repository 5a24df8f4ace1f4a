"""The case-study commands of ``python -m twin.run`` that belong to the learning model: ``align`` (and,
as they arrive, ``record`` and ``design``). ``twin.run`` imports this lazily, so the twin's own commands do not
depend on the tuner."""

from __future__ import annotations

import argparse
import json
import os

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from lf_common.files import check_output_dir
from mjcf.cli import parse_assignments
from tuner.align import align_lap_time
from tuner.jsonable import json_safe
from tuner.space import TunerError, parse_bounds
from twin.recording import recording_file


def save_alignment(out_path: str, result) -> str:
    """μ (or the aligned parameter) and lap time per lap, as Fig. 6b–c; written atomically."""
    blueprint = rrb.Blueprint(rrb.Vertical(
        rrb.TimeSeriesView(name=f"{result.parameter}", origin="/align/value"),
        rrb.TimeSeriesView(name="lap time [s]", contents=["/align/lap_time", "/align/measured"]),
    ), collapse_panels=True)
    with recording_file(out_path, blueprint) as rec:
        pts = [p for p in result.trace if p.lap_time_s is not None]
        idx = [rr.TimeColumn("lap", sequence=np.arange(len(pts)))]
        for entity, values in (("align/value", [p.value for p in pts]), ("align/lap_time", [p.lap_time_s for p in pts]),
                               ("align/measured", np.full(len(pts), result.measured_lap_time_s))):
            rr.send_columns(entity, indexes=idx, columns=rr.Scalars.columns(scalars=values), recording=rec)
    return os.path.abspath(out_path)


def cmd_align(args: argparse.Namespace) -> int:
    """Align a parameter (default motion.mu) so the simulated lap time equals a measured one, or several
    parameters so the simulated lap reproduces a recorded run's telemetry."""
    from twin.run import _twin

    if args.seed < 0:
        raise TunerError(f"--seed: must be >= 0, got {args.seed}")
    if (args.measured_lap_time is None) == (args.telemetry is None):
        raise TunerError("align: give either --measured-lap-time SECONDS or --telemetry FILE.jsonl")
    if args.telemetry is not None:
        return _align_telemetry(args)
    args.track = args.track or "default"
    parameters = args.parameter or ["motion.mu"]
    if len(parameters) != 1:
        raise TunerError("--measured-lap-time aligns one parameter: one lap time cannot fix several")
    twin = _twin(args)
    bounds = parse_bounds(args.bounds, parameters).get(parameters[0])
    r = align_lap_time(twin, args.measured_lap_time, parameters[0], bounds=bounds, seed=args.seed)
    summary = {
        "parameter": r.parameter, "value": r.value, "simulated_lap_time_s": r.simulated_lap_time_s,
        "measured_lap_time_s": r.measured_lap_time_s, "explained": r.explained, "identifiable": r.identifiable,
        "consistent_range": r.consistent, "reachable_lap_times_s": r.reachable_s, "iterations": r.iterations,
        "laps": r.laps, "message": r.message, "trace": [p.__dict__ for p in r.trace],
    }
    if args.save:
        summary["recording"] = save_alignment(args.save, r)
    if args.json:
        print(json.dumps(summary))
    else:
        print(r.message)
        if r.reachable_s:
            print(f"lap times {r.parameter} can give with these gains: {r.reachable_s[0]:.3f}–{r.reachable_s[1]:.3f} s")
        print(f"{r.iterations} iterations, {r.laps} laps")
        if args.save:
            print(f"recording: {summary['recording']}")
    return 0 if r.explained else 1


def _grid_params(items) -> dict[str, tuple[float, ...]]:
    from tuner.design import DEFAULT_GRID

    if not items:
        return dict(DEFAULT_GRID)
    out: dict[str, tuple[float, ...]] = {}
    for address, text in parse_assignments(items).items():
        try:
            values = tuple(float(v) for v in str(text).split(","))
        except ValueError:
            raise TunerError(f"--param {address}={text}: expected comma-separated numbers, e.g. cad.L=0.035,0.045") from None
        if not all(np.isfinite(values)):
            raise TunerError(f"--param {address}={text}: values must be finite")
        out[address] = values
    return out


def cmd_design(args: argparse.Namespace) -> int:
    """Design study: rebuild, tune and evaluate every design of a grid over cad.* parameters."""
    import time

    from tqdm import tqdm

    from tuner.design import grid, pareto, study, trend
    from tuner.design_report import write_report
    from twin.models import default_space

    if args.laps < 1 or args.max_iter < 1 or args.workers < 0:
        raise TunerError("--laps and --max-iter must be >= 1, --workers >= 0")
    check_output_dir(args.out_dir, "design study folder")  # before any work: refused now, not after the study
    params = _grid_params(args.param)
    space = default_space()
    for address in params:
        space.parameter(address)  # unknown address: one-line error
        if not address.startswith("cad."):
            raise TunerError(f"--param {address}: a design study varies cad.* parameters (the robot's geometry)")
    fixed = parse_assignments(args.set)
    space.update(fixed)  # fixed values are checked now: a bad --set is bad input, not a failing design
    from twin.environment import load_track

    load_track(args.track, space.get("environment.line_width"), space.get("environment.texture_resolution"),
               args.metres_per_pixel)  # an unknown track or unreadable image: one-line error before any work
    designs = grid(params)
    base = {"track": args.track, "metres_per_pixel": args.metres_per_pixel, "values": {a: float(v) for a, v in fixed.items()}}
    t0 = time.perf_counter()
    bar = tqdm(total=len(designs), desc="designs", unit="design", disable=args.quiet or None)
    results = study(designs, base, laps=args.laps, max_iter=args.max_iter, workers=args.workers,
                    on_done=lambda r: (bar.update(1), bar.set_postfix_str(f"{r.label}: {r.median_s:.3f} s" if r.ok else f"{r.label}: failed")))
    bar.close()
    wall = time.perf_counter() - t0
    front = pareto(results)
    trends = [trend(results, a) for a in params]
    meta = {"track": args.track, "grid": {a: list(v) for a, v in params.items()}, "fixed": base["values"],
            "laps_per_design": args.laps, "wall_s": wall}
    paths = write_report(args.out_dir, results, front, trends, meta)
    if args.save:
        paths["recording"] = _save_design(args.save, paths)
    summary = {**meta, "outputs": paths, "trends": trends,
               "designs": [{"design": r.design, "ok": r.ok, "error": r.error, "median_lap_time_s": r.median_s if r.ok else None,
                            "laps_completed": len(r.lap_times_s), "mean_cross_track_m": r.mean_cross_track_m if r.ok else None,
                            "pareto": on, "gains": r.gains} for r, on in zip(results, front)]}
    if args.json:
        print(json.dumps(json_safe(summary), allow_nan=False, default=str))
    else:
        for r, on in zip(results, front):
            if r.ok:
                t = np.array(r.lap_times_s)
                spread = f"{t.min():.3f}–{t.max():.3f}" if len(t) else "–"
                print(f"{r.label:28s} median {r.median_s:7.3f} s ({spread}, {len(t)}/{len(t) + r.failed_laps} laps), "
                      f"cross-track {r.mean_cross_track_m * 1000:.1f} mm{'  pareto' if on else ''}")
            else:
                print(f"{r.label:28s} failed: {r.error}")
        for t in trends:
            print(t)
        print(f"{len(designs)} designs in {wall:.0f} s; wrote {args.out_dir}/ (lap_times.png, pareto.png, designs.csv, "
              "designs.json, gains/)")
    return 0


def _save_design(out_path: str, paths: dict) -> str:
    from PIL import Image

    blueprint = rrb.Blueprint(rrb.Horizontal(
        rrb.Spatial2DView(name="lap times", origin="/design/lap_times"),
        rrb.Spatial2DView(name="Pareto", origin="/design/pareto")), collapse_panels=True)
    with recording_file(out_path, blueprint) as rec:
        for entity, key in (("design/lap_times", "chart"), ("design/pareto", "pareto")):
            rr.log(entity, rr.Image(np.asarray(Image.open(paths[key]).convert("RGB"))), static=True, recording=rec)
    return os.path.abspath(out_path)


def _align_telemetry(args: argparse.Namespace) -> int:
    from tuner.align_trace import align_telemetry
    from twin.run import _twin
    from twin.telemetry import read_telemetry

    tel = read_telemetry(args.telemetry)
    # the run's own track and gains unless told otherwise: they are what the robot ran with
    args.track = args.track or tel.header.get("track", "default")
    twin = _twin(args)
    if not args.gains and isinstance(tel.header.get("gains"), dict):
        twin.update({a: float(v) for a, v in tel.header["gains"].items() if not (args.set and any(x.startswith(a + "=") for x in args.set))})
    parameters = args.parameter or ["motion.mu", "motor.R_M"]
    r = align_telemetry(twin, tel, parameters, bounds=parse_bounds(args.bounds, parameters), seed=args.seed)
    summary = {
        "telemetry": os.path.abspath(args.telemetry), "parameters": [p.__dict__ for p in r.parameters],
        "rms_wheel_speed_radps": r.rms_wheel_radps, "simulated_lap_time_s": r.simulated_lap_time_s,
        "measured_lap_time_s": r.measured_lap_time_s, "iterations": r.iterations, "laps": r.laps,
        "correlation": r.correlation,
    }
    if args.json:
        print(json.dumps(json_safe(summary), allow_nan=False, default=str))
    else:
        for p in r.parameters:
            ci = f"95 % [{p.ci95[0]:.5g}, {p.ci95[1]:.5g}]" if np.isfinite(p.stderr) else "no interval"
            print(f"{p.address} = {p.value:.5g}  ({ci}): {p.note}")
        lap = f"{r.simulated_lap_time_s:.3f} s" if r.simulated_lap_time_s else "not completed"
        meas = f"{r.measured_lap_time_s:.3f} s" if r.measured_lap_time_s else "no lap in the run"
        print(f"wheel speeds match to {r.rms_wheel_radps:.3f} rad/s rms; lap {lap} against {meas}; "
              f"{r.iterations} iterations, {r.laps} laps")
    return 0 if all(p.identifiable for p in r.parameters) else 1


def cmd_record(args: argparse.Namespace) -> int:
    """Run one lap of a twin (with hidden parameters via --set) and write it as robot telemetry."""
    from twin.closed_loop import run_laps
    from twin.run import _twin
    from twin.telemetry import lap_lines, write_telemetry

    if args.seed < 0 or args.every < 1:
        raise TunerError("--seed must be >= 0 and --every >= 1")
    args.track = args.track or "default"
    twin = _twin(args)
    lap = run_laps(twin, [{}], seed=args.seed)[0]
    gains = {a: twin.space.get(a) for a in twin.space.addresses if a.startswith("control.")}
    header = {"track": twin.track.name if not args.track.lower().endswith(".png") else args.track,
              "sensors": int(twin.space.get("sensor.count")), "dt_s": twin.space.get("control.dt"), "gains": gains,
              "source": "twin", "seed": args.seed}
    path = write_telemetry(args.out, lap_lines(lap, header, args.every))
    what = f"lap {lap.lap_time_s:.3f} s" if lap.completed else f"not completed ({lap.failure})"
    print(f"wrote {path}: {what}, {len(lap.trace.records[::args.every])} samples")
    return 0


def cmd_emulate(args: argparse.Namespace) -> int:
    """A stand-in robot streaming wire telemetry on a pty (default) or a 127.0.0.1 TCP port."""
    import sys

    from twin.emulator import lap_records, open_pty, serve_tcp, stream
    from twin.run import _twin

    if args.speed <= 0 or args.every < 1 or args.seed < 0:
        raise TunerError("--speed must be > 0, --every >= 1 and --seed >= 0")
    args.track = args.track or "default"
    twin = _twin(args)
    twin.model()
    echo_file = open(args.echo, "a", buffering=1) if args.echo else None
    echo = echo_file.write if echo_file else None
    lines = lap_records(twin, args.seed, args.every, args.laps)
    try:
        if args.tcp is not None:
            server = serve_tcp(args.tcp)
            print(f"robot emulator on socket://127.0.0.1:{server.getsockname()[1]}", flush=True)
            while True:
                conn, _ = server.accept()
                try:
                    stream(lines, conn.sendall, args.speed, echo)
                    return 0
                except OSError:
                    continue  # the reader went away: wait for the next one, carry on with the laps
                finally:
                    conn.close()
        master, slave, path = open_pty(args.link)
        print(f"robot emulator on {path}", flush=True)
        stream(lines, lambda b: os.write(master, b), args.speed, echo)
        sys.stdout.flush()
        return 0
    finally:
        if echo_file:
            echo_file.close()


def cmd_live(args: argparse.Namespace) -> int:
    """Run the twin beside the robot: compare laps, re-align when they keep disagreeing."""
    import signal
    import time

    from tuner.live import LinkStats, LiveOptions, LiveTwin, replay_log, run_link

    if args.replay and not os.path.isfile(args.replay):
        raise TunerError(f"{args.replay}: no such telemetry log")
    from twin.run import _twin

    args.track = args.track or "default"
    twin = _twin(args)
    twin.model()
    parameters = args.parameter or ["motion.mu"]
    if len(parameters) != 1:
        raise TunerError("live: re-aligns one parameter (--parameter) from lap times")
    if not (args.threshold > 0 and args.k_laps >= 1):
        raise TunerError("--threshold must be > 0 and --k-laps >= 1")
    twin.space.parameter(parameters[0])
    bounds = parse_bounds(args.bounds, parameters).get(parameters[0], LiveOptions.bounds if parameters[0] == "motion.mu" else None)
    options = LiveOptions(parameters[0], bounds, args.threshold, args.k_laps, args.seed)
    state = args.state or f"{args.log}.state.json"
    rec = _live_recording(args)

    def on_lap(e):
        if not e["replayed"]:
            d = "–" if e["discrepancy"] is None else f"{e['discrepancy'] * 100:+.2f} %"
            robot = f"{e['robot_lap_time_s']:.3f} s" if e["robot_lap_time_s"] else "failed"
            print(f"lap {e['lap']}: robot {robot}, twin {e['twin_lap_time_s']:.3f} s ({d}), "
                  f"{options.address} = {e[options.address]:.5g}", flush=True)
        if rec is not None:
            _log_live_lap(rec, e, options.address)

    stats = LinkStats()
    if args.replay:
        live = LiveTwin(twin, options, None, on_lap)
        replay_log(args.replay, live, stats, realign=True)
        live.finish()
        summary = {"laps": len(live.laps), "lines": stats.lines, "corrupted": stats.corrupted,
                   "value": {options.address: twin.space.get(options.address)}, "alignments": live.alignments,
                   "replayed": os.path.abspath(args.replay)}
        print(json.dumps(summary, default=str) if args.json else
              f"replayed {len(live.laps)} laps ({stats.corrupted} corrupted lines); "
              f"{options.address} = {twin.space.get(options.address):.5g}")
        return 0
    if not args.port:
        raise TunerError("live: give --port PATH_OR_URL (or --replay FILE)")
    live = LiveTwin(twin, options, state, on_lap)
    if os.path.isfile(args.log):
        replay_log(args.log, live, stats)
        print(f"resumed {len(live.laps)} laps from {args.log}", flush=True)
    start_laps, t0 = len(live.laps), time.monotonic()
    stopping = [False]
    signal.signal(signal.SIGINT, lambda *a: stopping.__setitem__(0, True))
    signal.signal(signal.SIGTERM, lambda *a: stopping.__setitem__(0, True))

    def stop() -> bool:
        done_laps = args.laps is not None and len(live.laps) - start_laps >= args.laps
        timed_out = args.duration is not None and time.monotonic() - t0 > args.duration
        return stopping[0] or done_laps or timed_out

    run_link(args.port, live, args.log, stats, stop)
    live.finish()
    summary = {"laps": len(live.laps) - start_laps, "resumed_laps": start_laps, "lines": stats.lines,
               "corrupted": stats.corrupted, "reconnects": stats.reconnects,
               "value": {options.address: twin.space.get(options.address)}, "alignments": live.alignments,
               "log": os.path.abspath(args.log), "state": os.path.abspath(state)}
    if args.json:
        print(json.dumps(summary, default=str))
    else:
        print(f"{summary['laps']} laps, {stats.lines} lines ({stats.corrupted} corrupted), {stats.reconnects} reconnects; "
              f"{options.address} = {twin.space.get(options.address):.5g}; log {summary['log']}")
    return 0


def _live_recording(args):
    if not (args.save or args.view):
        return None
    rec = rr.RecordingStream("line-follower-twin-live")
    if args.save:
        rec.save(os.path.abspath(args.save))
    if args.view:
        rec.spawn()
    return rec


def _log_live_lap(rec, e: dict, address: str) -> None:
    rec.set_time("lap", sequence=e["lap"])
    if e["robot_lap_time_s"]:
        rec.log("live/lap_time/robot", rr.Scalars(e["robot_lap_time_s"]))
    if e["twin_lap_time_s"]:
        rec.log("live/lap_time/twin", rr.Scalars(e["twin_lap_time_s"]))
    if e["discrepancy"] is not None:
        rec.log("live/discrepancy", rr.Scalars(e["discrepancy"]))
    rec.log(f"live/{address}", rr.Scalars(e[address]))
    lap, twin_trace = e["lap_record"], e["twin_lap"].trace
    series = [("robot", lap.t, lap.wl, lap.pos)]
    if twin_trace is not None:
        series.append(("twin", twin_trace.time_s, twin_trace.column("wheel_left_radps"), twin_trace.column("position")))
    for who, t, wl, pos in series:  # both laps on one lap-time axis: where they part is visible
        if len(t):
            index = [rr.TimeColumn("lap_time", duration=t)]
            rec.send_columns(f"live/wheel_left/{who}", indexes=index, columns=rr.Scalars.columns(scalars=wl))
            rec.send_columns(f"live/line_position/{who}", indexes=index, columns=rr.Scalars.columns(scalars=pos))
    rec.flush()
