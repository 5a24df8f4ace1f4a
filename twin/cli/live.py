"""``live``: the twin beside the robot: every received line logged, each lap compared, re-alignment in the
background when laps keep disagreeing; with ``--act``, re-tuned gains sent to the robot, confirmed or rolled
back; what the twin did kept beside the log (``<log>.actions``)."""

from __future__ import annotations

import argparse
import contextlib
import os
import signal
import time
from typing import TYPE_CHECKING, Callable

from lf_common.files import input_file
from twin.cli import library_values as lib
from twin.cli import options as o
from twin.cli import progress
from twin.cli import twin_options as tw
from twin.cli.guard import EXIT_INTERRUPTED, EXIT_NEGATIVE, EXIT_TERMINATED
from twin.cli.output import Output
from twin.cli.startup import loading
from twin.errors import TwinError

if TYPE_CHECKING:
    from tuner.history import HistoryWriter, Journal
    from tuner.live import Actor, LiveOptions, LiveTwin
    from twin.link import LinkStats, LogWriteError, Outbox

HELP = "run the twin beside the robot: compare laps, re-align when they disagree"
RACE_AHEAD_WAIT_S = 600.0  # the longest a planned end waits for the races run ahead (each lap has its timeout)


def add_parser(sub) -> None:
    p = sub.add_parser("live", help=HELP, description=(
        "Reads wire telemetry from --port (a device path, a pty path, or socket://host:port), appends every "
        f"byte received to --log as it arrives and nothing else (fsynced every {lib.LINK_FSYNC_INTERVAL_S:g} s and after each "
        "lap; locked against a second reader; where each connection ended is kept beside it in <log>.breaks), "
        "compares each plausible lap with the twin, and re-aligns --param in the background when the lap time differs by more than --threshold for --k-laps laps. A restart resumes from the "
        "log and its state file. Exit status 1 when the link stayed down for --retry seconds; Ctrl-C or SIGTERM stop "
        "cleanly (log synced, state saved, summary printed) with 130 or 143; a log that cannot be written stops it "
        "the same way, then exit 2 naming the log and the cause."))
    p.add_argument("--port", metavar="PATH_OR_URL",
                   help="serial device, pty path or pyserial URL (socket://HOST:PORT, rfc2217://…)")
    p.add_argument("--replay", metavar="LOG", help="instead of a link: a recorded telemetry log, as fast as it reads")
    o.add_world(p)
    o.add_values(p, "the twin's model-space parameter, repeatable")
    o.add_seed(p, 0, "the twin's noise seed")
    o.add_search(p, "what re-alignment adjusts (default motion.mu)")
    p.add_argument("--threshold", type=o.number(0.0, 1.0, lo_open=True), default=0.005, metavar="FRACTION",
                   help="relative lap-time difference that counts as disagreeing")
    p.add_argument("--k-laps", type=o.count_type, default=2, metavar="N", help="laps in a row above the threshold before re-aligning")
    p.add_argument("--log", default="live_telemetry.log", metavar="FILE", help="telemetry log: every byte received, appended (to an existing file only if "
                   "live wrote it: its <log>.breaks beside it)")
    p.add_argument("--state", metavar="FILE", help="state file (default: <log>.state.json)")
    p.add_argument("--laps", type=o.count_type, metavar="N", help="stop after this many robot laps")
    p.add_argument("--duration", type=o.number(0.0, 10**7, lo_open=True), metavar="WALL_S", help="stop after this many wall-clock seconds")
    p.add_argument("--retry", type=o.number(0.0, 10**6), default=lib.LINK_RETRY_S, metavar="WALL_S",
                   help="how long to keep reopening a link that is down before giving up (exit 1)")
    p.add_argument("--retry-forever", action="store_true", help="keep reopening a link that is down, never give up")
    p.add_argument("--act", action="store_true", help=(
        "act on the robot: after a re-alignment whose value the gains in force no longer finish around, re-tune, "
        "predict, send the gains (wire version 2), wait for the answer, compare the laps that follow with the "
        "prediction and roll back what did worse; one command every lap (GET reads the gains back)"))
    p.add_argument("--act-every", type=o.count_type, default=lib.ACT_EVERY_LAPS, metavar="N",
                   help="at most one change of gains per N laps")
    p.add_argument("--confirm-laps", type=o.count_type, default=lib.ACT_CONFIRM_LAPS, metavar="N",
                   help="laps with new gains compared with the prediction before they are confirmed (or rolled back)")
    o.add_db(p, "the robot's life (robots, runs, laps, alignments, gain changes)")
    p.add_argument("--race-ahead", action=argparse.BooleanOptionalAction, default=None, help=(
        "race the gains in force on the twin in a background process while the robot laps, as history's forecast "
        "will (each part that wears; with --act again for each set that comes into force), so that its first "
        "forecast reads the races from the cache instead of running them (default: on with --db; at a planned "
        f"end, --laps or --duration, live waits for them, at most {RACE_AHEAD_WAIT_S:g} s; stopped unfinished by a "
        "signal or a link given up)"))
    p.add_argument("--ack-timeout", type=o.number(0.01, 3600.0), default=lib.ACT_ACK_TIMEOUT_S, metavar="WALL_S",
                   help="how long to wait for the robot's answer to a command (a STORE unanswered is sent again, "
                        f"{lib.ACT_STORE_TRIES} times in all, then reported not stored)")
    p.add_argument("--retune-deadline", type=o.number(0.1, 86400.0), metavar="WALL_S",
                   help="the longest a re-tune may take: the best gains found by then, or none (default: 10 laps of "
                        "the robot at its median lap time, as far ahead as the gains are raced; the robot does not "
                        "wait)")
    o.add_json(p)
    o.add_recording(p, "the comparison, lap by lap")
    o.add_verbose(p, quiet=True)
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    out = Output(args.json)
    if args.replay and args.port:
        raise TwinError("live: give --port PATH_OR_URL or --replay LOG, not both")
    if args.replay:
        input_file(args.replay, "telemetry log")
        if args.act:
            raise TwinError("live --act: acting needs a robot to send to: give --port, not --replay")
        if args.db:
            raise TwinError("live --replay --db: a log goes into the history with history --rebuild --log LOG --db URL")
    elif not args.port:
        raise TwinError("live: give --port PATH_OR_URL (or --replay LOG)")
    with loading():
        from tuner.live import LiveOptions
        from tuner.recording import LiveRecording
        from twin.link import check_port

    if not args.replay:
        check_port(args.port)  # a malformed URL is refused before the twin is built
    o.check_db(args.db)
    twin = tw.twin_from_args(args)
    warning = tw.gains_warning(args, twin)
    twin.model()
    parameters = args.param or ["motion.mu"]
    if len(parameters) != 1:
        raise TwinError("live: re-aligns one parameter (--param) from lap times")
    address = parameters[0]
    parameter = twin.space.parameter(address)
    bounds = o.parse_bounds(args.bounds, parameters).get(address)  # None: the aligner's default range
    options = LiveOptions(address, bounds, args.threshold, args.k_laps, args.seed)
    rec = LiveRecording(args.save, args.view, address, parameter.unit) if (args.save or args.view) else None
    on_lap = _lap_printer(out, address, rec)
    try:
        if args.replay:
            summary, code, log_error = _replay(args, twin, options, on_lap, out), 0, None
        else:
            summary, code, log_error = _link(args, twin, options, on_lap, out, rec)
    except BaseException as e:
        if rec is not None:
            rec.close(e)
        raise
    if rec is not None:
        rec.close()
    summary["recording"] = rec.saved if rec is not None else None
    summary["gains_warning"] = warning
    out.document(summary)
    if log_error is not None:
        raise log_error  # after the summary: the last line names the log and the cause (exit 2)
    return code


