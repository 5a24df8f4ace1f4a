"""The robot's telemetry: what the real robot streams and logs, and what the twin can write for a lap.

Format ``lf-telemetry`` version 1, JSON Lines (one JSON object per line, UTF-8):

* line 1, the header: ``{"type": "header", "format": "lf-telemetry", "version": 1, "track": "oval",
  "sensors": 8, "dt_s": 0.005, "every": 2, "gains": {"control.v_max": 1.2, ...}, "source": "twin"}``:
  control period Δt [s], one sample every ``every`` control ticks, the firmware's gains (``control.*``).
* samples: ``{"type": "sample", "t": 0.51, "pos": 3512, "seen": 1, "wl": 41.2, "wr": 43.9}``: time since the
  start of the lap [s], readLine position 0..(sensors−1)·1000, line seen 0/1, left and right wheel
  encoder speeds [rad/s]. Optional ``"s"``: the calibrated readings, a list of ``sensors`` integers 0..1000.
* events: ``{"type": "event", "t": 7.31, "event": "lap", "lap_time_s": 7.31}``; ``"start"`` at t = 0, ``"lap"`` when a lap
  completes, ``"fail"`` with ``"reason"`` when the robot stops following the line.

Samples are in time order. A line that is not JSON, or lacks a field, is an error naming its line number.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os

import numpy as np

from twin.errors import TwinError
from twin.lap import COL, LapResult

FORMAT, VERSION = "lf-telemetry", 1


@dataclasses.dataclass(frozen=True)
class Telemetry:
    """A recorded run: the header, samples as arrays (time order) and events."""

    header: dict
    t: np.ndarray  # [s]
    pos: np.ndarray  # readLine position
    seen: np.ndarray  # 0/1
    wl: np.ndarray  # [rad/s]
    wr: np.ndarray  # [rad/s]
    events: tuple[dict, ...]

    @property
    def lap_time_s(self) -> float | None:
        laps = [e for e in self.events if e.get("event") == "lap"]
        return float(laps[0]["lap_time_s"]) if laps else None


def _number(path: str, n: int, obj: dict, key: str) -> float:
    v = obj.get(key)
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise TwinError(f"{path}:{n}: field {key!r} must be a finite number, got {v!r}")
    return float(v)


def read_telemetry(path: str) -> Telemetry:
    """Parse and check a telemetry file; errors name the file and line."""
    try:
        f = open(path, encoding="utf-8")
    except OSError as e:
        raise TwinError(f"{path}: cannot read telemetry ({e.strerror or e})") from None
    header, rows, events = None, [], []
    with f:
        for n, line in enumerate(f, start=1):
            if not line.strip():
                continue
            try:
                obj = json.loads(line)
            except json.JSONDecodeError as e:
                raise TwinError(f"{path}:{n}: not a JSON object ({e.msg})") from None
            except UnicodeDecodeError:
                raise TwinError(f"{path}:{n}: not UTF-8 text") from None
            if not isinstance(obj, dict) or "type" not in obj:
                raise TwinError(f"{path}:{n}: expected an object with a \"type\"")
            kind = obj["type"]
            if header is None:
                if kind != "header" or obj.get("format") != FORMAT:
                    raise TwinError(f"{path}:{n}: the first line must be the {FORMAT} header")
                if obj.get("version") != VERSION:
                    raise TwinError(f"{path}:{n}: {FORMAT} version {obj.get('version')!r} is not supported (this reads {VERSION})")
                for key in ("dt_s", "sensors"):
                    _number(path, n, obj, key)
                header = obj
            elif kind == "sample":
                row = [_number(path, n, obj, k) for k in ("t", "pos", "seen", "wl", "wr")]
                if rows and row[0] <= rows[-1][0]:
                    raise TwinError(f"{path}:{n}: sample time {row[0]:g} s does not follow {rows[-1][0]:g} s")
                rows.append(row)
            elif kind == "event":
                _number(path, n, obj, "t")
                if not isinstance(obj.get("event"), str):
                    raise TwinError(f"{path}:{n}: an event needs an \"event\" name")
                if obj["event"] == "lap":
                    _number(path, n, obj, "lap_time_s")
                events.append(obj)
            elif kind != "header":
                raise TwinError(f"{path}:{n}: unknown line type {kind!r}")
            else:
                raise TwinError(f"{path}:{n}: a second header")
    if header is None:
        raise TwinError(f"{path}: empty telemetry file")
    if len(rows) < 2:
        raise TwinError(f"{path}: fewer than two samples")
    a = np.array(rows)
    return Telemetry(header, a[:, 0], a[:, 1], a[:, 2], a[:, 3], a[:, 4], tuple(events))


def lap_lines(lap: LapResult, header: dict, every: int) -> list[dict]:
    """A lap of the twin as telemetry lines (header first)."""
    tr = lap.trace
    if tr is None:
        raise TwinError("telemetry: the lap has no trace")
    rec = tr.records[::every]
    lines = [{"type": "header", "format": FORMAT, "version": VERSION, **header, "every": every},
             {"type": "event", "t": 0.0, "event": "start"}]
    for r, s in zip(rec, tr.calibrated[::every]):
        lines.append({"type": "sample", "t": round(float(r[COL["time_s"]]), 6), "pos": int(r[COL["position"]]),
                      "seen": int(r[COL["line_seen"]]), "wl": round(float(r[COL["wheel_left_radps"]]), 4),
                      "wr": round(float(r[COL["wheel_right_radps"]]), 4), "s": [int(v) for v in s]})
    if lap.completed:
        lines.append({"type": "event", "t": lap.lap_time_s, "event": "lap", "lap_time_s": lap.lap_time_s})
    else:
        lines.append({"type": "event", "t": lap.simulated_s, "event": "fail", "reason": lap.failure})
    return lines


def write_telemetry(path: str, lines: list[dict]) -> str:
    """Write telemetry lines atomically; returns the path."""
    path = os.path.abspath(path)
    tmp = f"{path}.{os.getpid()}.tmp"
    try:
        with open(tmp, "w", encoding="utf-8") as f:
            for obj in lines:
                f.write(json.dumps(obj, separators=(",", ":")) + "\n")
        os.replace(tmp, path)
    except OSError as e:
        if os.path.exists(tmp):
            os.remove(tmp)
        raise TwinError(f"{path}: cannot write telemetry ({e.strerror or e})") from None
    return path
