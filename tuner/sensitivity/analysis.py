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

**Censored outputs.** A model may give NaN for a run that has no value (a failed lap has no lap time). Nothing is
written in for it. Morris then averages only the elementary effects whose two runs both have a value. Saltelli's
estimators need every row of their design (its A, B and A_B^i matrices pair up row by row): with rows missing they are
biased, and the runs that have a value no longer have independent inputs (what fails couples them), which Sobol'
decomposition assumes. So such an output gets, from the Sobol' stage's runs that have a value, Borgonovo's
moment-independent δ (Borgonovo 2007, *Reliab. Eng. Syst. Saf.* 92:771; the given-data estimator of Plischke,
Borgonovo & Smith 2013, *EJOR* 226:536, SALib's ``delta``, bias-reduced, with its bootstrap interval) and the
given-data first-order S1: both are defined for any input distribution, dependent inputs included, and need no
design. A dummy column, random and read by nothing, is analysed with them: its δ is the estimator's noise floor, and
δ is measured only when its interval lies above it. Fewer than :data:`MIN_GIVEN` runs with a value: no δ (a note says
how many more samples it needs).

**Precision** (:mod:`tuner.sensitivity.precision`). Every index is a fraction of a variance (or of a distribution's
shift), in [0, 1]; an estimate outside it is sampling error, so it is clipped to [0, 1] and a note gives the raw
value. When an interval's half-width exceeds ±0.1 the sample is too small for the indices to mean much: a note
starting with ``too few samples`` says so and what sample would narrow it to that (half-widths shrink as 1/√N).

An output that does not vary within a stage (every lap completed) gets no indices from that stage: ``notes`` says
so. Every random choice (sampling, bootstrap) is seeded from ``seed``: the same seed gives bit-identical indices.
"""

from __future__ import annotations

import dataclasses
import math
import warnings
from typing import Callable, Mapping, Sequence

import numpy as np

from tuner.search.space import TunerError
from tuner.sensitivity.precision import TOO_FEW, clipped, flag_precision
from tuner.sensitivity.ranges import Factor

LEVELS = 4  # Morris grid levels (the classic choice with Δ = 2/3 of the range)
SCREEN_SHARE = 0.10  # a factor matters when its μ* reaches this share of the largest μ* on some output
RESAMPLES = 1000  # bootstrap resamples of every interval
CONFIDENCE = 0.95
MIN_TOTAL = 0.05  # a relation is measured when ST (or δ) ≥ this and its interval lies above 0 (δ: above the dummy's)
MIN_GIVEN = 100  # runs with a value the given-data δ needs at least (SALib's 10 bins of at least 10)
DELTA_RESAMPLES = 200  # bootstrap resamples of δ (each one a kernel density estimate per bin)
DUMMY = "dummy (reads nothing)"
SELECTION_SHARE = 0.01  # a δ whose factor's μ* is under this share of the largest: it acts through what completes

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
    delta: float | None = None  # Borgonovo's δ over the runs with a value (method "delta"; ``first`` is then S1)
    delta_interval: tuple[float, float] | None = None
    floor: float | None = None  # δ of a dummy factor on the same runs: the estimator's noise

    @property
    def index(self) -> float | None:
        """The importance measured: ST (method "sobol"), δ (method "delta"), None (screened out)."""
        return self.delta if self.method == "delta" else self.total

    @property
    def index_interval(self) -> tuple[float, float] | None:
        return self.delta_interval if self.method == "delta" else self.total_interval

    @property
    def index_name(self) -> str:
        return "δ" if self.method == "delta" else "ST"

    @property
    def measured(self) -> bool:
        """The output depends on the factor: ST (or δ) ≥ :data:`MIN_TOTAL` with its interval above 0 (δ: above the
        dummy factor's δ)."""
        if self.index is None or not self.index >= MIN_TOTAL:
            return False
        floor = (self.floor or 0.0) if self.method == "delta" else 0.0
        return self.index_interval[0] > floor


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
                               float(i["sigma"]), i.get("delta"), pair(i.get("delta_interval")), i.get("floor"))
                     for i in d["influences"])
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


