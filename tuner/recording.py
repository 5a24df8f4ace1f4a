"""rerun recordings of the learning model's work: tuning runs, alignments, design studies and the live twin.

Each writer takes ``save`` (a path or None) and ``view`` (stream to the viewer) and goes through
:func:`twin.viz.recording.recording`: atomic files that replace only recordings of ours, one unit per panel.
"""

from __future__ import annotations

import os
import re
from typing import Sequence

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from twin.viz import recording as twin_recording
from twin.core.digital_twin import DigitalTwin
from twin.core.lap import LapResult
from twin.viz.recording import log_lap, log_track, recording
from twin.telemetry.jsonl import Telemetry
from tuner.search.gradient import Iteration
from tuner.search.space import SearchSpace


def _saved(save: str | None) -> str | None:
    return os.path.abspath(save) if save else None


def _series(rec: rr.RecordingStream, entity: str, index: list, values) -> None:
    rr.send_columns(entity, indexes=index, columns=rr.Scalars.columns(scalars=values), recording=rec)


def save_tuning(save: str | None, view: bool, twin: DigitalTwin, space: SearchSpace, iterations: Sequence[Iteration],
                best_lap: LapResult, per_iteration: Sequence[dict] = ()) -> str | None:
    """Each iteration's cost and parameters (raw and as a fraction of their bounds), each scenario's median lap
    per iteration (``per_iteration``: the tuner's records), and the best lap."""
    if not save and not view:
        return None
    blueprint = rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(
                rrb.TimeSeriesView(name="cost (lap time, failures penalised) [s]", origin="/tuning/lap_time"),
                rrb.TimeSeriesView(name="median lap per scenario [s]", origin="/tuning/scenario"),
                rrb.TimeSeriesView(name="parameters (fraction of their bounds) [-]", origin="/tuning/normalised"),
            ),
            rrb.Spatial2DView(name="best lap", origin="/track"),
        ),
        collapse_panels=True,
    )
    with recording(save, view, blueprint) as rec:
        index = [rr.TimeColumn("iteration", sequence=np.array([it.k for it in iterations]))]
        _series(rec, "tuning/lap_time", index, [it.cost for it in iterations])
        for i, a in enumerate(space.addresses):
            _series(rec, f"tuning/normalised/{a}", index, np.array([it.z[i] for it in iterations]))
            _series(rec, f"tuning/value/{a}", index, space.from_unit(np.array([it.z for it in iterations]))[:, i])
        for j, name in enumerate(r["scenario"] for r in (per_iteration[0]["scenarios"] if per_iteration else [])):
            medians = [float(np.median(it["scenarios"][j]["lap_times_s"])) if it["scenarios"][j]["lap_times_s"]
                       else np.nan for it in per_iteration]
            _series(rec, f"tuning/scenario/{re.sub(r'[^A-Za-z0-9_.-]+', '_', name)}", [rr.TimeColumn("iteration", sequence=[it["iteration"] for it in
                                                                                          per_iteration])], medians)
        log_track(rec, twin.track, twin.texture)
        log_lap(rec, twin.track, twin.texture, best_lap, "best")
    return _saved(save)


def save_alignment(save: str | None, view: bool, result, unit: str) -> str | None:
    """The aligned parameter and the lap time, lap by lap, against the measurement (paper Fig. 6b–c)."""
    if not save and not view:
        return None
    blueprint = rrb.Blueprint(rrb.Vertical(
        rrb.TimeSeriesView(name=f"{result.parameter} [{unit}]", origin="/align/value"),
        rrb.TimeSeriesView(name="lap time [s]", contents=["/align/lap_time", "/align/measured"]),
    ), collapse_panels=True)
    with recording(save, view, blueprint) as rec:
        pts = [p for p in result.trace if p.lap_time_s is not None]
        index = [rr.TimeColumn("lap", sequence=np.arange(len(pts)))]
        _series(rec, "align/value", index, [p.value for p in pts])
        _series(rec, "align/lap_time", index, [p.lap_time_s for p in pts])
        _series(rec, "align/measured", index, np.full(len(pts), result.measured_lap_time_s))
    return _saved(save)