def _lap_printer(out: Output, address: str, rec):
    """One human line per lap received (not per lap replayed from the log), and the recording."""

    def seconds(v) -> str:
        return "failed" if v is None else f"{v:.3f} s"

    def on_lap(e: dict) -> None:
        if not e["replayed"]:
            d = "–" if e["discrepancy"] is None else f"{e['discrepancy'] * 100:+.2f} %"
            why = f"; implausible, ignored: {e['implausible']}" if e["implausible"] else ""
            out.say(f"lap {e['lap']}: robot {seconds(e['robot_lap_time_s'])}, twin {seconds(e['twin_lap_time_s'])} "
                    f"({d}), {address} = {e[address]:.5g}{why}")
        if rec is not None:
            rec.lap(e)

    return on_lap


def _implausible(laps: list[dict]) -> list[dict]:
    return [{"lap": e["lap"], "why": e["implausible"]} for e in laps if e.get("implausible")]


def _replay(args, twin, options: LiveOptions, on_lap, out: Output) -> dict:
    with loading():
        from tuner.live import LiveTwin, replay_log
        from twin.link import LinkStats

    stats = LinkStats()
    live = LiveTwin(twin, options, None, on_lap)
    replay_log(args.replay, live, stats, realign=True)
    live.finish()
    value = twin.space.get(options.address)
    implausible = _implausible(live.laps)
    out.say(f"replayed {len(live.laps)} laps ({len(implausible)} implausible, {stats.corrupted} corrupted lines); "
            f"{options.address} = {value:.5g}")
    return {"laps": len(live.laps), "lines": stats.lines, "corrupted": stats.corrupted,
            "implausible_laps": len(implausible), "implausible": implausible, "value": {options.address: value},
            "alignments": live.alignments, "replayed": os.path.abspath(args.replay)}


