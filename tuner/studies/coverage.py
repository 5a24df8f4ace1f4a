"""Coverage study: how often the intervals that ``align`` and ``diagnose`` state hold the value a robot really had.

A trial hides one parameter's value in a robot (the twin on the same track with that value and its own noise seed,
:data:`ROBOT_SEED0` on: seeds the twin's own laps never use), runs it for one lap, and asks a procedure to explain
the lap from the twin's side:

* ``lap_time``: :func:`tuner.align.lap_time.align_lap_time` on the lap time (``align --measured-lap-time``);
* ``diagnose``: :func:`tuner.align.diagnose.diagnose_one` for the hidden parameter (one candidate of ``diagnose``,
  searched over its diagnosis range);
* ``telemetry``: :func:`tuner.align.trace.align_telemetry` on the recorded run (``align --telemetry``).

The answer's stated set is its 95 % interval where it gives one, else the values it says are consistent (a parameter
the run does not pin); a lap-time answer states one such set for every disjoint range of values that explains the
lap, and covers when one of them holds the hidden value; an answer that explains nothing states nothing and misses. The hidden values are drawn
log-uniformly across each parameter's documented physical range (:data:`tuner.sensitivity.PHYSICAL_RANGES`, as
factors of the twin's value), not at its defaults; a draw whose robot does not finish its lap has no lap to explain
and is counted apart (:attr:`Trial.robot_completed`).

:func:`pass_rule` gives the least number covered out of ``n`` that a procedure of the claimed coverage reaches with
a stated probability, and how likely a procedure of lower coverage is to pass it (binomial).
"""

from __future__ import annotations

import concurrent.futures as cf
import dataclasses
import functools
import multiprocessing
import os
import tempfile
import time
from typing import Sequence

import numpy as np
from scipy import stats

from twin.core.closed_loop import run_laps
from twin.core.digital_twin import DigitalTwin

PROCEDURES = ("lap_time", "diagnose", "telemetry")
ROBOT_SEED0 = 1000  # the robots' noise seeds start here; the twin's laps use 0, 1, 2, … (its noise seeds)


@dataclasses.dataclass(frozen=True)
class Trial:
    procedure: str
    address: str
    hidden: float
    robot_seed: int
    robot_completed: bool
    stated: tuple[float, float] | None  # the 95 % interval, or the consistent set; None: nothing explained
    kind: str  # "ci95", "consistent" or "none"
    covered: bool
    laps: int  # the twin's laps for the answer (0 where the procedure does not count them)
    cpu_s: float

    def row(self) -> dict:
        return dataclasses.asdict(self)


def draw(addresses: Sequence[str], count: int, rng: np.random.Generator, twin: DigitalTwin) -> list[tuple[str, float]]:
    """``count`` (address, hidden value) pairs cycling through ``addresses``, each value log-uniform over the
    address's documented range around the twin's value."""
    from tuner.sensitivity import PHYSICAL_RANGES

    out = []
    for k in range(count):
        address = addresses[k % len(addresses)]
        r = PHYSICAL_RANGES[address]
        out.append((address, twin.space.get(address) * float(np.exp(rng.uniform(np.log(r.low), np.log(r.high))))))
    return out


def run_trial(twin: DigitalTwin, procedure: str, address: str, hidden: float, robot_seed: int,
              folder: str | None = None, nthread: int = 1) -> Trial:
    """One trial (see the module docstring); the twin is not changed."""
    if procedure not in PROCEDURES:
        raise ValueError(f"coverage: procedure {procedure!r} is not one of {', '.join(PROCEDURES)}")
    c0 = time.process_time()
    lap = run_laps(twin, [{address: hidden}], seed=robot_seed, keep_traces=procedure == "telemetry")[0]
    if not lap.completed:
        return Trial(procedure, address, hidden, robot_seed, False, None, "none", False, 0, time.process_time() - c0)
    laps = 0
    if procedure == "telemetry":
        from tuner.align.trace import align_telemetry
        from twin.telemetry.jsonl import lap_lines, read_telemetry, telemetry_header, write_telemetry

        with tempfile.TemporaryDirectory(dir=folder) as where:
            path = write_telemetry(os.path.join(where, "run.jsonl"),
                                   lap_lines(lap, telemetry_header(twin, twin.track.name, robot_seed), 2))
            (p,) = align_telemetry(twin, read_telemetry(path), [address], nthread=nthread).parameters
        sets = [(p.ci95, "ci95") if p.identifiable and p.ci95 is not None else (p.consistent, "consistent")]
    else:
        from tuner.align.diagnose import diagnose_one, explaining

        if procedure == "lap_time":
            from tuner.align.lap_time import align_lap_time

            r = align_lap_time(twin, lap.lap_time_s, address, nthread=nthread)
            ranges = explaining(r)
        else:
            r = diagnose_one(twin, lap.lap_time_s, address, nthread=nthread)
            ranges = r.ranges
        laps = r.laps
        # every range that explains the lap is the answer (the value given is the one nearest the twin's own)
        sets = list(ranges) if r.explained else []
    hit = [x for x in sets if x[0][0] <= hidden <= x[0][1]]
    stated, kind = (hit or sets or [(None, "none")])[0]
    return Trial(procedure, address, hidden, robot_seed, True, tuple(stated) if stated else None, kind, bool(hit), laps,
                 time.process_time() - c0)


