"""``history``: a robot's life from the history database: its laps, its changes of gains, the trend of each aligned
parameter, and when the gains in force will stop finishing (asked of the twin along the trend), with advice;
``--rebuild`` puts telemetry logs (and the actions journaled beside them) back into the database, idempotently."""

from __future__ import annotations

import argparse
import json
import math
import os
import sys

from lf_common.files import check_output_dir, input_file, output_dir
from twin.cli import options as o
from twin.cli import twin_options as tw
from twin.cli.output import Output
from twin.cli.startup import loading
from twin.errors import TwinError

HELP = "a robot's life from the history database: laps, gain changes, trends, a forecast and advice"


def add_parser(sub) -> None:
    p = sub.add_parser("history", help=HELP, description=__doc__ + (
        " The forecast races the gains in force on the twin the world flags describe (--track, --robot, --set, …: "
        "give the robot's), along the trend of the last aligned values."))
    p.add_argument("--db", nargs="?", const=o.DEFAULT_DB_URL, default=o.DEFAULT_DB_URL, metavar="URL",
                   help="the history database (SQLAlchemy URL; default twin_history.sqlite in the working folder)")
    p.add_argument("--robot-id", metavar="ID", help="only this robot (its wire id; 'twin' for lap, tune and align runs)")
    p.add_argument("--rebuild", action="store_true", help="rebuild the database's rows of each --log from the log and "
                   "the actions beside it (<log>.actions); running it again changes nothing, nor does a copy of a log "
                   "(the same log: its rows are replaced); a journal that is not the log's, or a log live is still "
                   "writing, is refused")
    p.add_argument("--log", action="append", metavar="FILE", help="a telemetry log of live (with --rebuild), repeatable")
    p.add_argument("--no-forecast", action="store_true", help="report without racing the twin")
    p.add_argument("--race-wait", type=o.number(0.0, 900.0), metavar="S", help="wait at most S seconds in all for "
                   "the twin's races of the gains in force that live's race-ahead (or another history) is still "
                   "running: a forecast whose races are not done by then says so and gives no number (ask again), "
                   "and the races after it are left to that process too; with no other process racing, they are "
                   "raced here, as without the flag; default: wait until they are done, up to 900 s each")
    o.add_world(p)
    o.add_values(p, "the robot's model-space parameter, for the forecast, repeatable")
    o.add_seed(p, 0, "the forecast's first noise seed")
    o.add_out_dir(p, "a chart per robot (history_<robot>.png) and history.json", None)
    o.add_json(p)
    o.add_recording(p, "each robot's lap times, aligned parameters and gain changes")
    o.add_verbose(p, quiet=True)
    p.set_defaults(run=run)


def _existing(url: str) -> None:
    """Reading a history must not create one: a SQLite file that is not there is bad input."""
    with loading():
        from tuner.history import check_db

    check_db(url)
    if url.startswith("sqlite:///"):
        path = url.removeprefix("sqlite:///")
        if path and not os.path.exists(path):
            raise TwinError(f"--db {url}: no history database there (live, lap, tune and align write one with --db)")


def run(args: argparse.Namespace) -> int:
    out = Output(args.json)
    if args.log and not args.rebuild:
        raise TwinError("history --log: give --rebuild to put the logs into the database")
    if args.rebuild:
        if not args.log:
            raise TwinError("history --rebuild: give each telemetry log with --log FILE")
        for path in args.log:
            input_file(path, "telemetry log")
        return _rebuild(args, out)
    with loading():
        from tuner.history import History, display  # (after the checks of the flags alone: they need none)
        from tuner.history.charts import robot_chart
        from tuner.history.report import report
        from tuner.recording import save_history
        from twin.viz import recording

    _existing(args.db)
    recording.check_targets(args.save, args.view)
    if args.out_dir:
        check_output_dir(args.out_dir, "history folder")
    twin = None if args.no_forecast else tw.twin_from_args(args)
    history = History(args.db)
    try:
        quiet = args.json or args.quiet
        entries = report(history, twin, args.robot_id, args.seed,
                         None if quiet else lambda text: print(text, file=sys.stderr, flush=True), args.race_wait)
    finally:
        history.close()
    if not entries:
        raise TwinError(f"--db {display(args.db)}: the history holds no robot yet (live, lap, tune and align write "
                        "one with --db)")
    charts = []
    if args.out_dir:
        with output_dir(args.out_dir, "history folder") as tmp:
            for e in entries:
                name = "".join(ch if ch.isalnum() or ch in "-_." else "_" for ch in e["robot"])
                charts.append(os.path.join(os.path.abspath(args.out_dir), os.path.basename(
                    robot_chart(e, os.path.join(tmp, f"history_{name}.png")))))
            with open(os.path.join(tmp, "history.json"), "w", encoding="utf-8") as f:
                json.dump({"generator": "line-follower-twin", "robots": entries}, f, indent=1, default=_json)
    saved = save_history(args.save, args.view, entries)
    out.document({"db": display(args.db), "robots": entries, "charts": charts, "recording": saved})
    for e in entries:
        say_entry(out, e)
    for what in charts + ([saved] if saved else []):
        out.say(f"wrote {what}")
    return 0