def problem_of(factors: Sequence[Factor]) -> dict:
    """SALib's problem: the factors' names and bounds."""
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
    """At least two runs have a value, and their values differ."""
    y = y[np.isfinite(y)]
    return bool(len(y) >= 2 and np.ptp(y) > 0)


def _censored(y: np.ndarray) -> bool:
    return not bool(np.all(np.isfinite(y)))


def _why_constant(o: str, y: np.ndarray, stage: str) -> str:
    finite = y[np.isfinite(y)]
    if len(finite) < 2:
        return f"{o}: {len(y) - len(finite)} of {len(y)} runs of the {stage} stage gave no value: no indices from it"
    return f"{o}: the same in every run of the {stage} stage that gave one ({finite[0]:.6g}): no indices from it"


def _elementary_effects(X: np.ndarray, y: np.ndarray, k: int) -> list[np.ndarray]:
    """Per factor, Morris' elementary effects (output unit per full range of the factor, as SALib's) of the steps
    whose two runs both have a value; X holds whole trajectories of k + 1 rows, each step changing one factor by
    Δ = 2/3 of its range (:data:`LEVELS` levels)."""
    delta = LEVELS / (2 * (LEVELS - 1))
    effects: list[list[float]] = [[] for _ in range(k)]
    for t in range(0, len(X), k + 1):
        for j in range(t, t + k):
            step = X[j + 1] - X[j]
            i = int(np.argmax(np.abs(step)))
            if np.isfinite(y[j]) and np.isfinite(y[j + 1]):
                effects[i].append(float(np.sign(step[i]) * (y[j + 1] - y[j]) / delta))
    return [np.array(e) for e in effects]


def screen_censored(factors: Sequence[Factor], X: np.ndarray, y: np.ndarray, seed: int, o: str,
                     notes: list[str]) -> dict:
    """Morris on an output some runs gave no value for: μ*, its bootstrap interval and σ over the elementary
    effects that have both runs (NaN where none has)."""
    from scipy.stats import norm

    rng = np.random.default_rng(stage_seed(seed, 2))
    z = float(norm.ppf(0.5 + CONFIDENCE / 2))  # SALib's μ* interval: z × the bootstrap's standard deviation
    result, short = {}, []
    for f, ee in zip(factors, _elementary_effects(X, y, len(factors))):
        if len(ee) < 2:
            short.append(f.address)
            result[(f.address, o)] = (math.nan, (math.nan, math.nan), math.nan)
            continue
        mu = float(np.mean(np.abs(ee)))
        boot = np.abs(ee[rng.integers(0, len(ee), size=(RESAMPLES, len(ee)))]).mean(axis=1)
        result[(f.address, o)] = (mu, _interval(mu, z * boot.std(ddof=1)), float(np.std(ee, ddof=1)))
    notes.append(f"{o}: {int(np.sum(~np.isfinite(y)))} of {len(y)} Morris runs gave no value: μ* over the steps "
                 "whose two runs both gave one" + (f"; fewer than 2 such steps for {', '.join(short)} (no μ*)"
                                                   if short else ""))
    return result


