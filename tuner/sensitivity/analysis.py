"""Global sensitivity, measured (SALib): Morris screening over every factor, then Sobol' indices for the ones that
matter.

One code path for any deterministic model that maps a sample of factor values to named outputs: the twin's laps
(:mod:`tuner.sensitivity.laps`) or an analytic function of known indices (the tests' Ishigami function).

1. **Morris** (Morris 1991, with Campolongo et al. 2007's μ*): ``trajectories`` one-at-a-time paths of k + 1 points on
   a 4-level grid of each factor's range. Per factor and output: μ*, the mean absolute elementary effect, in the
   output's unit per full range of the factor, with its 95 % bootstrap interval; σ, their spread (interactions,
   non-linearity).
2. **Selection**: a factor matters when its μ* on some output that varies is at least :data:`SCREEN_SHARE` of the
   largest μ* on that output; at most ``max_sobol`` of them, the largest share first.
3. **Sobol'** (Saltelli 2002/2010 sampling on a scrambled Sobol' sequence): N (k' + 2) points for the k' factors
   that matter, every other factor at the model's nominal value; first-order S1 and total ST indices with 95 %
   bootstrap intervals (:data:`RESAMPLES` resamples). No second-order indices.

An output that does not vary within a stage (every lap completed) gets no indices from that stage: ``notes`` says
so. Every random choice (sampling, bootstrap) is seeded from ``seed``: the same seed gives bit-identical indices.
"""

from __future__ import annotations

import dataclasses
from typing import Callable, Mapping, Sequence

import numpy as np

from tuner.search.space import TunerError
from tuner.sensitivity.ranges import Factor

LEVELS = 4  # Morris grid levels (the classic choice with Δ = 2/3 of the range)
SCREEN_SHARE = 0.10  # a factor matters when its μ* reaches this share of the largest μ* on some output
RESAMPLES = 1000  # bootstrap resamples of every interval
CONFIDENCE = 0.95
MIN_TOTAL = 0.05  # a relation is measured when ST ≥ this and its interval lies above 0

Model = Callable[[Sequence[str], np.ndarray], Mapping[str, np.ndarray]]  # (names, X (n, k)) → {output: (n,)}


@dataclasses.dataclass(frozen=True)
class Influence:
    """What one factor does to one output. ``method``: "sobol" (its indices were measured) or "morris" (screened
    out: μ* only). Intervals are 95 % bootstrap intervals [low, high]."""

    parameter: str
    output: str
    method: str
    first: float | None
    first_interval: tuple[float, float] | None
    total: float | None
    total_interval: tuple[float, float] | None
    mu_star: float  # [output unit] per full range of the factor
    mu_star_interval: tuple[float, float]
    sigma: float

    @property
    def measured(self) -> bool:
        """The output depends on the factor: ST ≥ :data:`MIN_TOTAL` with its interval above 0."""
        return self.total is not None and self.total >= MIN_TOTAL and self.total_interval[0] > 0


@dataclasses.dataclass(frozen=True)
class Analysis:
    """Both stages' results. ``summary``: per output, mean, std, min and max over every run; ``extra``: what the
    caller adds (laps, wall time, the twin's configuration)."""

    factors: tuple[Factor, ...]
    outputs: tuple[str, ...]
    influences: tuple[Influence, ...]
    selected: tuple[str, ...]  # the factors Sobol' indices were measured for
    morris_runs: int
    sobol_runs: int
    samples: int
    trajectories: int
    seed: int
    summary: dict
    notes: tuple[str, ...]
    extra: dict = dataclasses.field(default_factory=dict)

    @property
    def runs(self) -> int:
        return self.morris_runs + self.sobol_runs

    def influence(self, parameter: str, output: str) -> Influence | None:
        return next((i for i in self.influences if i.parameter == parameter and i.output == output), None)

    def to_dict(self) -> dict:
        d = dataclasses.asdict(self)
        d["factors"] = [dataclasses.asdict(f) for f in self.factors]
        d["influences"] = [dataclasses.asdict(i) for i in self.influences]
        return d

    @classmethod
    def from_dict(cls, d: Mapping) -> "Analysis":
        """The inverse of :meth:`to_dict` (a cached result read back); KeyError/TypeError/ValueError when malformed."""
        pair = lambda v: None if v is None else (float(v[0]), float(v[1]))  # noqa: E731
        infl = tuple(Influence(i["parameter"], i["output"], i["method"], i["first"], pair(i["first_interval"]),
                               i["total"], pair(i["total_interval"]), float(i["mu_star"]), pair(i["mu_star_interval"]),
                               float(i["sigma"])) for i in d["influences"])
        return cls(tuple(Factor(**f) for f in d["factors"]), tuple(d["outputs"]), infl, tuple(d["selected"]),
                   int(d["morris_runs"]), int(d["sobol_runs"]), int(d["samples"]), int(d["trajectories"]),
                   int(d["seed"]), dict(d["summary"]), tuple(d["notes"]), dict(d.get("extra") or {}))