def _actor(args, twin, options: LiveOptions, outbox: Outbox, journal: Journal, on_action) -> Actor | None:
    if not args.act:
        return None
    with loading():
        from tuner.history import read_journal
        from tuner.live import ActOptions, Actor

    past = [a for _, a in read_journal(journal.path)]
    known = {a["seq"]: a["gains"] for a in past if a.get("kind") == "decide" and a.get("gains")}
    sent = [a["seq"] for a in past if isinstance(a.get("seq"), int)]
    act = ActOptions(every_laps=args.act_every, confirm_laps=args.confirm_laps, ack_timeout_s=args.ack_timeout,
                     retune_deadline_s=args.retune_deadline)
    actor = Actor(twin, options.address, act, options.seed,
                  lambda line, deadline: outbox.put(line.encode("ascii"), deadline), on_action,
                  next_seq=max(sent, default=0) + 1, known=known)
    actor.retune_progress = progress.Phases(args, "re-tune (race, descent, final race)", "step")
    return actor


def _action_printer(out: Output, journal: Journal, rec, actions: list[dict], db: HistoryWriter | None):
    """Each action: to the journal beside the log (and the database), one human line (commands only to the
    journal), the recording and the summary."""

    def on_action(a: dict) -> None:
        index = journal.write(a)
        if db is not None:
            db.journal_record(a, index)
        if a["kind"] == "command":
            return
        actions.append(a)
        out.say(f"act: {a['kind']}{' #' + str(a['seq']) if a.get('seq') is not None else ''}: {a.get('outcome', '')}")
        if rec is not None:
            rec.action(a)

    return on_action


def _following(on_action, ahead):
    """``on_action``, and the races run ahead follow each set of gains that comes into force."""
    def on(a: dict) -> None:
        on_action(a)
        if a["kind"] == "in_force" and a.get("gains"):
            ahead.follow(a["gains"])

    return on


def _journal_record(journal: Journal, address: str, db: HistoryWriter | None):
    """What the live twin keeps (each lap's twin side, each alignment) to the journal beside the log, and the
    database."""
    with loading():
        from tuner.history import lap_digest

    def on_record(r: dict) -> None:
        if r["kind"] == "lap":
            lap = r["lap_record"]
            record = {"kind": "lap", "lap": r["lap"], "time": round(time.time(), 3), "robot": r["robot"],
                      "gains_seq": r["gains_seq"], "robot_lap_time_s": r["robot_lap_time_s"],
                      "twin_lap_time_s": r["twin_lap_time_s"], "discrepancy": r["discrepancy"],
                      "value": {address: r[address]}, "gains": r["gains"], "implausible": lap.implausible,
                      "digest": lap_digest(lap)}
            journal.write(record)
            if db is not None:
                db.lap(lap, record)
        else:
            index = journal.write(r)
            if db is not None:
                db.journal_record(r, index)

    return on_record