def screen(factors: Sequence[Factor], model: Model, outputs: Sequence[str], trajectories: int, seed: int,
           on_stage: Callable[[str, int], None] | None = None) -> tuple[dict, dict[str, np.ndarray], list[str]]:
    """Morris: {(parameter, output): (μ*, μ* interval, σ)}, the outputs of every run, and notes."""
    from SALib.analyze import morris as morris_analyze
    from SALib.sample import morris as morris_sample

    problem = problem_of(factors)
    X = morris_sample.sample(problem, N=trajectories, num_levels=LEVELS, seed=stage_seed(seed, 1))
    Y = _run(model, problem, X, outputs, "Morris screening", on_stage)
    result, notes = {}, []
    for o in outputs:
        if not _varies(Y[o]):
            notes.append(_why_constant(o, Y[o], "Morris"))
            for f in factors:
                result[(f.address, o)] = (0.0, (0.0, 0.0), 0.0)
            continue
        if _censored(Y[o]):
            result.update(screen_censored(factors, X, Y[o], seed, o, notes))
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
    mu = {key: (0.0 if math.isnan(v[0]) else v[0]) for key, v in screened.items()}  # no μ*: no evidence it matters
    for o in outputs:
        top = max(mu[(f.address, o)] for f in factors)
        if top > 0:
            for f in factors:
                share[f.address] = max(share[f.address], mu[(f.address, o)] / top)
    keep = [a for a in share if share[a] >= SCREEN_SHARE]
    keep.sort(key=lambda a: -share[a])  # stable: ties keep the factors' order
    return keep[:max_sobol]


def _given_data(problem: dict, X: np.ndarray, y: np.ndarray, seed: int) -> dict:
    """SALib's ``delta`` (Borgonovo's δ, given-data S1) over the rows with a value, a dummy column appended last."""
    from SALib.analyze import delta as delta_analyze
    from threadpoolctl import threadpool_limits

    ok = np.isfinite(y)
    dummy = np.random.default_rng(stage_seed(seed, 5)).uniform(size=int(ok.sum()))
    given = {"num_vars": problem["num_vars"] + 1, "names": [*problem["names"], DUMMY],
             "bounds": [*problem["bounds"], [0.0, 1.0]]}
    state = np.random.get_state()  # SALib's delta seeds numpy's global generator: leave it as it was
    try:
        # one BLAS thread: each of its small density estimates is a triangular solve that threads only slow down
        with warnings.catch_warnings(), threadpool_limits(limits=1, user_api="blas"):
            warnings.simplefilter("ignore")  # its bin-merge notices; what it could not estimate comes back as NaN
            return delta_analyze.analyze(given, np.column_stack([X[ok], dummy]), y[ok], num_resamples=DELTA_RESAMPLES,
                                         conf_level=CONFIDENCE, seed=stage_seed(seed, 6))
    finally:
        np.random.set_state(state)


def sobol_indices(factors: Sequence[Factor], model: Model, outputs: Sequence[str], samples: int, seed: int,
                  on_stage: Callable[[str, int], None] | None = None) -> tuple[dict, dict[str, np.ndarray], list[str]]:
    """Saltelli sampling and Sobol' indices: {(parameter, output): {"first", "total", ...: (value, interval)}},
    outputs, notes; an output some runs gave no value for gets δ and the given-data S1 instead (see the module
    docstring)."""
    from SALib.analyze import sobol as sobol_analyze
    from SALib.sample import sobol as sobol_sample

    problem = problem_of(factors)
    X = sobol_sample.sample(problem, samples, calc_second_order=False, scramble=True, seed=stage_seed(seed, 3))
    Y = _run(model, problem, X, outputs, "Sobol' indices", on_stage)
    result, notes = {}, []
    names = [f.address for f in factors]
    for o in outputs:
        if not _varies(Y[o]):
            notes.append(_why_constant(o, Y[o], "Sobol'"))
            continue
        if _censored(Y[o]):
            n = int(np.sum(np.isfinite(Y[o])))
            if n < MIN_GIVEN:
                per_sample = n / samples
                more = 2 ** math.ceil(math.log2(max(MIN_GIVEN / max(per_sample, 1e-9), samples * 2)))
                notes.append(f"{TOO_FEW}: {o}: {n} of {len(X)} Sobol' runs gave a value; Borgonovo's δ over them needs "
                             f"at least {MIN_GIVEN}: no indices (about --samples {more} would give them)")
                continue
            d = _given_data(problem, X, Y[o], seed)
            floor = float(d["delta_raw"][-1])
            deltas = clipped(o, "δ", {a: (float(d["delta_raw"][i]), _interval(d["delta_raw"][i], d["delta_raw_conf"][i]))
                                       for i, a in enumerate(names)}, notes)
            firsts = clipped(o, "S1", {a: (float(d["S1"][i]), _interval(d["S1"][i], d["S1_conf"][i]))
                                        for i, a in enumerate(names)}, notes)
            for a in names:
                result[(a, o)] = {"method": "delta", "first": firsts[a], "delta": deltas[a], "floor": floor}
            notes.append(f"{o}: {len(X) - n} of {len(X)} Sobol' runs gave no value: Borgonovo's δ and the given-data S1 "
                         f"over the {n} that did (a dummy factor's δ, the noise floor: {floor:.3f})")
            flag_precision(o, "δ", max(float(np.nanmax(d["delta_raw_conf"][:-1])), 0.0), n, "runs with a value",
                            notes, power_of_two=False)
            continue
        s = sobol_analyze.analyze(problem, Y[o], calc_second_order=False, num_resamples=RESAMPLES,
                                  conf_level=CONFIDENCE, seed=stage_seed(seed, 4))
        firsts = clipped(o, "S1", {a: (float(s["S1"][i]), _interval(s["S1"][i], s["S1_conf"][i]))
                                    for i, a in enumerate(names)}, notes)
        totals = clipped(o, "ST", {a: (float(s["ST"][i]), _interval(s["ST"][i], s["ST_conf"][i]))
                                    for i, a in enumerate(names)}, notes)
        for a in names:
            result[(a, o)] = {"method": "sobol", "first": firsts[a], "total": totals[a]}
        flag_precision(o, "ST", float(np.max(s["ST_conf"])), samples, "base samples (--samples)", notes)
    return result, Y, notes