def check_samples(samples: int) -> int:
    """Saltelli's base sample size: a power of two ≥ 8 (a Sobol' sequence is balanced only at powers of two)."""
    if not isinstance(samples, int) or samples < 8 or samples & (samples - 1):
        raise TunerError(f"--samples {samples}: must be a power of two, at least 8 (Sobol' sequences are balanced only "
                         "at powers of two), e.g. 256")
    return samples


def stage_seed(seed: int, stage: int) -> int:
    """A seed per stage, derived from the user's; never 0 (SALib's Sobol' bootstrap treats 0 as "unseeded")."""
    return int(np.random.SeedSequence(int(seed), spawn_key=(stage,)).generate_state(1)[0]) + 1


def _problem(factors: Sequence[Factor]) -> dict:
    return {"num_vars": len(factors), "names": [f.address for f in factors],
            "bounds": [[f.lower, f.upper] for f in factors]}


def _interval(value: float, half: float) -> tuple[float, float]:
    return (float(value - half), float(value + half))


def _run(model: Model, problem: dict, X: np.ndarray, outputs: Sequence[str], stage: str,
         on_stage: Callable[[str, int], None] | None) -> dict[str, np.ndarray]:
    """One stage's runs: the model at every row of X, its outputs checked."""
    if on_stage:
        on_stage(stage, len(X))
    Y = model(problem["names"], X)
    out = {}
    for o in outputs:
        y = np.asarray(Y[o], dtype=float)
        if y.shape != (len(X),):
            raise TunerError(f"sensitivity: the model gave {y.shape} values of {o} for {len(X)} runs")
        out[o] = y
    return out


def _varies(y: np.ndarray) -> bool:
    return bool(np.all(np.isfinite(y)) and np.ptp(y) > 0)


def _why_constant(o: str, y: np.ndarray, stage: str) -> str:
    if not np.all(np.isfinite(y)):
        return f"{o}: {int(np.sum(~np.isfinite(y)))} runs of the {stage} stage gave no value: no indices from it"
    return f"{o}: the same in every run of the {stage} stage ({y[0]:.6g}): no indices from it"


def screen(factors: Sequence[Factor], model: Model, outputs: Sequence[str], trajectories: int, seed: int,
           on_stage: Callable[[str, int], None] | None = None) -> tuple[dict, dict[str, np.ndarray], list[str]]:
    """Morris: {(parameter, output): (μ*, μ* interval, σ)}, the outputs of every run, and notes."""
    from SALib.analyze import morris as morris_analyze
    from SALib.sample import morris as morris_sample

    problem = _problem(factors)
    X = morris_sample.sample(problem, N=trajectories, num_levels=LEVELS, seed=stage_seed(seed, 1))
    Y = _run(model, problem, X, outputs, "Morris screening", on_stage)
    result, notes = {}, []
    for o in outputs:
        if not _varies(Y[o]):
            notes.append(_why_constant(o, Y[o], "Morris"))
            for f in factors:
                result[(f.address, o)] = (0.0, (0.0, 0.0), 0.0)
            continue
        m = morris_analyze.analyze(problem, X, Y[o], num_resamples=RESAMPLES, conf_level=CONFIDENCE,
                                   num_levels=LEVELS, seed=stage_seed(seed, 2))
        for i, f in enumerate(factors):
            result[(f.address, o)] = (float(m["mu_star"][i]), _interval(m["mu_star"][i], m["mu_star_conf"][i]),
                                      float(m["sigma"][i]))
    return result, Y, notes


def select(factors: Sequence[Factor], screened: Mapping, outputs: Sequence[str], max_sobol: int) -> list[str]:
    """The factors that matter (see the module docstring), the largest share first."""
    share = {f.address: 0.0 for f in factors}
    for o in outputs:
        top = max(screened[(f.address, o)][0] for f in factors)
        if top > 0:
            for f in factors:
                share[f.address] = max(share[f.address], screened[(f.address, o)][0] / top)
    keep = [a for a in share if share[a] >= SCREEN_SHARE]
    keep.sort(key=lambda a: -share[a])  # stable: ties keep the factors' order
    return keep[:max_sobol]


