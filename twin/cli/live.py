"""``live``: the twin beside the robot: every received line logged, each lap compared, re-alignment in the
background when laps keep disagreeing."""

from __future__ import annotations

import argparse
import os
import signal
import sys
import time

from twin.cli import options as o
from twin.cli.output import Output
from twin.errors import TwinError
from tuner.live import LiveOptions, LiveTwin, replay_log
from twin.link import FSYNC_INTERVAL_S, RETRY_S, DurableLog, LinkGaveUp, LinkStats, read_link
from twin.wire import Event, WireError, decode
from tuner.recording import LiveRecording

HELP = "run the twin beside the robot: compare laps, re-align when they disagree"


def add_parser(sub) -> None:
    p = sub.add_parser("live", help=HELP, description=(
        "Reads wire telemetry from --port (a device path, socket://host:port, loop://, or a pty path), appends every "
        f"byte received to --log (fsynced every {FSYNC_INTERVAL_S:g} s and at each lap; the log is locked against a "
        "second reader), compares each plausible lap with the twin, and re-aligns --param in the background when the "
        "lap time differs by more than --threshold for --k-laps laps. A restart resumes from the log and its state "
        "file. Exit status 1 when the link could not be opened."))
    p.add_argument("--port", metavar="PATH_OR_URL", help="serial device, pty path or pyserial URL")
    p.add_argument("--replay", metavar="LOG", help="instead of a link: a recorded telemetry log, as fast as it reads")
    o.add_world(p)
    o.add_values(p, "the twin's model-space parameter, repeatable")
    o.add_seed(p, 0, "the twin's noise seed")
    o.add_search(p, "what re-alignment adjusts (default motion.mu)")
    p.add_argument("--threshold", type=o.number(0.0, 1.0, lo_open=True), default=0.005, metavar="FRACTION",
                   help="relative lap-time difference that counts as disagreeing")
    p.add_argument("--k-laps", type=o.count_type, default=2, metavar="N", help="laps in a row above the threshold before re-aligning")
    p.add_argument("--log", default="live_telemetry.log", metavar="FILE", help="telemetry log: every received line, appended")
    p.add_argument("--state", metavar="FILE", help="state file (default: <log>.state.json)")
    p.add_argument("--laps", type=o.count_type, metavar="N", help="stop after this many robot laps")
    p.add_argument("--duration", type=o.number(0.0, 10**7, lo_open=True), metavar="WALL_S", help="stop after this many wall-clock seconds")
    p.add_argument("--retry", type=o.number(0.0, 10**6), default=RETRY_S, metavar="WALL_S",
                   help="how long to keep reopening a link that is down before giving up (exit 1)")
    p.add_argument("--retry-forever", action="store_true", help="keep reopening a link that is down, never give up")
    o.add_json(p)
    o.add_recording(p, "the comparison, lap by lap")
    o.add_verbose(p)
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    out = Output(args.json)
    if args.replay and not os.path.isfile(args.replay):
        raise TwinError(f"{args.replay}: no such telemetry log")
    twin = o.twin_from_args(args)
    twin.model()
    parameters = args.param or ["motion.mu"]
    if len(parameters) != 1:
        raise TwinError("live: re-aligns one parameter (--param) from lap times")
    address = parameters[0]
    parameter = twin.space.parameter(address)
    bounds = o.parse_bounds(args.bounds, parameters).get(address, LiveOptions.bounds if address == "motion.mu" else None)
    options = LiveOptions(address, bounds, args.threshold, args.k_laps, args.seed)
    state = args.state or f"{args.log}.state.json"
    rec = LiveRecording(args.save, args.view, address, parameter.unit) if (args.save or args.view) else None

    def on_lap(e):
        if not e["replayed"]:
            d = "–" if e["discrepancy"] is None else f"{e['discrepancy'] * 100:+.2f} %"
            robot = f"{e['robot_lap_time_s']:.3f} s" if e["robot_lap_time_s"] else "failed"
            out.say(f"lap {e['lap']}: robot {robot}, twin {e['twin_lap_time_s']:.3f} s ({d}), "
                    f"{address} = {e[address]:.5g}")
        if rec is not None:
            rec.lap(e)

    try:
        summary = _replay(args, twin, options, on_lap, out) if args.replay else _link(args, twin, options, state, on_lap, out)
    except BaseException as e:
        if rec is not None:
            rec.close(e)
        raise
    if rec is not None:
        rec.close()
    summary["recording"] = rec.saved if rec is not None else None
    out.document(summary)
    return 1 if summary.get("gave_up") else 0