def selection_notes(influences: Sequence[Influence], outputs: Sequence[str]) -> list[str]:
    """A δ measured over the runs with a value, for a factor whose direct effect (Morris μ*, from steps whose two
    runs both gave one) is under :data:`SELECTION_SHARE` of the largest on that output: it tells the output mostly
    through which runs give a value (at low grip only the slower settings complete), not by moving a run."""
    out = []
    for o in outputs:
        rows = [i for i in influences if i.output == o]
        top = max((i.mu_star for i in rows if not math.isnan(i.mu_star)), default=0.0)
        chosen = [i for i in rows if i.method == "delta" and i.measured and not i.mu_star >= SELECTION_SHARE * top]
        if chosen:
            out.append(f"{o}: {', '.join(f'{i.parameter} (δ {i.delta:.2f}, μ* {i.mu_star:.3g})' for i in chosen)}: "
                       f"measured over the runs that gave a value, yet moving a run by under {SELECTION_SHARE:.0%} of the "
                       "most (μ*): it acts through which runs give one (which laps complete), not on a run")
    return out


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
            got = sobol.get((f.address, o))
            if got and got["method"] == "sobol":
                (s1, s1_ci), (st, st_ci) = got["first"], got["total"]
                influences.append(Influence(f.address, o, "sobol", s1, s1_ci, st, st_ci, mu, mu_ci, sigma))
            elif got:
                (s1, s1_ci), (d, d_ci) = got["first"], got["delta"]
                influences.append(Influence(f.address, o, "delta", s1, s1_ci, None, None, mu, mu_ci, sigma, d, d_ci,
                                            got["floor"]))
            else:
                influences.append(Influence(f.address, o, "morris", None, None, None, None, mu, mu_ci, sigma))
    notes += selection_notes(influences, outputs)
    summary = {}
    for o in outputs:
        y = np.concatenate([y_morris[o], y_sobol[o]])
        y = y[np.isfinite(y)]
        summary[o] = {"mean": float(y.mean()), "std": float(y.std()), "min": float(y.min()), "max": float(y.max()),
                      "median": float(np.median(y))} if len(y) else {}
    return Analysis(tuple(factors), tuple(outputs), tuple(influences), tuple(chosen),
                    len(next(iter(y_morris.values()))), sobol_runs, samples, trajectories, int(seed), summary,
                    tuple(notes))