def sobol_indices(factors: Sequence[Factor], model: Model, outputs: Sequence[str], samples: int, seed: int,
                  on_stage: Callable[[str, int], None] | None = None) -> tuple[dict, dict[str, np.ndarray], list[str]]:
    """Saltelli sampling and Sobol' indices: {(parameter, output): (S1, S1 interval, ST, ST interval)}, outputs, notes."""
    from SALib.analyze import sobol as sobol_analyze
    from SALib.sample import sobol as sobol_sample

    problem = _problem(factors)
    X = sobol_sample.sample(problem, samples, calc_second_order=False, scramble=True, seed=stage_seed(seed, 3))
    Y = _run(model, problem, X, outputs, "Sobol' indices", on_stage)
    result, notes = {}, []
    for o in outputs:
        if not _varies(Y[o]):
            notes.append(_why_constant(o, Y[o], "Sobol'"))
            continue
        s = sobol_analyze.analyze(problem, Y[o], calc_second_order=False, num_resamples=RESAMPLES,
                                  conf_level=CONFIDENCE, seed=stage_seed(seed, 4))
        for i, f in enumerate(factors):
            result[(f.address, o)] = (float(s["S1"][i]), _interval(s["S1"][i], s["S1_conf"][i]),
                                      float(s["ST"][i]), _interval(s["ST"][i], s["ST_conf"][i]))
    return result, Y, notes


def analyse(factors: Sequence[Factor], model: Model, outputs: Sequence[str], samples: int = 256,
            trajectories: int = 12, seed: int = 0, max_sobol: int = 8,
            on_stage: Callable[[str, int], None] | None = None) -> Analysis:
    """Morris over every factor, then Sobol' indices for those that matter (see the module docstring).

    Args:
      factors: what to vary, each over [lower, upper].
      model: ``model(names, X)`` → {output: values}, X (n, len(names)) in the factors' units; factors not named
        stay at their nominal values. It must be deterministic.
      outputs: the outputs to analyse.
      samples: Saltelli's base sample N (a power of two): the Sobol' stage runs N (k' + 2) times.
      trajectories: Morris trajectories r: the screening runs r (k + 1) times.
      seed: seeds every sample and bootstrap.
      max_sobol: at most this many factors get Sobol' indices.
      on_stage: told (stage name, runs) before each stage runs.
    """
    if not factors:
        raise TunerError("sensitivity: nothing to vary")
    if len({f.address for f in factors}) != len(factors):
        raise TunerError("sensitivity: a factor is given twice")
    if not (isinstance(trajectories, int) and trajectories >= 2):
        raise TunerError(f"sensitivity: Morris needs at least 2 trajectories, got {trajectories!r}")
    check_samples(samples)
    screened, y_morris, notes = screen(factors, model, outputs, trajectories, seed, on_stage)
    chosen = select(factors, screened, outputs, max_sobol)
    sobol, y_sobol, sobol_runs = {}, {o: np.empty(0) for o in outputs}, 0
    if chosen:
        sub = [f for f in factors if f.address in chosen]
        sub.sort(key=lambda f: chosen.index(f.address))
        sobol, y_sobol, more = sobol_indices(sub, model, outputs, samples, seed, on_stage)
        sobol_runs = len(next(iter(y_sobol.values()))) if y_sobol else 0
        notes += more
    else:
        notes.append("no factor moves any output: no Sobol' stage")
    influences = []
    for f in factors:
        for o in outputs:
            mu, mu_ci, sigma = screened[(f.address, o)]
            if (f.address, o) in sobol:
                s1, s1_ci, st, st_ci = sobol[(f.address, o)]
                influences.append(Influence(f.address, o, "sobol", s1, s1_ci, st, st_ci, mu, mu_ci, sigma))
            else:
                influences.append(Influence(f.address, o, "morris", None, None, None, None, mu, mu_ci, sigma))
    summary = {}
    for o in outputs:
        y = np.concatenate([y_morris[o], y_sobol[o]])
        y = y[np.isfinite(y)]
        summary[o] = {"mean": float(y.mean()), "std": float(y.std()), "min": float(y.min()), "max": float(y.max()),
                      "median": float(np.median(y))} if len(y) else {}
    return Analysis(tuple(factors), tuple(outputs), tuple(influences), tuple(chosen),
                    len(next(iter(y_morris.values()))), sobol_runs, samples, trajectories, int(seed), summary,
                    tuple(notes))
