"""Telemetry lines into the live twin: one received line, a recorded log replayed, a restart resumed from its log."""

from __future__ import annotations

import os
from typing import Callable

from tuner.live.live_twin import LiveTwin
from twin.link import LinkStats, log_lines
from twin.telemetry.wire import Event, WireError, decode


def replay_log(path: str, live: LiveTwin, stats: LinkStats, realign: bool = False) -> None:
    """Feed a telemetry log (wire lines) through live mode: without re-aligning to resume after a restart,
    or with it to replay a recorded session as if it were live. Lines are split as they were received: a line
    cut off by a drop (marked in the log's break index) is not glued to the next one."""
    for raw in log_lines(path):
        _replay_line(raw, live, stats, realign)


def _replay_line(raw: bytes | None, live: LiveTwin, stats: LinkStats, realign: bool) -> None:
    stats.lines += 1
    if raw is None:  # longer than any wire line, or cut off
        stats.corrupted += 1
        return
    # as fast as the file goes, each lap waits for the alignment the previous ones asked for
    feed_line(raw, live, stats, replay=not realign, before_lap=live.finish if realign else None)


def decode_line(raw: bytes, stats: LinkStats):
    """One received wire line → (its record or None if corrupted, whether it is a lap event: LAP or FAIL)."""
    try:
        rec = decode(raw)
    except WireError:
        stats.corrupted += 1
        return None, False
    lap_event = isinstance(rec, Event) and rec.event in ("LAP", "FAIL")
    stats.robot_laps += lap_event
    return rec, lap_event


def feed_line(raw: bytes, live: LiveTwin, stats: LinkStats, replay: bool = False,
              before_lap: Callable[[], None] | None = None) -> bool:
    """One received wire line → the live twin (a corrupted one only counted); True for a lap event (LAP, FAIL).
    ``before_lap`` runs just before a lap event is fed."""
    rec, lap_event = decode_line(raw, stats)
    if rec is None:
        return False
    if lap_event and before_lap is not None:
        before_lap()
    live.feed(rec, replay=replay)
    return lap_event


def resume(live: LiveTwin, log_path: str) -> int:
    """Replay the laps already in the log (after a restart); with a state that was set aside, re-align on them
    to rebuild it. Returns how many laps the log held."""
    if not os.path.exists(log_path) or os.path.getsize(log_path) == 0:
        return 0
    replay_log(log_path, live, LinkStats(), realign=live.rebuild_from_log)
    live.finish()
    if live.rebuild_from_log:
        live.save_state()
        live.rebuild_from_log = False
    return len(live.laps)