def _link(args, twin, options: LiveOptions, on_lap, out: Output, rec=None) -> tuple[dict, int, LogWriteError | None]:
    """Resume from the log, then read the link until --laps, --duration, Ctrl-C, SIGTERM or a log that cannot be
    written; (summary, exit code, that log error)."""
    with loading():
        from tuner.history import HistoryWriter, Journal, actions_path, check_journal, display
        from tuner.history.race_ahead import RacesAhead
        from tuner.live import LiveTwin, Worker, check_state, decode_line, feed_line, resume
        from twin.link import (DurableLog, LinkGaveUp, LinkStats, LogWriteError, Outbox, breaks_path, check_log,
                               read_link)
        from twin.telemetry.wire import GAIN_ADDRESSES

    state = args.state or f"{args.log}.state.json"
    stats, signalled, gave_up, log_error = LinkStats(), [], None, None
    check_state(state)  # a file that is not a state of ours is refused before the log is even opened
    check_log(args.log)
    check_journal(actions_path(args.log))
    ours = [f for f in (args.log, breaks_path(args.log), actions_path(args.log)) if not os.path.lexists(f)]
    log_file = DurableLog(args.log)  # locked, a cut-off last line marked: before anything reads it
    journal, actions, outbox, db, ahead, race_ahead = None, [], Outbox(), None, None, None
    try:
        if args.race_ahead or (args.race_ahead is None and args.db):
            ahead = RacesAhead(twin, {a: twin.space.get(a) for a in GAIN_ADDRESSES})
        journal = Journal(actions_path(args.log), os.path.basename(args.log))
        db = HistoryWriter(args.db, args.log, out.warn, journal.log_id) if args.db else None
        on_action = _action_printer(out, journal, rec, actions, db)
        if ahead is not None:
            on_action = _following(on_action, ahead)
        actor = _actor(args, twin, options, outbox, journal, on_action)
        live = LiveTwin(twin, options, state, on_lap, actor, _journal_record(journal, options.address, db))
        start_laps = resume(live, args.log)
        if start_laps:
            out.say(f"resumed {start_laps} laps from {args.log}")
        session = {"kind": "session", "time": round(time.time(), 3), "lap": start_laps, "act": bool(args.act),
                   "address": options.address, "port": args.port, "pitch_m": twin.space.get("sensor.pitch"),
                   "gains": {a: v for a, v in twin.space.values.items() if a.startswith("control.")}}
        index = journal.write(session)
        if db is not None:
            db.journal_record(session, index)
        received = _LapCounter()
        stop, ended = _stopper(args, (lambda: len(live.laps) - start_laps) if actor is None else received.count,
                               signalled)
        worker = None
        if actor is not None:  # the laps up to the last are still fed; nothing goes out once the reader stops
            actor.stopping = stop
            worker = Worker(live, ended)

        def on_line(raw: bytes) -> bool:
            if worker is None:
                return feed_line(raw, live, stats)
            record, lap_event = decode_line(raw, stats)
            if record is not None:
                received.see(record)
                worker.put(record)
            return lap_event

        with _stop_on_signals(signalled):  # a clean stop: the log synced, the state saved, the summary printed
            try:
                read_link(args.port, log_file, on_line, (lambda: None) if worker else (lambda: live.feed(None)), stats,
                          stop, None if args.retry_forever else args.retry, outbox)
            except LinkGaveUp as e:
                gave_up = str(e)
            except LogWriteError as e:  # the log is the record: stop as cleanly as for a signal
                log_error = e
            finally:
                if worker is not None:
                    worker.finish()
        live.finish()  # (a second Ctrl-C interrupts this wait: the handlers are back)
        if ahead is not None and not (signalled or gave_up or log_error):  # a planned end: history comes next
            out.say("finishing the twin's races of the gains in force, for history's first forecast")
            race_ahead = ahead.stop(wait_s=RACE_AHEAD_WAIT_S)
    finally:
        if ahead is not None and race_ahead is None:
            race_ahead = ahead.stop()
        log_file.close()
        if journal is not None:
            journal.close()
        if db is not None:
            db.close()
    if gave_up and not stats.opened and not start_laps:  # nothing was ever received: no empty files left behind
        _remove(ours)
    summary = _summary(args, live, stats, start_laps, state, gave_up, signalled)
    summary["log_error"] = str(log_error) if log_error else None
    summary["actions"] = actions
    summary["changes"] = actor.summary() if actor is not None else []
    summary["robot_state"] = actor.robot_state() if actor is not None else None
    summary["keep_alives"] = actor.keep_alives if actor is not None else 0
    summary["race_ahead"] = race_ahead
    summary["journal"] = os.path.abspath(journal.path) if os.path.exists(journal.path) else None
    summary["history"] = None if db is None else {"db": display(args.db), "written": db.written, "error": db.failed}
    if not os.path.exists(args.log):
        summary["log"] = None
    kept = f"log {summary['log']}" if summary["log"] else "the link never opened: no log kept"
    out.say(f"{summary['laps']} laps ({summary['implausible_laps']} implausible), {stats.lines} lines "
            f"({stats.corrupted} corrupted), {stats.reconnects} reconnects; "
            f"{options.address} = {summary['value'][options.address]:.5g}; {kept}")
    if gave_up:
        out.say(f"exit status 1: {gave_up}")
    if signalled:
        return summary, EXIT_INTERRUPTED if signalled[0] == signal.SIGINT else EXIT_TERMINATED, log_error
    return summary, EXIT_NEGATIVE if gave_up else 0, log_error