@functools.cache
def _twin(track: str, gains: tuple[tuple[str, float], ...]) -> DigitalTwin:
    """The twin of a worker process (built once per process and kept: laps reuse its model)."""
    twin = DigitalTwin(track=track)
    twin.update(dict(gains))
    return twin


def _job(job: tuple) -> Trial:
    procedure, address, hidden, seed, track, gains = job
    return run_trial(_twin(track, gains), procedure, address, hidden, seed)


@dataclasses.dataclass(frozen=True)
class Study:
    trials: list[Trial]
    robots_drawn: int
    robots_finished: int


def run_study(track: str, gains: dict, procedures: Sequence[str], per_procedure: int, addresses: Sequence[str],
              rng_seed: int, workers: int = 2) -> Study:
    """``per_procedure`` trials of each procedure whose robots finish: hidden values drawn (:func:`draw`) for
    ``addresses`` in turn, the robots on seeds from :data:`ROBOT_SEED0` raced in one batch (a draw whose robot does
    not finish is passed over), the procedures in turn over the robots that finish; run in ``workers`` processes.
    ValueError if too few robots finish."""
    key = tuple(sorted(gains.items()))
    twin = _twin(track, key)
    draws = draw(addresses, 3 * per_procedure * len(procedures), np.random.default_rng(rng_seed), twin)
    seeds = [ROBOT_SEED0 + k for k in range(len(draws))]
    robots = run_laps(twin, [{a: v} for a, v in draws], seed=seeds, keep_traces=False)
    kept = [(a, v, s) for (a, v), s, r in zip(draws, seeds, robots) if r.completed]
    jobs = [(procedures[k % len(procedures)], a, v, s, track, key) for k, (a, v, s) in enumerate(kept)]
    jobs = [j for p in procedures for j in [j for j in jobs if j[0] == p][:per_procedure]]
    if len(jobs) < per_procedure * len(procedures):
        raise ValueError(f"coverage study: only {len(kept)} of {len(draws)} robots finished their lap")
    with cf.ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("spawn")) as pool:
        return Study(list(pool.map(_job, jobs)), len(draws), len(kept))


@dataclasses.dataclass(frozen=True)
class PassRule:
    """Pass when at least ``least`` of ``n`` trials are covered."""

    n: int
    least: int
    claimed: float
    pass_if_claimed: float  # the probability that a procedure of the claimed coverage passes
    pass_if: dict[float, float]  # …and one of lower coverage


def pass_rule(n: int, least: int, claimed: float = 0.95, lower: Sequence[float] = (0.9, 0.8, 0.7)) -> PassRule:
    """The binomial probabilities of passing ``least`` of ``n`` at the claimed and at lower coverages."""
    def passes(p: float) -> float:
        return float(stats.binom.sf(least - 1, n, p))
    return PassRule(n, least, claimed, passes(claimed), {c: passes(c) for c in lower})


def coverage(trials: Sequence[Trial]) -> tuple[int, int]:
    """(covered, trials whose robot finished)."""
    done = [t for t in trials if t.robot_completed]
    return sum(t.covered for t in done), len(done)


def wilson(covered: int, n: int, level: float = 0.95) -> tuple[float, float]:
    """Wilson's score interval of a binomial proportion (Wilson 1927), as scipy computes it."""
    if n == 0:
        return (0.0, 1.0)
    ci = stats.binomtest(covered, n).proportion_ci(level, method="wilson")
    return (float(ci.low), float(ci.high))