def save_trace_alignment(save: str | None, view: bool, tel: Telemetry, result) -> str | None:
    """The robot's recorded wheel speeds and line position against the twin's at the fitted values."""
    if not save and not view:
        return None
    blueprint = rrb.Blueprint(rrb.Vertical(
        rrb.TimeSeriesView(name="left wheel speed [rad/s]", origin="/trace/wheel_left"),
        rrb.TimeSeriesView(name="right wheel speed [rad/s]", origin="/trace/wheel_right"),
        rrb.TimeSeriesView(name="line position (readLine) [-]", origin="/trace/line_position"),
    ), collapse_panels=True)
    with recording(save, view, blueprint) as rec:
        series = [("robot", tel.t, tel.wl, tel.wr, tel.pos)]
        tr = result.best_lap.trace if result.best_lap is not None else None
        if tr is not None:
            series.append(("twin", tr.time_s, tr.column("wheel_left_radps"), tr.column("wheel_right_radps"),
                           tr.column("position")))
        for who, t, wl, wr, pos in series:
            index = [rr.TimeColumn("lap_time", duration=np.asarray(t))]
            _series(rec, f"trace/wheel_left/{who}", index, wl)
            _series(rec, f"trace/wheel_right/{who}", index, wr)
            _series(rec, f"trace/line_position/{who}", index, pos)
    return _saved(save)


class LiveRecording:
    """The live comparison, streamed lap by lap: both lap times, their discrepancy, the aligned parameter,
    and both laps' wheel speed and line position on one lap-time axis (where they part is visible)."""

    def __init__(self, save: str | None, view: bool, address: str, unit: str):
        self.address = address
        blueprint = rrb.Blueprint(rrb.Horizontal(
            rrb.Vertical(
                rrb.TimeSeriesView(name="lap time [s]", origin="/live/lap_time"),
                rrb.TimeSeriesView(name="discrepancy, robot vs twin [-]", origin="/live/discrepancy"),
                rrb.TimeSeriesView(name=f"{address} [{unit}]", origin=f"/live/{address}"),
                rrb.TimeSeriesView(name="gains in force", origin="/live/gains"),
            ),
            rrb.Vertical(
                rrb.TimeSeriesView(name="left wheel speed [rad/s]", origin="/live/wheel_left"),
                rrb.TimeSeriesView(name="line position (readLine) [-]", origin="/live/line_position"),
                rrb.TextLogView(name="what the twin did (--act)", origin="/live/actions"),
            ),
        ), collapse_panels=True)
        self._context = recording(save, view, blueprint, app_id=f"{twin_recording.APP_ID}-live")
        self.rec = self._context.__enter__()
        self.saved = _saved(save)

    def lap(self, e: dict) -> None:
        rec = self.rec
        rec.set_time("lap", sequence=e["lap"])
        if e["robot_lap_time_s"]:
            rec.log("live/lap_time/robot", rr.Scalars(e["robot_lap_time_s"]))
        if e["twin_lap_time_s"]:
            rec.log("live/lap_time/twin", rr.Scalars(e["twin_lap_time_s"]))
        if e["discrepancy"] is not None:
            rec.log("live/discrepancy", rr.Scalars(e["discrepancy"]))
        rec.log(f"live/{self.address}", rr.Scalars(e[self.address]))
        for address, value in (e.get("gains") or {}).items():
            rec.log(f"live/gains/{address.removeprefix('control.')}", rr.Scalars(value))
        lap, twin_trace = e["lap_record"], e["twin_lap"].trace
        series = [("robot", lap.t, lap.wl, lap.pos)]
        if twin_trace is not None:
            series.append(("twin", twin_trace.time_s, twin_trace.column("wheel_left_radps"), twin_trace.column("position")))
        for who, t, wl, pos in series:
            if len(t):
                index = [rr.TimeColumn("lap_time", duration=t)]
                rec.send_columns(f"live/wheel_left/{who}", indexes=index, columns=rr.Scalars.columns(scalars=wl))
                rec.send_columns(f"live/line_position/{who}", indexes=index, columns=rr.Scalars.columns(scalars=pos))
        twin_recording.flush(rec)  # to the viewer, and to the file lap by lap

    def action(self, a: dict) -> None:
        """One action of ``live --act`` (what, which command, the outcome), on the lap it was taken."""
        self.rec.set_time("lap", sequence=a.get("lap", 0))
        seq = f" #{a['seq']}" if a.get("seq") is not None else ""
        level = "WARN" if a["kind"] in ("nak", "silent", "rollback", "hold") else "INFO"
        self.rec.log("live/actions", rr.TextLog(f"{a['kind']}{seq}: {a.get('outcome', '')}", level=level))
        twin_recording.flush(self.rec)

    def close(self, error: BaseException | None = None) -> None:
        """Finish the recording (renamed into place); after an error the partial file is discarded."""
        if error is None:
            self._context.__exit__(None, None, None)
        else:
            self._context.__exit__(type(error), error, error.__traceback__)