def _replay(args, twin, options: LiveOptions, on_lap, out: Output) -> dict:
    stats = LinkStats()
    live = LiveTwin(twin, options, None, on_lap)
    replay_log(args.replay, live, stats, realign=True)
    live.finish()
    value = twin.space.get(options.address)
    out.say(f"replayed {len(live.laps)} laps ({stats.corrupted} corrupted lines); {options.address} = {value:.5g}")
    return {"laps": len(live.laps), "lines": stats.lines, "corrupted": stats.corrupted,
            "value": {options.address: value}, "alignments": live.alignments, "replayed": os.path.abspath(args.replay)}


def _link(args, twin, options: LiveOptions, state: str, on_lap, out: Output) -> dict:
    if not args.port:
        raise TwinError("live: give --port PATH_OR_URL (or --replay FILE)")
    stats = LinkStats()
    log_file = DurableLog(args.log)  # locked, a cut-off last line ended: before anything reads it
    try:
        live = LiveTwin(twin, options, state, on_lap)
        if os.path.getsize(args.log) > 0:
            replay_log(args.log, live, LinkStats(), realign=live.rebuild_from_log)
            live.finish()
            if live.rebuild_from_log:
                live.save_state()
            out.say(f"resumed {len(live.laps)} laps from {args.log}")
        start_laps, t0 = len(live.laps), time.monotonic()
        stopping = [False]
        signal.signal(signal.SIGINT, lambda *a: stopping.__setitem__(0, True))
        signal.signal(signal.SIGTERM, lambda *a: stopping.__setitem__(0, True))

        def stop() -> bool:
            done_laps = args.laps is not None and len(live.laps) - start_laps >= args.laps
            timed_out = args.duration is not None and time.monotonic() - t0 > args.duration
            return stopping[0] or done_laps or timed_out

        def on_line(raw: bytes) -> bool:
            try:
                rec = decode(raw)
            except WireError:
                stats.corrupted += 1
                return False
            lap_event = isinstance(rec, Event) and rec.event in ("LAP", "FAIL")
            stats.robot_laps += lap_event
            live.feed(rec)
            return lap_event

        gave_up = None
        try:
            read_link(args.port, log_file, on_line, lambda: live.feed(None), stats, stop,
                      None if args.retry_forever else args.retry)
        except LinkGaveUp as e:
            gave_up = str(e)
        live.finish()
    finally:
        log_file.close()
    value = twin.space.get(options.address)
    new = live.laps[start_laps:]
    summary = {"laps": len(new), "resumed_laps": start_laps, "lines": stats.lines, "corrupted": stats.corrupted,
               "reconnects": stats.reconnects, "implausible_laps": sum(1 for e in new if e.get("implausible")),
               "value": {options.address: value}, "alignments": live.alignments, "log": os.path.abspath(args.log),
               "state": os.path.abspath(state), "gave_up": gave_up}
    out.say(f"{summary['laps']} laps ({summary['implausible_laps']} implausible), {stats.lines} lines "
            f"({stats.corrupted} corrupted), {stats.reconnects} reconnects; {options.address} = {value:.5g}; "
            f"log {summary['log']}")
    if gave_up:
        print(f"gave up: {gave_up}", file=sys.stderr)
    return summary
