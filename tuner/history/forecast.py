"""When will the gains in force stop finishing laps? Asked of the twin itself, not of the lap times: along the trend
of the aligned parameter (:mod:`tuner.history.trend`), the twin races the gains at a ladder of values (each with a
few noise seeds, one batch) and finds where they first fail; the trend says in how many laps it gets there, and
the slope's 95 % interval gives the forecast's. Lap times say nothing about this until the failures begin: a
line follower keeps its lap time almost to its grip limit, then leaves the track.

Advice follows: re-tune now when the gains fail within ``RETUNE_WITHIN`` laps (or already do), and for a parameter
with a service limit (:data:`SERVICE`: the ends of the robust envelope, :data:`tuner.search.envelope.ROBUST_AXES`)
when the trend reaches it: replace the tyres, charge the battery.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from tuner.history.trend import Trend
from tuner.search.envelope import ROBUST_AXES, ROBUST_SEEDS
from twin.core.closed_loop import run_laps
from twin.core.digital_twin import DigitalTwin
from twin.core.lap import LapLimits

LADDER = 12  # values raced along the trend, one batch
REFINE = 6  # then between the last that finished and the first that failed, one more batch
Z95 = 1.96
RETUNE_WITHIN = 10  # [laps]
# where a parameter needs service, and what to do: the worn end of the robust envelope
SERVICE = {"motion.mu": (min(ROBUST_AXES["motion.mu"]), "replace the tyres"),
           "motor.supply_voltage": (min(ROBUST_AXES["motor.supply_voltage"]), "charge or replace the battery")}


@dataclasses.dataclass(frozen=True)
class Forecast:
    address: str
    now_lap: int  # the robot's last lap
    value_now: float  # the trend there
    failing_value: float | None  # where the gains first fail along the trend (None: not within the range raced)
    laps_to_failure: float | None  # from now_lap (0: they fail already)
    interval: tuple[float, float] | None  # 95 % (the upper end may be inf: the trend may be flat)
    raced: tuple[float, float]  # the range of values raced
    laps: int  # twin laps run
    advice: tuple[str, ...]
    note: str

    def summary(self) -> dict:
        d = dataclasses.asdict(self)
        if self.interval:  # JSON has no infinity
            d["interval"] = [None if math.isinf(v) else v for v in self.interval]
        return d


def _fails(twin: DigitalTwin, gains: dict, address: str, values, seeds: int, seed: int, limits: LapLimits):
    """For each value: does any seed's lap fail? (one batch)"""
    laps = run_laps(twin, [{**gains, address: float(v)} for v in values for _ in range(seeds)],
                    seed=[seed + k for _ in values for k in range(seeds)], limits=limits, keep_traces=False)
    return [any(not r.completed for r in laps[i * seeds:(i + 1) * seeds]) for i in range(len(values))], len(laps)


def first_failure(twin: DigitalTwin, gains: dict, address: str, start: float, end: float, seeds: int, seed: int,
                  limits: LapLimits) -> tuple[float | None, bool, int]:
    """Racing ``gains`` from ``address`` = ``start`` towards ``end``: (the first value where a lap fails, refined
    between the ladder's steps; None if none does), whether they fail at ``start`` already, laps run."""
    values = np.linspace(start, end, LADDER)
    fails, laps = _fails(twin, gains, address, values, seeds, seed, limits)
    if fails[0] or not any(fails):
        return (float(start) if fails[0] else None), fails[0], laps
    i = fails.index(True)
    fine = np.linspace(values[i - 1], values[i], REFINE + 2)[1:-1]
    more, n = _fails(twin, gains, address, fine, seeds, seed, limits)
    return (float(fine[more.index(True)]) if any(more) else float(values[i])), False, laps + n


def _laps_until(target: float, t: Trend, now: int, slope: float) -> float:
    if slope == 0 or (target - t.at(now)) / slope < 0:
        return math.inf
    return (target - t.at(now)) / slope


def forecast_failure(twin: DigitalTwin, gains: dict, t: Trend, now_lap: int, seeds: int = ROBUST_SEEDS, seed: int = 0,
             lap_timeout_s: float = 30.0) -> Forecast:
    """Where along the trend ``t`` the ``gains`` start failing on the twin, and in how many laps from ``now_lap``."""
    p = twin.space.parameter(t.address)
    now = float(np.clip(t.at(now_lap), p.lower, p.upper))
    direction = -1.0 if t.slope <= 0 else 1.0
    end = p.lower if direction < 0 else p.upper
    service = SERVICE.get(t.address)
    if service is not None and (service[0] - now) * direction > 0:
        end = now + 2 * (service[0] - now)  # twice as far as the service limit: far enough, and finely spaced
    failing, already, laps = first_failure(twin, gains, t.address, now, end, seeds, seed,
                                           LapLimits(timeout_s=lap_timeout_s))
    advice: list[str] = []
    if already:
        note = f"the gains fail already at {t.address} = {now:.4g}"
    elif failing is None:
        note = f"the gains finish every lap raced for {t.address} from {now:.4g} to {end:.4g}"
    else:
        note = f"the gains first fail at {t.address} = {failing:.4g} (they finish at {now:.4g})"
    laps_to = interval = None
    if failing is not None:
        laps_to = 0.0 if already else _laps_until(failing, t, now_lap, t.slope)
        if already:
            interval = (0.0, 0.0)
        else:
            steep, shallow = t.slope + direction * Z95 * t.slope_se, t.slope - direction * Z95 * t.slope_se
            lo = _laps_until(failing, t, now_lap, steep)
            hi = _laps_until(failing, t, now_lap, shallow) if shallow * direction > 0 else math.inf
            interval = (min(lo, laps_to), max(hi, laps_to))
        if laps_to <= RETUNE_WITHIN:
            advice.append("re-tune now" + (": the gains in force already fail" if already else
                                           f": the gains in force stop finishing in about {laps_to:.0f} laps")
                          + " (live --act does it, or tune with --set " + f"{t.address}={failing:.4g})")
    if service is not None:
        limit, what = service
        past = (now - limit) * direction >= 0
        n = 0.0 if past else _laps_until(limit, t, now_lap, t.slope)
        if math.isfinite(n):
            advice.append(f"{what} in about {n:.0f} laps ({t.address} reaches {limit:g}, the worn end of the "
                          "robust envelope)" if n > 0 else f"{what} now ({t.address} is past {limit:g})")
    return Forecast(t.address, now_lap, now, failing, laps_to, interval, (now, float(end)), laps, tuple(advice), note)
