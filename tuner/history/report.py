"""``history``: per robot, its laps, the changes of its gains, the trend of each aligned parameter, and the forecast
of when the gains in force stop finishing (:mod:`tuner.history.forecast`), read from the history database.

A robot's laps are numbered across its runs (:func:`robot_laps`): the laps of each telemetry log follow those of
the logs before it (by when their first session began), so trends span every run.
"""

from __future__ import annotations

import math
from typing import Callable

import numpy as np
import sqlalchemy as sa

from tuner.history import schema as s
from tuner.history.forecast import SERVICE, STILL_RACING, alone_explains
from tuner.history.store import History
from tuner.history.trend import trend_of
from tuner.history.two_causes import forecasts_of, joint_address
from twin.core.digital_twin import DigitalTwin
from twin.errors import TwinError
from twin.telemetry.wire import GAIN_ADDRESSES

TREND_POINTS = 6  # the trend is fitted to the last this many alignments


def robots(history: History, name: str | None = None) -> list[dict]:
    with history.begin() as c:
        q = sa.select(s.robots).order_by(s.robots.c.name)
        if name is not None:
            q = q.where(s.robots.c.name == name)
        rows = [dict(r._mapping) for r in c.execute(q)]
    if name is not None and not rows:
        with history.begin() as c:
            known = [r.name for r in c.execute(sa.select(s.robots.c.name).order_by(s.robots.c.name))]
        raise TwinError(f"--robot-id {name}: no such robot in the history database (it holds: "
                        f"{', '.join(known[:20]) or 'none'}{', …' if len(known) > 20 else ''})")
    return rows


def robot_laps(c, robot_id: int) -> tuple[list[dict], dict]:
    """The robot's laps in order, each with ``n`` (its number across runs), and the offset of each run's laps."""
    runs = [dict(r._mapping) for r in c.execute(sa.select(s.runs).where(s.runs.c.robot_id == robot_id))]
    logs: dict[str, list[dict]] = {}
    for r in runs:
        logs.setdefault(r["log_path"] or r["source"], []).append(r)
    order = sorted(logs, key=lambda k: (min((r["started"] or math.inf) for r in logs[k]), k))  # ties: by the log
    laps, offsets, base = [], {}, 0
    for key in order:
        ids = [r["id"] for r in logs[key]]
        rows = [dict(x._mapping) for x in c.execute(sa.select(s.laps).where(s.laps.c.run_id.in_(ids))
                                                    .order_by(s.laps.c.lap, s.laps.c.source))]
        for r in logs[key]:
            offsets[r["id"]] = base
        for row in rows:
            row["n"] = base + row["lap"]
            laps.append(row)
        base += (max(r["lap"] for r in rows) + 1) if rows else 0
    return laps, offsets


def _changes(c, robot_id: int, offsets: dict) -> list[dict]:
    rows = c.execute(sa.select(s.gain_changes).where(s.gain_changes.c.robot_id == robot_id).order_by(s.gain_changes.c.id))
    out = []
    for r in rows:
        d = dict(r._mapping)
        base = offsets.get(d["run_id"], 0)
        for k in ("decided_lap", "first_lap"):
            if d[k] is not None:
                d[k] += base
        out.append({k: d[k] for k in ("seq", "kind", "status", "stored", "decided_lap", "first_lap", "gains", "reason",
                                      "predicted_lap_time_s", "nak_reason", "outcome")})
    # in the order of the robot's laps (not of the rows), whatever order the logs were rebuilt in
    return sorted(out, key=lambda ch: (math.inf if ch["decided_lap"] is None else ch["decided_lap"], ch["seq"],
                                       math.inf if ch["first_lap"] is None else ch["first_lap"], ch["status"]))


def _alignments(c, robot_id: int, offsets: dict) -> list[dict]:
    """The robot's alignments in the order of the laps they measured (ties: by address, then value), whatever the
    order their rows were written in: a rebuild of the logs in any order gives the same list."""
    rows = c.execute(sa.select(s.alignments).where(s.alignments.c.robot_id == robot_id))
    out = []
    for r in rows:
        d = dict(r._mapping)
        if d["lap"] is None:
            continue  # an alignment of the twin alone (align): no place among the robot's laps
        base = offsets.get(d["run_id"], 0)
        first = d["first_lap"] if d["first_lap"] is not None else d["lap"]
        out.append({"lap": d["lap"] + base, "first_lap": first + base, "address": d["address"], "value": d["value"],
                    "interval": [d["lo"], d["hi"]] if d["lo"] is not None else None, "explained": d["explained"],
                    "estimated": bool(d["estimated"]), "measured_lap_time_s": d["measured_lap_time_s"],
                    "identifiable": d["identifiable"]})
    return sorted(out, key=_lap_order)


def _lap_order(a: dict) -> tuple:
    return (a["lap"], a["first_lap"], a["address"], a["value"] is None, a["value"] or 0.0, str(a["identifiable"]),
            a["interval"] or (), a["explained"], a["estimated"], a["measured_lap_time_s"] or 0.0)