def _json(v):
    return None if isinstance(v, float) and not math.isfinite(v) else str(v)


def say_entry(out: Output, e: dict) -> None:
    """One robot's entry of the history (as `--json` gives it under "robots") in lines for a person."""
    median = f", median lap {e['median_lap_time_s']:.3f} s" if e["median_lap_time_s"] else ""
    out.say(f"{e['kind']} {e['robot']}: {e['laps']} laps, {e['completed']} completed, {e['failed']} failed{median}")
    for ch in e["changes"]:
        stored = f", {ch['stored'].replace('_', ' ')}" if ch.get("stored") else ""  # what it boots on, apart
        out.say(f"  gains #{ch['seq']} ({ch['kind']}, decided at lap {ch['decided_lap']}): {ch['status']}{stored}"
                + (f" — {ch['outcome']}" if ch["outcome"] else ""))
    for address, f in (e.get("forecasts") or {}).items():
        carried = ""  # the value now not read but carried on at its rate (tuner.history.forecast.carried_on)
        if f["evidence"].get("carried_on"):
            carried = f" (carried on from lap {f['evidence']['last_read_lap']}, the last lap read)"
        if f["rate"] is not None:
            lo, mid, hi = f["rate"]
            out.say(f"  {address}: {f['value_now']:.4g} at lap {f['now_lap']}{carried}, {mid:+.3g} per lap (90 %: "
                    f"{lo:+.3g} to {hi:+.3g}), from "
                    f"{f['evidence'].get('alignments_used', f['evidence']['alignments'])} alignments, "
                    f"{f['evidence'].get('observed_laps', 0)} laps read through the twin and {f['evidence']['laps']} "
                    "lap outcomes")
        elif f.get("misfit") is not None:
            out.say(f"  {address}: {f['statement']}")
        for cause, c in (f.get("causes") or {}).items():  # both at once (tuner.history.two_causes)
            lo, mid, hi = c["rate"]
            out.say(f"  {cause} (with {' and '.join(a for a in f['causes'] if a != cause)} at once): "
                    f"{c['value_now']:.4g} at lap {f['now_lap']}{carried}, {mid:+.3g} per lap (90 %: {lo:+.3g} to "
                    f"{hi:+.3g}), from {f['evidence'].get('observed_laps', 0)} laps read through the twin and "
                    f"{f['evidence']['laps']} lap outcomes")
    if e.get("causes_note"):
        out.say(f"  causes: {e['causes_note']}")
    f = e["forecast"]
    if f:
        out.say(f"  forecast (from lap {f['now_lap']}): {f['statement']}")
        if f["raced"] is not None:  # what it rests on (nothing was raced on too little evidence)
            out.say(f"    {f['note']}")
    for a in e["advice"]:
        out.say(f"  advice: {a}")


def _rebuild(args, out: Output) -> int:
    with loading():
        from tuner.history import History, check_db, display, rebuild_log
        from tuner.history.rebuild import read_log

    check_db(args.db)
    logs = [read_log(path) for path in args.log]  # each refused (live writing it, a journal not its own) before any row
    history = History(args.db)
    done = []
    try:
        for log in logs:
            r = rebuild_log(history, log)
            done.append(r)
            out.say(f"rebuilt {r['laps']} laps and {r['journal_records']} journaled records of {r['log']} "
                    f"(replacing {r['runs_replaced']} runs) in {display(args.db)}")
    finally:
        history.close()
    out.document({"db": display(args.db), "rebuilt": done})
    return 0