def _remove(paths: list[str]) -> None:
    """Remove the files this run created (none of the user's: they did not exist before it)."""
    for f in paths:
        with contextlib.suppress(FileNotFoundError):
            os.remove(f)


def _stopper(args, laps: Callable[[], int], signalled: list[int]):
    """(when to stop reading: a signal, ``laps()`` reaching --laps, or --duration wall seconds from now; when the
    run has ended, laps aside: what is still queued is not fed)."""
    t0 = time.monotonic()

    def ended() -> bool:
        return bool(signalled) or (args.duration is not None and time.monotonic() - t0 > args.duration)

    def stop() -> bool:
        return ended() or (args.laps is not None and laps() >= args.laps)

    return stop, ended


class _LapCounter:
    """The laps received (a LAP or FAIL event after a START, as :class:`twin.telemetry.laps.LapAssembler` counts
    them), before the twin has fed them: reading stops at the last lap --laps watches, however far behind the
    twin's decisions are."""

    def __init__(self):
        self.laps, self.started = 0, False

    def see(self, record) -> None:
        event = getattr(record, "event", None)  # (only an Event has one)
        if event == "START":
            self.started = True
        elif event in ("LAP", "FAIL") and self.started:
            self.laps, self.started = self.laps + 1, False

    def count(self) -> int:
        return self.laps


def _summary(args, live: LiveTwin, stats: LinkStats, start_laps: int, state: str, gave_up: str | None,
             signalled: list[int]) -> dict:
    address = live.o.address
    implausible = _implausible(live.laps[start_laps:])
    return {"laps": len(live.laps) - start_laps, "resumed_laps": start_laps, "lines": stats.lines,
            "corrupted": stats.corrupted, "reconnects": stats.reconnects, "implausible_laps": len(implausible),
            "implausible": implausible, "value": {address: live.twin.space.get(address)},
            "alignments": live.alignments, "log": os.path.abspath(args.log), "state": os.path.abspath(state),
            "gave_up": gave_up, "stopped_by": signal.Signals(signalled[0]).name if signalled else None}


@contextlib.contextmanager
def _stop_on_signals(signalled: list[int]):
    """While reading the link, Ctrl-C and SIGTERM ask for a clean stop (noted in ``signalled``) instead of
    raising; the previous handlers come back afterwards."""
    note = lambda signum, frame: signalled.append(signum)  # noqa: E731
    previous = {s: signal.signal(s, note) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
