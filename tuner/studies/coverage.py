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

import dataclasses
import math
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
        stated, kind = (p.ci95, "ci95") if p.identifiable and p.ci95 is not None else (p.consistent, "consistent")
    else:
        from tuner.align.diagnose import diagnose_one, explaining

        if procedure == "lap_time":
            from tuner.align.lap_time import align_lap_time

            r = align_lap_time(twin, lap.lap_time_s, address, nthread=nthread)
            ranges, explained = explaining(r), r.explained
        else:
            r = diagnose_one(twin, lap.lap_time_s, address, nthread=nthread)
            ranges, explained = r.ranges, r.explained
        laps = r.laps
        # every range that explains the lap is the answer (the value given is the one nearest the twin's own)
        sets = list(ranges) if explained else []
        hit = [x for x in sets if x[0][0] <= hidden <= x[0][1]]
        stated, kind = (hit or sets or [(None, "none")])[0]
        covered = bool(hit)
        return Trial(procedure, address, hidden, robot_seed, True, tuple(stated) if stated else None, kind, covered,
                     laps, time.process_time() - c0)
    covered = stated is not None and stated[0] <= hidden <= stated[1]
    return Trial(procedure, address, hidden, robot_seed, True, tuple(stated) if stated else None, kind, covered, laps,
                 time.process_time() - c0)


@dataclasses.dataclass(frozen=True)
class PassRule:
    """Pass when at least ``least`` of ``n`` trials are covered."""

    n: int
    least: int
    claimed: float
    pass_if_claimed: float  # the probability that a procedure of the claimed coverage passes
    pass_if: dict[float, float]  # …and one of lower coverage

    def text(self) -> str:
        lower = ", ".join(f"{100 * c:g} %: {p:.3f}" for c, p in sorted(self.pass_if.items(), reverse=True))
        return (f"at least {self.least} of {self.n} covered: a {100 * self.claimed:g} % procedure passes with "
                f"probability {self.pass_if_claimed:.3f}; lower coverage passes with {lower}")


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
    """Wilson's score interval of a binomial proportion (Wilson 1927)."""
    if n == 0:
        return (0.0, 1.0)
    z = float(stats.norm.ppf(0.5 + level / 2))
    p = covered / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return (max(0.0, centre - half), min(1.0, centre + half))
