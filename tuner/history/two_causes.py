"""Two causes at once: when no one part's wear explains the robot's last laps (:func:`tuner.history.forecast.
one_cause_misfit`: with the lap time and the line's offset and side, grip and battery leave different marks), the
forecast tracks both parts that wear together (:data:`tuner.history.forecast.SERVICE`: grip and the battery):

1. the twin races the gains in force along the first cause's ladder at ``ROWS`` values of the second, from the
   twin's own value to where the gains fail on the second alone (each row a race of :mod:`tuner.history.twin_edge`,
   kept in the cache; the row at the twin's own value is the race of the first cause alone): the failure edge and
   the observation model over the plane of the two (:mod:`tuner.prognostics.plane`);
2. one particle filter carries both values, their rates and shapes, from every finished lap's features and every
   lap outcome (alignments are not evidence here: each explains the laps by one parameter alone);
3. the Monte Carlo races each future against the plane's edge: the laps to the first failure, as for one cause,
   and when each part reaches its service limit.

:func:`forecasts_of` is what ``history`` asks for a robot: each cause on its own and, when no one explains the laps,
both together.
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from lf_common.cache import StillBuilding
from tuner.history.forecast import (EDGE_PRIOR, LAP_TIMEOUT_S, MIN_TIMED_LAPS, SERVICE, STILL_RACING, Forecast,
                                    alone_explains, carried, carried_on, forecast_failure, no_number, observations_of,
                                    outcomes_of, race_range, service_direction)
from tuner.history.twin_edge import SEEDS as EDGE_SEEDS
from tuner.history.twin_edge import twin_edge
from tuner.prognostics import FilterSettings, estimate, life_sentence, remaining_life, retune_advice, service_advice
from tuner.prognostics import shape_sentence
from tuner.prognostics.plane import PlaneFailure, PlaneObservation
from twin.core.digital_twin import DigitalTwin
from twin.core.lap import LapLimits

ROWS = 7  # values of the second cause the first is raced at: the twin's own, then closer and closer (ROW_CROWDING)
# to where it fails alone (4, evenly, until 2026-11-29: between rows the plane's lap time was up to 8 lap scatters
# off a race there, and the forecast read grip 0.05 low and its wear twice as fast; at 7, each row read at its
# edge's distance, within 2)
ROW_CROWDING = 2.0  # row k at 1 − (1 − k/(ROWS − 1))² of the way: grip's edge moves fastest near the battery's own
# edge (evenly, bench_forecast's two-cause robot seed 7 was forecast 32, 26 and 15 laps at 30/50/70 % of its life,
# against 42, 30 and 18, none covered)
SECOND_ALONE = 1e-3  # a row counts towards the first cause's edge where the second alone fails fewer laps than this
# (its edge 3.1 widths on): nearer, a lap fails about as often at any grip, and the row's edge along grip is the
# twin's Monte Carlo (PlaneFailure: the second's own edge says when those laps fail)
TELLS_APART = 0.9  # above this |correlation| of the two values over the particles the laps do not tell them apart


def time_left(wait_s: float | None):
    """A function giving what is left of ``wait_s`` seconds from now [s], never below 0 (None: None)."""
    end = None if wait_s is None else time.monotonic() + wait_s
    return lambda: None if end is None else max(0.0, end - time.monotonic())


def joint_address(causes: tuple[str, str]) -> str:
    """The key of the forecast of both causes at once (``history --json``'s ``forecasts``)."""
    return "+".join(causes)


@dataclasses.dataclass(frozen=True)
class Plane:
    failure: PlaneFailure | None  # None: fewer than two rows where the gains fail
    observation: PlaneObservation | None  # None: fewer than two rows with regular laps
    rows: tuple[float, ...]  # the second cause's values raced
    raced: tuple[float, float]  # the first cause's range along each row
    laps: int
    spans: tuple[float, float]  # each cause's distance from the twin's value to where the gains fail on it alone


class RowsRacing(StillBuilding):
    """The plane's races are still running in another process: ``done`` of ``total`` are ready."""

    def __init__(self, done: int, total: int):
        super().__init__(f"the twin's races of both at once are still running in another process: {done} of {total} "
                         "done")
        self.done, self.total = done, total


def race_plane(twin: DigitalTwin, gains: dict, causes: tuple[str, str], seed: int, limits: LapLimits,
               seeds: int = EDGE_SEEDS, wait_s: float | None = None) -> Plane:
    """Race ``gains`` along the first cause at ``ROWS`` values of the second (each row a cached race). ``wait_s``:
    how long to wait in all for races another process is running (None: until they are done), else
    :class:`RowsRacing`."""
    first, second = causes
    d1, d2 = service_direction(twin, first, []), service_direction(twin, second, [])
    start, end = race_range(twin, first, [], d1)
    s2, e2 = race_range(twin, second, [], d2)
    left = time_left(wait_s)
    alone, edges = None, []
    try:
        alone = twin_edge(twin, gains, second, s2, e2, d2, seed, limits, seeds=seeds, wait_s=left())
        own = float(twin.space.get(second))
        far = alone.failure.threshold if alone.failure is not None else e2
        values = own + (far - own) * (1 - (1 - np.linspace(0.0, 1.0, ROWS)) ** ROW_CROWDING)
        # the row at the twin's own value is the first cause's race alone (the same gains: the same cached race)
        for k, w in enumerate(values):
            edges.append((float(w), twin_edge(twin, gains if k == 0 else {**gains, second: float(w)}, first, start,
                                              end, d1, seed, limits, seeds=seeds, wait_s=left())))
    except StillBuilding:  # (the second cause's race alone, then the rows)
        raise RowsRacing(len(edges) + (alone is not None), ROWS + 1) from None
    # a row's failures are the first cause's only where the second alone (almost) never fails a lap
    failing = [(w, e.failure) for w, e in edges if e.failure is not None
               and (alone.failure is None or alone.failure.p_fail(w) < SECOND_ALONE)]
    seen = [(w, e.observation) for w, e in edges if e.observation is not None]
    own_edge = edges[0][1].failure
    spans = (abs(start - own_edge.threshold) if own_edge is not None else abs(end - start), abs(own - far))
    failure = PlaneFailure.of(failing, d2, alone.failure) if len(failing) >= 2 else None
    row_edges = None if failure is None else failure.threshold(np.array([w for w, _ in seen]))
    return Plane(failure, PlaneObservation.of(seen, row_edges) if len(seen) >= 2 else None,
                 tuple(float(w) for w in values),
                 (start, end), sum(e.laps for _, e in edges) + alone.laps, spans)


def race_ahead_both(twin: DigitalTwin, gains: dict, seed: int = 0) -> Plane:
    """The races a forecast of both parts that wear (:data:`SERVICE`) at once asks for, run ahead (``live``)."""
    return race_plane(twin, gains, tuple(sorted(SERVICE)), seed, LapLimits(timeout_s=LAP_TIMEOUT_S))


def forecast_two_causes(twin: DigitalTwin, gains: dict, laps: list[dict], causes: tuple[str, str], now_lap: int,
                        seed: int = 0, lap_timeout_s: float = LAP_TIMEOUT_S, filter_seed: int | None = None,
                        seeds: int = EDGE_SEEDS, race_wait_s: float | None = None) -> Forecast:
    """When the ``gains`` in force first fail with both ``causes`` wearing, from the robot's ``laps`` up to
    ``now_lap`` (each with its lap time and the line's offset and side: with the lap time alone any one cause
    explains the laps, and the two cannot be told apart). ``race_wait_s``: as
    :func:`tuner.history.forecast_failure`'s."""
    filter_seed = seed if filter_seed is None else filter_seed
    address = joint_address(causes)
    outs = sorted((o for o in outcomes_of(laps, gains) if o.lap <= now_lap), key=lambda o: (o.lap, o.failed))
    names = carried(laps)
    obs = observations_of(laps, gains, now_lap, names) if len(names) > 1 else []
    evidence = {"alignments": 0, "laps": len(outs), "failed": sum(o.failed for o in outs), "timed_laps": len(obs)}
    if len(names) < 2:
        return no_number(address, now_lap, f"the laps carry the lap time alone, which either of {causes[0]} and "
                          f"{causes[1]} explains: the two cannot be told apart, no number for both at once",
                          evidence, "too little evidence")
    try:
        plane = race_plane(twin, gains, causes, seed, LapLimits(timeout_s=lap_timeout_s), seeds, race_wait_s)
    except RowsRacing as e:
        return no_number(address, now_lap, f"neither {causes[0]} nor {causes[1]} alone explains the laps, and the "
                         f"twin's races of both at once are still running in another process (live's race-ahead, "
                         f"or another history): {e.done} of {e.total} done; no number for both at once yet, ask "
                         "again", evidence, STILL_RACING)
    if plane.failure is None or plane.observation is None:
        return dataclasses.replace(no_number(
            address, now_lap, f"the twin's races of {causes[0]} at {len(plane.rows)} values of {causes[1]} give "
            f"{'no failure edge' if plane.failure is None else 'no regular laps'} on two of them or more: no number "
            "for both at once", evidence, "no plane"), laps=plane.laps)
    seen = plane.observation.subset(names)
    obs = [o for o in obs if seen.reads(o.features)]
    if len(obs) < MIN_TIMED_LAPS:
        return dataclasses.replace(no_number(
            address, now_lap, f"too little evidence to forecast {causes[0]} and {causes[1]} at once: {len(obs)} laps "
            f"read through the twin (at least {MIN_TIMED_LAPS})", evidence, "too little evidence"), laps=plane.laps)
    own = np.array([plane.raced[0], plane.rows[0]])  # each cause's least worn value raced
    ends = own + plane.failure.direction * np.array(plane.spans)
    lo, hi = np.minimum(own, ends) - 0.5 * np.array(plane.spans), np.maximum(own, ends) + 0.5 * np.array(plane.spans)
    settings = FilterSettings(span=plane.spans, value_range=tuple(zip(lo, hi)),
                              one_way=tuple(plane.failure.directions), edge_prior=EDGE_PRIOR * plane.spans[0])
    state = estimate((), outs, now_lap, settings, plane.failure, filter_seed, obs, seen)
    limits = np.array([SERVICE[c][0] for c in causes])
    life = remaining_life(state, plane.failure, settings.q, filter_seed + 1, service_limit=limits)
    evidence.update(observed_laps=len(obs), alignments_used=0, features=list(names), last_read_lap=obs[-1].lap)
    told = abs(float(np.corrcoef(state.value[:, 0], state.value[:, 1])[0, 1])) < TELLS_APART
    per = {c: {"value_now": state.quantiles(dim=k)[1], "value_band": state.quantiles((0.05, 0.95), dim=k),
               "rate": state.rate_quantiles(dim=k), "band": [(b[0], *b[1 + 3 * k:4 + 3 * k]) for b in state.band]}
           for k, c in enumerate(causes)}
    together = (f"{causes[0]} and {causes[1]} wearing together (neither alone explains the laps"
                + ("" if told else "; the laps cannot tell yet how much of the wear is each's") + ")")
    advice: list[str] = []
    failing_now = float(plane.failure.threshold(np.array(per[causes[1]]["value_now"])))
    if outs and outs[-1].failed and outs[-1].lap == now_lap:
        statement = f"the gains in force already fail (the robot's last lap, {now_lap}, did), {together}"
        laps_to, interval, quantiles = 0.0, (0.0, 0.0), life.quantiles()
        advice.append(f"re-tune now: the gains in force already fail (live --act does it, or tune with --set "
                      f"{causes[0]}={failing_now:.4g} --set {causes[1]}={per[causes[1]]['value_now']:.4g})")
    else:
        statement = f"{life_sentence(life)}, {together}"
        humps = shape_sentence(life)
        if humps:
            statement = f"{statement}; {humps}"
        quantiles = life.quantiles()
        laps_to, interval = quantiles["50"], (quantiles["5"], quantiles["95"])
        retune = retune_advice(life, causes[0], failing_now, {causes[1]: per[causes[1]]["value_now"]})
        if retune:
            advice.append(retune)
    for k, c in enumerate(causes):
        said = service_advice(life, SERVICE[c][1], c, SERVICE[c][0], dim=k)
        if said:
            advice.append(said)
    since = carried_on(obs[-1].lap, outs, now_lap)
    evidence["carried_on"] = bool(since)
    now = "; ".join(f"{c} is {p['value_now']:.4g} now (90 % {p['value_band'][0]:.4g}–{p['value_band'][1]:.4g})"
                    for c, p in per.items()) + (f" ({since})" if since else "")
    note = (f"{now}, from {len(obs)} laps read through the twin ({', '.join(names)}) and "
            f"{evidence['laps']} lap outcomes on these gains ({evidence['failed']} failed); on the twin half their "
            f"laps fail at {causes[0]} {failing_now:.4g} with {causes[1]} at its value now (raced at {causes[1]} "
            f"{', '.join(f'{w:.4g}' for w in plane.rows)})")
    return Forecast(address, now_lap, statement, None, None, None, None, laps_to, interval, quantiles, plane.raced,
                    plane.laps, evidence, (), tuple(advice), note, None, life.by_shape(), per)


def forecasts_of(twin: DigitalTwin, gains: dict, alignments: list[dict], laps: list[dict], causes: list[str],
                 now_lap: int, seed: int = 0, filter_seed: int | None = None,
                 record: dict | None = None, race_wait_s: float | None = None,
                 seeds: int | None = None) -> dict[str, Forecast]:
    """{address: forecast} for each cause on its own and, when no one of the parts that wear explains the last laps
    while two of them do wear, for both at once (:func:`forecast_two_causes`, keyed by :func:`joint_address`).
    ``record``: each one-cause filter's inputs, by address (:func:`forecast_failure`). ``race_wait_s``: how long
    the forecasts wait in all for races another process is running (None: until they are done); a forecast whose
    races are not done by then says so. ``seeds``: the twin's noise seeds a raced value (None: each cause's as its
    timed laps ask, :func:`tuner.history.forecast.edge_seeds`, and the plane's ``EDGE_SEEDS``: on 20 a value its
    forecast moved with the filter's seed, by 65 % of the true life against 0 on 5, docs/models.md)."""
    left = time_left(race_wait_s)
    out: dict[str, Forecast] = {}
    for a in causes:  # once a race is another process's, the ones after it are to come from it too: not raced here
        waiting = any(f.note == STILL_RACING for f in out.values())
        out[a] = forecast_failure(twin, gains, alignments, laps, a, now_lap, seed=seed, filter_seed=filter_seed,
                                  record=record, race_wait_s=left(), race_here=not waiting, seeds=seeds)
    worn = tuple(sorted(SERVICE))
    if len(worn) == 2 and all(a in out and alone_explains(out[a]) is False for a in worn):
        out[joint_address(worn)] = forecast_two_causes(twin, gains, laps, worn, now_lap, seed=seed,
                                                       filter_seed=filter_seed, race_wait_s=left(),
                                                       seeds=EDGE_SEEDS if seeds is None else seeds)
    return out
