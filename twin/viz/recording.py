"""rerun recordings of laps: the track, the robot's path, sensor readings and control signals over time.

Whole series go in with ``send_columns`` (one call per signal, not one per tick), and a blueprint lays the
views out, one unit per panel. Files are written to a temporary name and renamed when complete, so a crash
leaves no half file; ``--view`` alone streams to the viewer and writes nothing.
"""

from __future__ import annotations

import contextlib
import os
import re
import shutil
import tempfile
import threading
from typing import Iterator, Sequence

import numpy as np
import rerun as rr
import rerun.blueprint as rrb
from PIL import Image

from mjcf.maze import Maze
from mjcf.track import FloorTexture, Track
from lf_common.errors import OutputError
from lf_common.files import atomic_file, check_output_file, rrd_is_ours
from twin.viz import viewer
from twin.errors import TwinError
from twin.core.lap import LapResult

APP_ID = "line-follower-twin"
TIMELINE = "sim_time"
RELAY_CLOSE_S = 120.0  # [s] for rerun to finish a recording once it is disconnected
MAP_PIXEL_M = 0.004  # the floor image in the recording: 4 mm pixels keep a default-track file ~0.2 MB


def lap_blueprint(count: int, shows: bool = False) -> rrb.Blueprint:
    robot = [rrb.TextLogView(name="LCD", origin="/robot/lcd"),
             rrb.TimeSeriesView(name="buzzer [Hz]", origin="/robot/buzzer"),
             rrb.TimeSeriesView(name="LEDs (1 lit)", origin="/robot/led")] if shows else []
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Spatial2DView(name="track", origin="/track"),
            rrb.Vertical(
                *robot,
                rrb.TimeSeriesView(name="line angle e [rad]", origin="/control/e"),
                rrb.TimeSeriesView(name="speed v [m/s]", origin="/control/v"),
                rrb.TimeSeriesView(name="turn rate ω [rad/s]", origin="/control/omega"),
                rrb.TimeSeriesView(name="motor voltage [V]", contents=["/motors/left", "/motors/right"]),
                rrb.TimeSeriesView(name="energy drawn [J]", origin="/energy"),
                rrb.TimeSeriesView(name=f"calibrated readings 0..1000 ({count} sensors)", origin="/sensors/calibrated"),
                rrb.TimeSeriesView(name="cross-track error [m]", origin="/lap/cross_track"),
            ),
            column_shares=[3, 2],
        ),
        collapse_panels=True,
    )


class _Map:
    """World metres → pixels of the downsampled floor image logged under /track."""

    def __init__(self, texture: FloorTexture):
        self.step = max(1, int(round(MAP_PIXEL_M / texture.metres_per_pixel)))
        self.texture = texture
        self.image = texture.grey[:: self.step, :: self.step]

    def px(self, xy: np.ndarray) -> np.ndarray:
        row, col = self.texture.pixel_of(xy)
        return np.stack([col, row], axis=-1) / self.step


def _series(rec: rr.RecordingStream, path: str, t: np.ndarray, values: np.ndarray) -> None:
    rr.send_columns(path, indexes=[rr.TimeColumn(TIMELINE, duration=t)], columns=rr.Scalars.columns(scalars=values),
                    recording=rec)


def log_lap(rec: rr.RecordingStream, track: Track, texture: FloorTexture, result: LapResult, name: str = "robot") -> None:
    """Log one lap (it must carry its trace) under /track/<name> and the time series."""
    tr = result.trace
    if tr is None:
        raise TwinError("recording: the lap has no trace (run it with keep_traces=True)")
    m = _Map(texture)
    t = tr.time_s
    path = m.px(tr.records[:, 1:3])
    rr.log(f"track/{name}/path", rr.LineStrips2D([path], radii=0.6, colors=[[230, 60, 40]]), static=True, recording=rec)
    rr.send_columns(f"track/{name}/position", indexes=[rr.TimeColumn(TIMELINE, duration=t)],
                    columns=rr.Points2D.columns(positions=path).partition(np.ones(len(t), dtype=int)), recording=rec)
    for col, entity in (("e_rad", "control/e"), ("v_mps", "control/v"), ("omega_radps", "control/omega"),
                        ("u_left_v", "motors/left"), ("u_right_v", "motors/right"), ("energy_j", "energy/motors")):
        _series(rec, entity, t, tr.column(col))
    _series(rec, "lap/cross_track", t, tr.cross_track_m)
    _series(rec, "lap/progress", t, tr.progress_m)
    for i in range(tr.count):
        _series(rec, f"sensors/calibrated/{i}", t, tr.calibrated[:, i])
        _series(rec, f"sensors/raw/{i}", t, tr.raw_us[:, i])