def save_history(save: str | None, view: bool, entries: Sequence[dict]) -> str | None:
    """Each robot's life (``history``): lap times and the twin's predictions, the aligned parameter, the filter's
    estimate of it lap by lap with its 90 % band, and the failed laps (at the value where the twin fails the gains
    in force), by the robot's lap counted across runs; each change of gains as a text line on the lap it came into force."""
    if not save and not view:
        return None
    blueprint = rrb.Blueprint(rrb.Horizontal(
        rrb.TimeSeriesView(name="lap time [s]", origin="/history", contents=["/history/**/lap_time/**"]),
        rrb.TimeSeriesView(name="aligned parameters", origin="/history", contents=["/history/**/aligned/**"]),
        rrb.TextLogView(name="gain changes", origin="/history"),
    ), collapse_panels=True)
    with recording(save, view, blueprint, app_id=f"{twin_recording.APP_ID}-history") as rec:
        for e in entries:
            robot = re.sub(r"[^A-Za-z0-9_.-]+", "_", e["robot"])
            for who, key in (("robot", "lap_time_s"), ("twin", "twin_lap_time_s")):
                rows = [r for r in e["lap_times"] if r[key] is not None]
                if rows:
                    _series(rec, f"history/{robot}/lap_time/{who}", [rr.TimeColumn("lap", sequence=[r["n"] for r in rows])],
                            [r[key] for r in rows])
            for address in e["trends"]:
                pts = [a for a in e["alignments"] if a["address"] == address and a["value"] is not None]
                if pts:
                    _series(rec, f"history/{robot}/aligned/{address}", [rr.TimeColumn("lap", sequence=[a["lap"] for a in pts])],
                            [a["value"] for a in pts])
            for address, f in (e.get("forecasts") or {}).items():  # the filter's estimate and its 90 % band
                bands = [(address, f["band"])] if f.get("band") else []
                bands += [(f"{c}_with_{'+'.join(o for o in f['causes'] if o != c)}", x["band"])  # both at once
                          for c, x in (f.get("causes") or {}).items() if x.get("band")]
                for name_of, band in bands:
                    laps = [rr.TimeColumn("lap", sequence=[b[0] for b in band])]
                    for k, name in ((1, "q05"), (2, "median"), (3, "q95")):
                        _series(rec, f"history/{robot}/aligned/{name_of}_estimate/{name}", laps, [b[k] for b in band])
                failed = [r["n"] for r in e["lap_times"] if not r["completed"]]
                if failed and f.get("failing_value") is not None:
                    _series(rec, f"history/{robot}/aligned/{address}_failed_laps", [rr.TimeColumn("lap", sequence=failed)],
                            [f["failing_value"]] * len(failed))
            for ch in e["changes"]:
                at = ch["first_lap"] if ch["first_lap"] is not None else ch["decided_lap"]
                rec.set_time("lap", sequence=at or 0)
                rec.log(f"history/{robot}/changes", rr.TextLog(f"#{ch['seq']} {ch['kind']} {ch['status']}: {ch['outcome'] or ''}"))
    return _saved(save)