def gains_in_force(laps: list[dict], changes: list[dict]) -> dict | None:
    """The gains of the robot's last lap (the twin's record of them), else of its last confirmed change."""
    for row in reversed(laps):
        if row["gains"]:
            return {a: row["gains"][a] for a in GAIN_ADDRESSES if a in row["gains"]}
    done = [ch for ch in changes if ch["status"] in ("confirmed", "in_force")]
    return done[-1]["gains"] if done else None


def causes_note(forecasts: dict, aligned: list[dict]) -> str:
    """Which causes the forecast tracks, which of them alone explain the laps, and what the evidence cannot tell
    apart."""
    if not forecasts:
        return "no cause tracked"
    unsure = sorted({a["address"] for a in aligned if a.get("identifiable") is False and not a.get("estimated")})
    worn = tuple(sorted(SERVICE))
    joint = joint_address(worn)  # both at once (tuner.history.two_causes)
    both = joint in forecasts
    alone = [a for a in forecasts if a != joint]
    said = f"tracks {', '.join(alone)}, each on its own (the forecast is the soonest)"
    checked = {a: forecasts[a].misfit for a in alone if forecasts[a].misfit is not None}
    if not checked:
        said += ("; the laps carry one feature (the lap time), which any one cause explains: the evidence cannot "
                 "tell them apart")
    else:
        fits = sorted(a for a in checked if alone_explains(forecasts[a]))
        names = forecasts[next(iter(checked))].evidence["features"]
        read = f"{', '.join(names[:-1])} and {names[-1]}"
        if not fits:
            said += (f"; no one of them alone explains the last laps' {read} together: more than "
                     "one cause is at work (or another)")
            said += (f", so it tracks {' and '.join(worn)} together too" if both else ": no number")
        elif len(fits) == 1:
            said += f"; only {fits[0]} alone explains the last laps' {read} together"
        else:
            said += f"; {', '.join(fits)} each explain the last laps alike: the evidence cannot tell them apart"
    if unsure:
        said += f"; some alignments of {', '.join(unsure)} say other values explain the laps as well"
    return said


def soonest(forecasts):
    """The forecast of the parameter that fails the gains first (by median; one with a number before one
    without, and among those without, one whose races are still running first: it says when to ask again)."""
    ranked = sorted(forecasts, key=lambda f: (f.laps_to_failure is None, f.laps_to_failure or 0.0,
                                              f.note != STILL_RACING, f.address))
    return ranked[0] if ranked else None


def report(history: History, twin: DigitalTwin | None, name: str | None = None, seed: int = 0,
           progress: Callable[[str], None] | None = None, race_wait_s: float | None = None) -> list[dict]:
    """Per robot: laps, changes, trends and (with a ``twin``) the forecast and advice; ``progress`` hears of each
    robot's forecast (a few seconds each) before it begins; ``race_wait_s``: how long a forecast waits for a race
    another process is running (:func:`tuner.history.two_causes.forecasts_of`)."""
    out = []
    for robot in robots(history, name):
        with history.begin() as c:
            laps, offsets = robot_laps(c, robot["id"])
            changes = _changes(c, robot["id"], offsets)
            aligned = _alignments(c, robot["id"], offsets)
        done = [r["lap_time_s"] for r in laps if r["completed"]]
        entry = {"robot": robot["name"], "kind": robot["kind"], "first_seen": robot["first_seen"],
                 "last_seen": robot["last_seen"], "laps": len(laps), "completed": len(done),
                 "failed": sum(not r["completed"] for r in laps),
                 "median_lap_time_s": float(np.median(done)) if done else None,
                 "lap_times": [{"n": r["n"], "lap_time_s": r["lap_time_s"], "completed": r["completed"],
                                "failure": r["failure"], "gains_seq": r["gains_seq"],
                                "twin_lap_time_s": r["twin_lap_time_s"]} for r in laps],
                 "changes": changes, "alignments": aligned, "trends": {}, "forecast": None, "advice": []}
        for address in sorted({a["address"] for a in aligned}):
            t = trend_of(aligned, address, TREND_POINTS)
            entry["trends"][address] = t.summary() if t else None
        gains = gains_in_force(laps, changes)
        entry["gains_in_force"] = gains
        if twin is not None and gains and laps:
            if progress is not None:
                progress(f"forecasting robot {robot['name']}: filtering its evidence, racing its gains on the twin")
            # every aligned parameter, and every part that wears (read from the laps themselves)
            causes = sorted(set(entry["trends"]) | set(SERVICE))
            entry["forecasts"] = forecasts_of(twin, gains, aligned, laps, causes, laps[-1]["n"], seed=seed,
                                              race_wait_s=race_wait_s)
            f = soonest(entry["forecasts"].values())
            entry["causes_tracked"] = causes
            entry["causes_note"] = causes_note(entry["forecasts"], aligned)
            entry["forecasts"] = {a: x.summary() for a, x in entry["forecasts"].items()}
            if f is not None:
                entry["forecast"], entry["advice"] = f.summary(), list(f.advice)
        out.append(entry)
    return out
