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

Samples are in time order. A line that is not JSON, or lacks a field, is an error naming its line number. The
header's ``track`` must be a name (a string) and its ``gains`` an object of ``control.*`` numbers: a header cannot
set the robot's physics. Files are read up to 256 MB; a lap at 100 samples/s is about 1 MB.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os

import numpy as np

from lf_common.files import GENERATOR, atomic_file, jsonl_is_ours, parse_json, read_text
from twin.errors import TwinError
from twin.core.lap import COL, LapResult

FORMAT, VERSION = "lf-telemetry", 1
MAX_BYTES = 256 * 2**20


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
    def gains(self) -> dict[str, float]:
        """The header's firmware gains (checked when read): {control.address: value}."""
        return dict(self.header.get("gains") or {})

    @property
    def lap_time_s(self) -> float | None:
        laps = [e for e in self.events if e.get("event") == "lap"]
        return float(laps[0]["lap_time_s"]) if laps else None


def _number(path: str, n: int, obj: dict, key: str) -> float:
    v = obj.get(key)
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise TwinError(f"{path}:{n}: field {key!r} must be a finite number, got {str(v)[:40]!r}")
    return float(v)


def _check_header(path: str, n: int, obj: dict) -> dict:
    if obj.get("format") != FORMAT:
        raise TwinError(f"{path}:{n}: the first line must be the {FORMAT} header")
    if obj.get("version") != VERSION:
        raise TwinError(f"{path}:{n}: {FORMAT} version {str(obj.get('version'))[:20]} is not supported (this reads {VERSION})")
    for key in ("dt_s", "sensors"):
        _number(path, n, obj, key)
    if "track" in obj and not isinstance(obj["track"], str):
        raise TwinError(f"{path}:{n}: \"track\" must be a track name or image path, got {str(obj['track'])[:40]!r}")
    if "gains" in obj:
        gains = obj["gains"]
        if not isinstance(gains, dict):
            raise TwinError(f"{path}:{n}: \"gains\" must be an object of control.* numbers")
        for address in gains:
            if not isinstance(address, str) or not address.startswith("control."):
                raise TwinError(f"{path}:{n}: header gains hold control.* parameters only, not {str(address)[:40]!r}")
            _number(path, n, gains, address)
    return obj


def read_telemetry(path: str) -> Telemetry:
    """Parse and check a telemetry file; errors name the file and line."""
    text = read_text(path, MAX_BYTES, "telemetry file")
    header, rows, events = None, [], []
    for n, line in enumerate(text.splitlines(), start=1):
        if not line.strip():
            continue
        obj = parse_json(line, f"{path}:{n}")
        if not isinstance(obj, dict) or "type" not in obj:
            raise TwinError(f"{path}:{n}: expected an object with a \"type\"")
        kind = obj["type"]
        if header is None:
            if kind != "header":
                raise TwinError(f"{path}:{n}: the first line must be the {FORMAT} header")
            header = _check_header(path, n, obj)
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
            raise TwinError(f"{path}:{n}: unknown line type {str(kind)[:40]!r}")
        else:
            raise TwinError(f"{path}:{n}: a second header")
    if header is None:
        raise TwinError(f"{path}: empty telemetry file")
    if len(rows) < 2:
        raise TwinError(f"{path}: fewer than two samples")
    a = np.array(rows)
    return Telemetry(header, a[:, 0], a[:, 1], a[:, 2], a[:, 3], a[:, 4], tuple(events))


def telemetry_header(twin, track: str | None, seed: int) -> dict:
    """The header of a run of ``twin`` (track as the user named it, sensors, Δt, the firmware's gains)."""
    gains = {a: twin.space.get(a) for a in twin.space.addresses if a.startswith("control.")}
    name = track if track and track.lower().endswith(".png") else twin.track.name
    return {"track": name, "sensors": int(twin.space.get("sensor.count")), "dt_s": twin.space.get("control.dt"),
            "gains": gains, "source": "twin", "seed": seed}


def lap_lines(lap: LapResult, header: dict, every: int) -> list[dict]:
    """A lap of the twin as telemetry lines (header first)."""
    tr = lap.trace
    if tr is None:
        raise TwinError("telemetry: the lap has no trace")
    rec = tr.records[::every]
    lines = [{"type": "header", "format": FORMAT, "version": VERSION, "generator": GENERATOR, **header, "every": every},
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
    """Write telemetry lines atomically (replacing only telemetry this program wrote); returns the path."""
    with atomic_file(path, jsonl_is_ours, "telemetry") as f:
        for obj in lines:
            f.write(json.dumps(obj, separators=(",", ":")) + "\n")
    return os.path.abspath(path)
