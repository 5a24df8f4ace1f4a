"""Learned influences kept for the commands that use them (``diagnose``, ``align``), without running the analysis
again.

``graph --learn`` with the default factors stores its result in the cache folder (``lf_common.cache.cache_dir()``,
``learned/<key>.json``), keyed by the twin's configuration (:func:`config_key`): the robot (the generated robot, or
a description's path and content), the track (a name, or an image's path and content), every model-space value
(gains included), the package and MuJoCo versions and this format's version. A command that wants the learned
influences of its twin reads that file (:func:`load`); when there is none (another configuration, never learned, a
damaged file) it says so and falls back explicitly:

* ``diagnose``: its four default causes, grip, battery, winding resistance and payload
  (:data:`tuner.align.diagnose.DEFAULT_CANDIDATES`);
* ``align``: the lap times its own scan ran over the parameter's physical range (:func:`scan_spread`), no extra laps.
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
from typing import Sequence

import mujoco

from lf_common import VERSION
from lf_common.cache import cache_dir
from lf_common.errors import LineFollowerError
from lf_common.files import read_json, write_json
from twin.core.digital_twin import DigitalTwin
from tuner.sensitivity.analysis import Analysis
from tuner.sensitivity.ranges import default_factors, is_setting, physical_range

log = logging.getLogger(__name__)

FORMAT = 2  # of the stored analysis; a new format is a new key (2: failed laps no longer written in as the median)
MAX_BYTES = 16 * 1024 * 1024
CANDIDATE_SHARE = 0.01  # a diagnosis candidate moves the lap time by at least 1 % over its physical range
CANDIDATES_MAX = 4


def _file_digest(path: str | None) -> str | None:
    if not path or not os.path.isfile(path):
        return None
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def config_record(twin: DigitalTwin) -> dict:
    """What the twin is, for the cache key: robot, track, every value, versions."""
    track = twin.track_source
    return {"format": FORMAT, "version": VERSION, "mujoco": mujoco.__version__,
            "robot": twin.robot_urdf or "generated", "robot_sha256": _file_digest(twin.robot_urdf),
            "robot_config": repr(twin.robot_config), "track": os.path.abspath(track) if os.path.isfile(track) else track,
            "track_sha256": _file_digest(track), "metres_per_pixel": twin.track_metres_per_pixel,
            "values": dict(sorted(twin.space.values.items()))}


def config_key(twin: DigitalTwin) -> str:
    text = json.dumps(config_record(twin), sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:24]


def path_for(twin: DigitalTwin) -> str:
    return os.path.join(cache_dir(), "learned", config_key(twin) + ".json")


def is_default(twin: DigitalTwin, analysis: Analysis) -> bool:
    """The analysis varied the default factors over their default ranges (what the commands look up)."""
    return list(analysis.factors) == default_factors(twin.space)[0]


def store(twin: DigitalTwin, analysis: Analysis) -> str:
    """Keep a default analysis of this twin for ``diagnose`` and ``align``; returns the file. Raises LineFollowerError
    when the cache folder cannot be written."""
    if not is_default(twin, analysis):
        raise LineFollowerError("learned influences: only an analysis of the default parameters over their default "
                                "ranges is kept (it is what diagnose and align look up)")
    path = path_for(twin)
    try:
        os.makedirs(os.path.dirname(path), exist_ok=True)
    except OSError as e:
        raise LineFollowerError(f"cache {os.path.dirname(path)}: cannot write ({e.strerror or e}); set TWIN_CACHE_DIR "
                                "to a writable folder") from None
    return write_json(path, {"config": config_record(twin), "analysis": analysis.to_dict()}, "learned influences")


def load(twin: DigitalTwin) -> tuple[Analysis | None, str]:
    """The stored default analysis of this twin's configuration, or None; and a line saying where it came from or
    why there is none."""
    path = path_for(twin)
    if not os.path.isfile(path):
        return None, "no learned influences for this twin's configuration; graph --learn measures them"
    try:
        doc = read_json(path, MAX_BYTES, "learned influences")
        if doc.get("config") != json.loads(json.dumps(config_record(twin), default=str)):
            raise ValueError("it was learned for another configuration")
        analysis = Analysis.from_dict(doc["analysis"])
    except (LineFollowerError, KeyError, TypeError, ValueError, AttributeError) as e:
        log.warning("learned influences %s cannot be used (%s); ignoring it", path, e)
        return None, f"the learned influences in {path} cannot be used ({e})"
    return analysis, f"learned influences of this twin ({path})"


def lap_time_governors(analysis: Analysis) -> list[tuple[str, float, float | None]]:
    """(parameter, μ* [s], total index or None) on the lap time, the largest μ* first."""
    rows = [(i.parameter, i.mu_star, i.total) for i in analysis.influences if i.output == "lap_time_s"]
    return sorted(rows, key=lambda r: -r[1])


def _lap_s(analysis: Analysis) -> float:
    return float(analysis.summary.get("lap_time_s", {}).get("median", float("nan")))


def diagnosis_candidates(analysis: Analysis, limit: int = CANDIDATES_MAX) -> list[str]:
    """The physical parameters (not settings) that surely move the lap time over their physical range: the lower end
    of their Morris μ*'s 95 % interval is at least :data:`CANDIDATE_SHARE` of the lap; the largest μ* first, at most
    ``limit``."""
    lap = _lap_s(analysis)
    rows = [i for i in analysis.influences if i.output == "lap_time_s" and not is_setting(i.parameter)
            and i.mu_star_interval[0] >= CANDIDATE_SHARE * lap]
    return [i.parameter for i in sorted(rows, key=lambda i: -i.mu_star)][:limit]


def barely_moves(analysis: Analysis, address: str, threshold: float) -> str | None:
    """A warning when the parameter surely moves the lap time by less than ``threshold`` of it over its range (the
    upper end of its μ*'s 95 % interval), or None (also when the analysis did not vary it)."""
    infl = analysis.influence(address, "lap_time_s")
    factor = next((f for f in analysis.factors if f.address == address), None)
    lap = _lap_s(analysis)
    if infl is None or factor is None or not infl.mu_star_interval[1] < threshold * lap:
        return None
    top = [f"{a} ({mu:.3g} s)" for a, mu, _ in lap_time_governors(analysis)[:3]]
    unit = "" if factor.unit == "-" else f" {factor.unit}"
    return (f"{address} barely moves the lap time: across {factor.lower:.4g}–{factor.upper:.4g}{unit} it changes it by "
            f"{infl.mu_star:.2g} s ({100 * infl.mu_star / lap:.2g} % of a {lap:.3g} s lap; Morris μ*, "
            f"learned by graph --learn), so a lap time hardly tells its value; the lap time is governed by "
            f"{', '.join(top)}")


def scan_spread(twin: DigitalTwin, address: str, points: Sequence[tuple[float, float | None]]) -> tuple[float, tuple[float, float]] | None:
    """From laps already run at several values of one parameter (value, lap time or None if it failed): how far
    apart the lap times are over its physical range, as a fraction of their median, and that range. None when
    fewer than two laps lie in it, or one of them failed (then it moves the lap a lot)."""
    rng = physical_range(twin.space, address)
    if rng is None:
        return None
    lo, hi = rng[0], rng[1]
    inside = [t for v, t in points if lo <= v <= hi]
    if len(inside) < 2 or any(t is None for t in inside):
        return None
    med = sorted(inside)[len(inside) // 2]
    return (max(inside) - min(inside)) / med, (lo, hi)


def lap_time_warning(twin: DigitalTwin, address: str, points: Sequence[tuple[float, float | None]],
                     threshold: float) -> tuple[str | None, str]:
    """For ``align``: a warning when the parameter barely moves the lap time (by less than ``threshold`` of it over
    its physical range), and where that judgement comes from: "learned" (this twin's learned influences),
    "scan" (the fallback: ``points``, the laps the alignment ran, (value, lap time or None)) or "none"."""
    analysis, source = load(twin)
    if analysis is not None and analysis.influence(address, "lap_time_s") is not None:
        return barely_moves(analysis, address, threshold), "learned"
    spread = scan_spread(twin, address, points)
    if spread is None:
        return None, "none"
    fraction, (lo, hi) = spread
    if fraction >= threshold:
        return None, "scan"
    return (f"{address} barely moves the lap time: over the range it plausibly spans on this robot, {lo:.4g}–{hi:.4g}, "
            f"the alignment's laps differ by {100 * fraction:.2g} % (less than {100 * threshold:g} %), so a lap time hardly tells its value (judged "
            f"from those laps: {source})"), "scan"