def log_track(rec: rr.RecordingStream, track: Track, texture: FloorTexture) -> None:
    m = _Map(texture)
    rr.log("track/floor", rr.Image(m.image), static=True, recording=rec)
    if isinstance(track, Maze):  # its segments, and the finish spot
        strips = [m.px(seg) for seg in track.segments_xy]
        rr.log("track/centre_line", rr.LineStrips2D(strips, radii=0.3, colors=[[40, 120, 230]]), static=True,
               recording=rec)
        rr.log("track/finish", rr.Points2D(m.px(track.finish_xy[None]), radii=3.0, colors=[[230, 60, 40]],
                                           labels=["finish"]), static=True, recording=rec)
    else:
        centre = m.px(np.vstack([track.centre, track.centre[:1]]))
        rr.log("track/centre_line", rr.LineStrips2D([centre], radii=0.3, colors=[[40, 120, 230]]), static=True,
               recording=rec)
    start = m.px(track.centre[:1])
    rr.log("track/start", rr.Points2D(start, radii=3.0, colors=[[40, 200, 80]], labels=["start"]), static=True, recording=rec)


def check_targets(save: str | None, view: bool) -> None:
    """Before any work: the recording can be written where asked, and a viewer exists if asked. Without a
    display, ``view`` alone is refused now; with ``save`` the work is done and saved first (see :func:`recording`)."""
    if save:
        check_output_file(save, rrd_is_ours, "recording")
    if view:
        viewer.viewer_executable()
        if not save:
            viewer.require_display()


class _Relay:
    """rerun's file sink writes into a named pipe; a thread copies what comes through into the recording's file.
    A write that fails (a full disk) is kept and reported by :meth:`check` as an :class:`OutputError` naming the
    file and the cause, and the pipe is still drained, so rerun never sees a failure: its own file sink, failing,
    said only "File-writer thread shut down prematurely", printed its own lines after ours, and hung the next
    flush for good. (Its in-memory stream would hold a long session in memory, and pieces of it read one by one
    do not make a valid file.)"""

    def __init__(self, path: str, file):
        self.path, self.file, self.error, self.opened = path, file, None, threading.Event()
        self.folder = tempfile.mkdtemp(prefix="lf-recording-")
        self.pipe = os.path.join(self.folder, "recording.rrd")
        os.mkfifo(self.pipe, 0o600)
        self.thread = threading.Thread(target=self._copy, name="recording-writer", daemon=True)
        self.thread.start()

    def _copy(self) -> None:
        with open(self.pipe, "rb", buffering=0) as pipe:  # returns once rerun has opened its end
            self.opened.set()
            while chunk := pipe.read(1 << 16):
                if self.error is None:
                    try:
                        self.file.write(chunk)
                    except OSError as e:
                        self.error = e

    def check(self) -> None:
        if self.error is not None:
            raise OutputError(f"{self.path}: cannot write the recording ({self.error.strerror or self.error})")

    def close(self) -> None:
        """Once rerun has let go of the pipe: wait for its last bytes, and remove the pipe."""
        if not self.opened.is_set():  # rerun never opened it (it failed first): let the thread's open return
            with contextlib.suppress(OSError):
                os.close(os.open(self.pipe, os.O_WRONLY | os.O_NONBLOCK))
        self.thread.join(RELAY_CLOSE_S)
        shutil.rmtree(self.folder, ignore_errors=True)
        if self.thread.is_alive() and self.error is None:
            self.error = OSError(0, f"rerun did not finish it within {RELAY_CLOSE_S:g} s")


_relays: dict[rr.RecordingStream, _Relay] = {}


def flush(rec: rr.RecordingStream) -> None:
    """Send what was logged to the viewer and to the file; a write that failed is reported now (see
    :func:`recording`)."""
    rec.flush()
    if rec in _relays:
        _relays[rec].check()


