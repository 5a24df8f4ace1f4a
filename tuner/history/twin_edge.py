"""Where the gains in force stop finishing, asked of the twin: it races them at a ladder of values of the wearing
parameter, several noise seeds each (one batch), then more finely across the first failures, and reads from those
laps:

* the failure model (:class:`tuner.prognostics.FailureModel`): the probability that a lap fails at a value,
  a normal CDF fitted by maximum likelihood to the raced laps, finished or failed, of the onset: from the least
  worn value to the first where most laps fail (a grid over the edge and its width: deterministic). Each value's
  laps draw noise seeds of their own: with the same few seeds at every value (common random numbers) a lap's failure
  is one seed's threshold seen again and again, and the fit learns the spread of five thresholds, not how often a
  lap fails: it put the plain gains' failures at μ 0.69 at 3.6 % a lap where 40 independent seeds fail 10 % (issue
  35);
* how well a lap time pins the parameter: the mean lap time's slope over the ladder's values before the edge
  [s per unit], and the scatter of a lap time around it over noise seeds [s]; an alignment on n laps then knows
  the parameter to about scatter/√n/|slope|, whatever its own consistent interval says;
* what a finished lap shows at each value (:class:`tuner.prognostics.ObservationModel`): the mean lap time, the
  mean |offset| of the line from the sensor array's centre and its mean signed offset, the side it runs on (what the
  robot's telemetry gives, read the same way: :func:`lap_features`) over the values raced before the edge (the first
  value where most laps fail), from their finished laps, and their covariance over noise seeds.
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import json
import math
import os

import numpy as np
from scipy.special import log_ndtr

from lf_common.cache import cache_dir, cached_folder
from lf_common.errors import LineFollowerError
from lf_common.files import files_digest, json_safe, read_json, write_json
from tuner.prognostics import FailureModel, ObservationModel
from tuner.prognostics.evidence import SLOW
from twin.core.closed_loop import run_laps
from twin.core.digital_twin import DigitalTwin
from twin.core.lap import LapLimits
from twin.telemetry.laps import line_offsets_m, line_sides_m

LADDER = 12  # values raced from the least worn measured value to the end of the range, one batch
REFINE = 8  # then across the first failures, and …
DENSE = 3  # … this many times as finely as the ladder before them, one more batch
SEEDS = 5  # noise seeds per value
# what a finished lap shows, in the observation model's order: its lap time [s], the mean |offset| of the line from
# the array's centre [m] and its mean signed offset [m] (a tyre that grips less runs wider in a bend: the line lies
# further towards its inside). Of the telemetry's summaries of a lap tried beside the lap time (the |offset|'s RMS
# and quantiles, the offset in time bins along the lap, the wheels' speeds and turns), the side pinned grip best,
# and from the line position every robot sends, whatever its encoders or sample rate (docs/models.md, issue 35)
FEATURES = ("lap_time_s", "line_offset_m", "line_side_m")
EDGE_GRID, WIDTH_GRID = 241, 40  # the maximum-likelihood grid


@dataclasses.dataclass(frozen=True)
class TwinEdge:
    failure: FailureModel | None  # None: no lap failed in the range raced
    finished: float | None  # the last value raced where every lap finished (None: none did)
    failing: float | None  # the first value where one failed
    seconds_per_unit: float | None  # d(mean lap time)/d(value) where every lap finished [s per parameter unit]
    lap_time_sd_s: float | None  # a lap time's scatter over noise seeds [s]
    raced: tuple[float, float]
    laps: int
    observation: ObservationModel | None = None  # None: fewer than two values raced where every lap finished

    def value_sd_per_lap(self) -> float | None:
        """How far one lap time pins the parameter (its unit), or None if the laps cannot tell."""
        if not self.seconds_per_unit or self.lap_time_sd_s is None:
            return None
        return self.lap_time_sd_s / abs(self.seconds_per_unit)


def line_offset_m(position: np.ndarray, sensors: int, pitch_m: float) -> float:
    """The mean |offset| of the line from the sensor array's centre [m], from line positions (0 … (sensors − 1)·1000
    across the array): the twin's trace and the robot's telemetry read the same way
    (:func:`tuner.history.ingest.cross_track`)."""
    return float(np.mean(line_offsets_m(position, sensors, pitch_m)))


def line_side_m(position: np.ndarray, sensors: int, pitch_m: float) -> float:
    """The mean signed offset of the line from the sensor array's centre [m] (+ towards its last sensor): the side
    the line runs on, read as :func:`line_offset_m` (:func:`tuner.history.ingest.cross_track`)."""
    return float(np.mean(line_sides_m(position, sensors, pitch_m)))


def lap_features(lap, pitch_m: float) -> tuple[float, ...]:
    """What a finished twin lap (a :class:`twin.core.lap.LapResult` with its trace) shows, in :data:`FEATURES`'
    order."""
    position, sensors = lap.trace.column("position"), lap.trace.count
    return (float(lap.lap_time_s), line_offset_m(position, sensors, pitch_m), line_side_m(position, sensors, pitch_m))


def _race(twin, gains, address, values, seeds, seed, limits, first=0):
    """[(value, [(failed, features or None) per seed])]: value j's laps on seeds of their own, seed +
    (first + j)·seeds onwards (a later batch passes the number of values raced before it as ``first``); a finished
    lap's features (:data:`FEATURES`) as the robot's telemetry gives them (:func:`lap_features`)."""
    laps = run_laps(twin, [{**gains, address: float(v)} for v in values for _ in range(seeds)],
                    seed=[seed + (first + j) * seeds + k for j in range(len(values)) for k in range(seeds)],
                    limits=limits, keep_traces=True)
    pitch = float(twin.space.get("sensor.pitch"))
    seen = [(not r.completed, lap_features(r, pitch) if r.completed else None) for r in laps]
    del laps  # the traces: only the features are kept
    return [(float(v), seen[i * seeds:(i + 1) * seeds]) for i, v in enumerate(values)]


def _mostly_fail(laps) -> bool:
    return 2 * sum(f for f, _ in laps) >= len(laps)


def observation_model(rows) -> ObservationModel | None:
    """The features' means and covariance over noise seeds of the finished laps at each value raced before the edge
    (``rows`` from the least worn; the edge: the first value where most laps fail, or fewer than two finish) while
    its laps are regular (none ``SLOW`` times slower than the mean of the value raced before it: past there laps
    lose the line and find it again; against the least worn value's mean, a part that slows every lap, a battery
    running down, was cut off 40 % of its way short of its edge). Each value's covariance (few seeds) is shrunk
    halfway towards its neighbours' (the values raced on either side), and widened by the mean's own standard
    error. Pooled over every value instead, the scatter near the edge (ten times the variance far from it) set the
    scatter everywhere: a robot's early laps were read with a third of their sharpness, and early wear was seen late
    (issue 35). The means are read off a smooth curve through them all (:func:`smooth_means`)."""
    done = []
    for v, laps in rows:
        finished = [x for f, x in laps if not f]
        if _mostly_fail(laps) or len(finished) < 2:
            break
        y = np.array(finished)
        if done and y[:, 0].max() > SLOW * done[-1][1][:, 0].mean():
            break
        done.append((v, y))
    if len(done) < 2:
        return None
    done.sort(key=lambda d: d[0])
    own = np.array([np.cov(y, rowvar=False) for _, y in done])
    k = len(own)
    local = np.array([own[max(i - 1, 0):i + 2].mean(axis=0) for i in range(k)])  # each value and its neighbours
    means = smooth_means(np.array([v for v, _ in done]), np.array([y.mean(axis=0) for _, y in done]),
                         np.diagonal(0.5 * own + 0.5 * local, axis1=1, axis2=2) / np.array([[len(y)] for _, y in done]))
    # a lap's scatter, plus the twin's own mean's (a few seeds): a robot's lap is read against a mean known so well
    covs = (0.5 * own + 0.5 * local) * (1 + 1 / min(len(y) for _, y in done))
    floor = np.maximum(np.diagonal(local, axis1=1, axis2=2), 1e-18) * 1e-6
    covs += floor[:, :, None] * np.eye(own.shape[1])[None]  # never singular
    return ObservationModel(FEATURES, np.array([v for v, _ in done]), means, covs)


def smooth_means(values: np.ndarray, means: np.ndarray, variances: np.ndarray) -> np.ndarray:
    """The features' mean curves through the values raced (ascending): for each feature a cubic smoothing spline
    weighted by its means' standard errors (``variances``: of each mean, over its few seeds), as far from them as
    they scatter (χ² = the number of values: FITPACK's ``s``). The means of five seeds wander by their standard
    error: a robot's lap time between two values whose means came out alike read as the less worn one (μ 0.86 for
    a robot at 0.83, outside the filter's 90 % band: issue 35); the curve through all of them does not."""
    from scipy.interpolate import UnivariateSpline

    if len(values) < 4 or np.any(np.diff(values) <= 0):
        return means
    out = means.copy()
    for j in range(means.shape[1]):
        se = np.sqrt(np.maximum(variances[:, j], 1e-24))
        out[:, j] = UnivariateSpline(values, means[:, j], w=1 / se, k=3, s=len(values))(values)
    return out


def fit_failure(points: list[tuple[float, bool]], direction: float, span: float) -> FailureModel:
    """The normal-CDF failure model of largest likelihood for (value, failed) laps."""
    v = np.array([p[0] for p in points])
    failed = np.array([p[1] for p in points])
    edges = np.linspace(v.min(), v.max(), EDGE_GRID)
    widths = np.geomspace(span * 1e-3, span * 0.2, WIDTH_GRID)
    z = direction * (v[None, None, :] - edges[:, None, None]) / widths[None, :, None]
    ll = np.where(failed, log_ndtr(z), log_ndtr(-z)).sum(axis=2)
    i, j = np.unravel_index(np.argmax(ll), ll.shape)  # first of equals: deterministic
    return FailureModel(float(edges[i]), float(widths[j]), direction)


def _lap_times(rows) -> tuple[float | None, float | None]:
    """(slope [s per unit], scatter [s]) over the finished laps of the values ``rows`` holds (those before the
    edge)."""
    done = [(v, [x[0] for f, x in laps if not f]) for v, laps in rows]
    done = [(v, ts) for v, ts in done if ts]
    if len(done) < 2:
        return None, None
    x = np.array([v for v, ts in done for _ in ts])
    y = np.array([t for _, ts in done for t in ts])
    slope = float(np.polyfit(x, y, 1)[0])
    within = [np.var(ts, ddof=1) for _, ts in done if len(ts) > 1]
    return slope, (math.sqrt(float(np.mean(within))) if within else None)


_RECENT: dict = {}  # the last few races, by what decides them: a forecast lap after lap races the same ladder
RECENT = 8
RACES = "twin-edges"  # their folder in the cache (lf_common.cache.cache_dir()), one verified entry per race
STORE_FORMAT = 3  # 2: the twin's values as its laps run them (race_record); 3: the line's side as a feature


def forget_races() -> None:
    """Forget the races kept in this process: the next forecast reads its race from the cache folder (or races the
    twin if it is not there), as a new process does."""
    _RECENT.clear()


@functools.cache
def code_digest() -> str:
    """What decides a race beside its inputs: the C core and the Python of the twin and of this race (a change to
    either is a new key: a stored race is never read for other code)."""
    import twin

    return files_digest(digest_files(), os.path.dirname(os.path.dirname(os.path.abspath(twin.__file__))))


def digest_files() -> list[str]:
    """The files :func:`code_digest` hashes: the twin's packages and this race's own modules, not the command line
    (``twin/cli``: it says what a race gave, and no race runs through it; hashed, every edit of a command's wording
    raced every stored race again, a user's first forecast after an upgrade waiting on it)."""
    import twin
    import tuner

    roots = [os.path.dirname(twin.__file__)] + [os.path.dirname(m.__file__) for m in _model_packages()]
    cli = os.path.join(os.path.dirname(twin.__file__), "cli")
    files = [os.path.join(r, n) for root in roots for r, _, names in os.walk(root) for n in names
             if n.endswith((".py", ".so", ".pyd", ".c", ".h")) and os.path.commonpath([r, cli]) != cli]
    files.append(__file__)
    files.append(os.path.join(os.path.dirname(tuner.__file__), "prognostics", "evidence.py"))
    return files


def _model_packages():
    import lf_common
    import line_sensor
    import mjcf
    import motors

    return (lf_common, line_sensor, mjcf, motors)


def race_record(twin: DigitalTwin, gains: dict, address: str, start: float, end: float, direction: float, seed: int,
                limits: LapLimits, seeds: int) -> dict:
    """Everything a race depends on, as JSON: the twin's configuration (robot, track, values), the gains, the
    ladder and the code. The values are those its laps run with: the twin's own under the gains, and not the
    raced parameter's (each lap sets it): a twin built with other gains, or another value of the parameter, races
    the same laps and finds the same race (``live``'s twin runs ahead what ``history``'s asks for)."""
    from tuner.sensitivity.learned import config_record

    config = json.loads(json.dumps(config_record(twin), default=str))
    config["values"] = {a: v for a, v in sorted({**config["values"], **gains}.items()) if a != address}
    return {"format": STORE_FORMAT, "twin": config,
            "gains": dict(sorted(gains.items())), "address": address, "start": start, "end": end,
            "direction": direction, "seed": seed, "limits": dataclasses.asdict(limits), "seeds": seeds,
            "ladder": [LADDER, REFINE, DENSE], "code": code_digest()}


def race_key(record: dict) -> str:
    """A race's key: what decides it (:func:`race_record`), hashed."""
    return hashlib.sha256(json.dumps(record, sort_keys=True).encode()).hexdigest()[:32]


def race_folder(record: dict) -> str:
    """Where the race of ``record`` is kept: its entry in the cache folder."""
    return os.path.join(cache_dir(), RACES, race_key(record))


def _edge_doc(edge: TwinEdge) -> dict:
    doc = dataclasses.asdict(dataclasses.replace(edge, observation=None))
    o = edge.observation
    doc["observation"] = None if o is None else {"names": list(o.names), "values": o.values.tolist(),
                                                 "means": o.means.tolist(), "covariances": o.covariances.tolist()}
    return doc


def _edge_of(doc: dict) -> TwinEdge:
    o = doc["observation"]
    return TwinEdge(None if doc["failure"] is None else FailureModel(**doc["failure"]), doc["finished"],
                    doc["failing"], doc["seconds_per_unit"], doc["lap_time_sd_s"], tuple(doc["raced"]), doc["laps"],
                    None if o is None else ObservationModel(tuple(o["names"]), np.array(o["values"]),
                                                            np.array(o["means"]), np.array(o["covariances"])))


def twin_edge(twin: DigitalTwin, gains: dict, address: str, start: float, end: float, direction: float, seed: int,
              limits: LapLimits, seeds: int = SEEDS, wait_s: float | None = None,
              race_here: bool = True) -> TwinEdge:
    """Race ``gains`` from ``address`` = ``start`` towards ``end`` (where the wear goes: ``direction``). A race is
    deterministic: the same race asked again (the same robot, values, track, gains, ladder and code) is answered
    from the last few of this process, or from the cache folder, where each race is kept as a verified entry (JSON
    floats read back bit for bit): a forecast after the first, in any process, does not race the twin again.
    ``wait_s``: how long to wait for another process racing it (``live``'s race-ahead; None: as the cache does,
    :func:`lf_common.cache.cached_folder`), else :class:`lf_common.cache.StillBuilding`; ``race_here`` False: a race
    not in the cache is not raced here either (it is to come from that process): StillBuilding too."""
    record = race_record(twin, gains, address, start, end, direction, seed, limits, seeds)
    key = race_key(record)
    if key not in _RECENT:
        if len(_RECENT) >= RECENT:
            del _RECENT[next(iter(_RECENT))]

        def race_into(folder: str) -> None:
            edge = _twin_edge(twin, gains, address, start, end, direction, seed, limits, seeds)
            write_json(os.path.join(folder, "race.json"), {"record": record, "edge": _edge_doc(edge)}, "the race")

        folder = cached_folder(race_folder(record), race_into, f"the twin's race of {address}", wait_s, race_here)
        doc = read_json(os.path.join(folder, "race.json"), 1 << 24, "the race")
        if doc["record"] != json.loads(json.dumps(json_safe(record))):  # a hand-made entry (or a collision)
            raise LineFollowerError(f"cache {folder}: holds another race; delete it")
        _RECENT[key] = _edge_of(doc["edge"])
    return _RECENT[key]


def _twin_edge(twin, gains, address, start, end, direction, seed, limits, seeds) -> TwinEdge:
    p = twin.space.parameter(address)
    rows = _race(twin, gains, address, np.linspace(start, end, LADDER), seeds, seed, limits)
    any_fail = [any(f for f, _ in laps) for _, laps in rows]
    # the edge: the first of the ladder's values where most laps fail (else where one does); a lap failing now and
    # then before it is the failure model's tail, not the edge
    mostly = [_mostly_fail(laps) for _, laps in rows]
    edge_at = mostly.index(True) if any(mostly) else (any_fail.index(True) if any(any_fail) else None)
    # the lap time's slope and scatter where the robot runs well: the ladder's values before the edge
    before = rows[:edge_at] if edge_at is not None else rows
    slope, sd = _lap_times(before)
    if edge_at:
        i = edge_at
        hi = min(i + 1, len(rows) - 1)  # across the edge and one step beyond
        fine = np.linspace(rows[i - 1][0], rows[hi][0], REFINE + 2)[1:-1]
        # and finely where the robot runs well: the lap time bends there, and a robot's lap is read against it
        dense = np.linspace(start, rows[i - 1][0], DENSE * (i - 1) + 1)
        dense = dense[np.arange(len(dense)) % DENSE != 0]  # the ladder's own values raced already
        rows += _race(twin, gains, address, np.concatenate([fine, dense]), seeds, seed, limits, first=len(rows))
    rows.sort(key=lambda r: direction * r[0])  # from the least worn
    laps = sum(len(l) for _, l in rows)
    fails = [any(f for f, _ in l) for _, l in rows]
    # what a finished lap shows: from every value before the edge, the refined ones too (the ladder's
    # own, should a refined value fail early)
    observation = observation_model(rows) or observation_model(before)
    if not any(fails):
        return TwinEdge(None, float(end), None, slope, sd, (start, end), laps, observation)
    k = fails.index(True)
    # the onset, from the least worn to the first value where most laps fail: beyond it failures can come and go
    # (gains fail 80 % of their laps at μ 0.70 and 42 % at 0.62 in a wrong-way band), which a CDF does not
    # describe and a forecast of the first failure does not need
    mostly = [_mostly_fail(l) for _, l in rows]
    upto = mostly.index(True) + 1 if any(mostly) else len(rows)
    failure = fit_failure([(v, f) for v, l in rows[:upto] for f, _ in l], direction, float(p.upper - p.lower))
    return TwinEdge(failure, rows[k - 1][0] if k else None, rows[k][0], slope, sd, (start, end), laps, observation)