@contextlib.contextmanager
def recording(save: str | None, view: bool, blueprint: rrb.Blueprint, app_id: str = APP_ID) -> Iterator[rr.RecordingStream | None]:
    """A recording streamed to a viewer (``view``) and/or saved to ``save``; None when neither is asked.

    The file is written under a temporary name and renamed into place when the ``with`` block completes, and
    replaces only a recording this program wrote; a failure leaves no file, and a write that fails is an
    :class:`OutputError` naming the file and the cause. With ``view`` alone nothing is written to disk: the data
    streams to the viewer. With ``view`` but no display, the recording is saved and then the missing display is
    reported (TwinError): the work is kept, the window could not open.
    """
    if not save and not view:
        yield None
        return
    check_targets(save, view)
    show = view and viewer.has_display()
    with contextlib.ExitStack() as stack:
        relay = _Relay(save, stack.enter_context(atomic_file(save, rrd_is_ours, "recording", binary=True))) if save else None
        rec = rr.RecordingStream(app_id)
        try:
            sinks = [rr.FileSink(relay.pipe)] if relay else []
            if show:
                sinks.append(rr.GrpcSink(viewer.spawn_for_stream()))
            if relay:
                _relays[rec] = relay
            rec.set_sinks(*sinks, default_blueprint=blueprint)
            yield rec
            flush(rec)
        finally:
            rec.disconnect()  # rerun ends the file and lets go of the pipe
            if relay:
                _relays.pop(rec, None)
                relay.close()
        if relay:
            relay.check()  # the last bytes too, before the file is renamed into place
    if view and not show:
        viewer.require_display(os.path.abspath(save))  # saved above; now say why no window opened


@contextlib.contextmanager
def recording_file(out_path: str, blueprint: rrb.Blueprint) -> Iterator[rr.RecordingStream]:
    """A recording saved to ``out_path`` only (see :func:`recording`)."""
    with recording(out_path, False, blueprint) as rec:
        yield rec


def save_laps(save: str | None, view: bool, track: Track, texture: FloorTexture, results: Sequence[LapResult],
              names: Sequence[str], shows: dict | None = None) -> str | None:
    """Laps to a saved recording and/or the viewer (see :func:`recording`); returns the saved path, if any.
    ``shows``: what the robot showed during the first lap (:func:`log_shows`)."""
    if not save and not view:
        return None
    count = results[0].trace.count if results and results[0].trace else 8
    with recording(save, view, lap_blueprint(count, shows is not None)) as rec:
        log_track(rec, track, texture)
        for r, n in zip(results, names):
            log_lap(rec, track, texture, r, n)
        if shows is not None:
            log_shows(rec, shows)
    return os.path.abspath(save) if save else None


def log_shows(rec: rr.RecordingStream, shows: dict) -> None:
    """What the robot showed, on the lap's timeline [s]: ``lcd`` [(t, text)] as a text log under /robot/lcd, ``notes``
    [(start, end, Hz)] as the buzzer's frequency under /robot/buzzer (0 between notes), ``leds`` [(t, red, green)]
    as 0/1 series under /robot/led/red and /robot/led/green."""
    for t, text in shows.get("lcd", ()):
        rr.set_time(TIMELINE, duration=t, recording=rec)
        rr.log("robot/lcd", rr.TextLog(" / ".join(line.rstrip() for line in text.split("\n"))), recording=rec)
    rec.reset_time()
    notes = shows.get("notes", ())
    if notes:
        t = np.array([x for a, b, _ in notes for x in (a, b)])
        hz = np.array([x for _, _, f in notes for x in (f, 0.0)])
        _series(rec, "robot/buzzer", t, hz)
    leds = shows.get("leds", ())
    if leds:
        t = np.array([e[0] for e in leds])
        _series(rec, "robot/led/red", t, np.array([float(e[1]) for e in leds]))
        _series(rec, "robot/led/green", t, np.array([float(e[2]) for e in leds]))


def save_charts(save: str | None, view: bool, charts: dict[str, str]) -> str | None:
    """PNG charts as images, one panel each ({panel name: PNG path}); returns the saved path, if any."""
    if not save and not view:
        return None
    entities = {name: "charts/" + re.sub(r"[^A-Za-z0-9_.-]+", "_", name) for name in charts}
    blueprint = rrb.Blueprint(rrb.Horizontal(*(rrb.Spatial2DView(name=name, origin="/" + e) for name, e in entities.items())),
                              collapse_panels=True)
    with recording(save, view, blueprint) as rec:
        for name, path in charts.items():
            with Image.open(path) as img:
                rr.log(entities[name], rr.Image(np.asarray(img.convert("RGB"))), static=True, recording=rec)
    return os.path.abspath(save) if save else None
