"""Design-parameter study (paper §4.2, Fig. 5): how the robot's geometry changes the lap time it can reach.

For each design on a grid over ``cad.*`` parameters: rebuild the robot, tune the control gains from the same
start with the learning model until convergence (or the iteration cap: each design says which, ``converged`` and
``search``), then run the tuned gains for ``laps`` laps with different sensor-noise seeds (the paper takes laps from lap 100 on, once the gains have converged). The
spread of those laps is the design's lap-time distribution.

Designs run in parallel, one process per core (each tunes with one thread, so a design's result does not
depend on how many run at once). A design that cannot be built or fails is reported with its reason and the
others go on.

With a program for the robot's MCU (``base["firmware"]``) the laps after tuning run on the emulated MCU: the twin's
own firmware (``avr``, or its ELF) is tuned on the C loop, which runs the same C source, then raced on the MCU; any
other 3pi program keeps the gains compiled into it, so its designs are not tuned, only raced.
"""

from __future__ import annotations

import concurrent.futures as cf
import dataclasses
import itertools
import logging
import math
import multiprocessing
import os
import signal
import threading
import time
from typing import Callable, Mapping, Sequence

import numpy as np

from lf_common.errors import LineFollowerError
from tuner.studies.evidence import evidence
from tuner.search.envelope import ROBUST_AXES, ROBUST_RISK, ROBUST_SEEDS, Envelope, Risk
from tuner.search.gradient import DescentOptions, descend
from tuner.search.objective import LapObjective
from tuner.search.space import SearchSpace, robot_bounds
from tuner.studies.sweep import firmware_lap
from twin.core.closed_loop import run_laps
from twin.core.lap import LapLimits
from twin.core.digital_twin import DigitalTwin
from twin.core.identity import tuned_for
from twin.model.motor_setup import MOTOR_MODEL, catalogue_motor, use_motor
from twin.pil.board import Operator, load_script
from twin.pil.program import load_program

log = logging.getLogger(__name__)

PARENT_POLL_S = 0.5  # how often a worker checks that the study's process is still there [s]
DEFAULT_GRID: dict[str, tuple[float, ...]] = {"cad.L": (0.035, 0.045, 0.055), "cad.S": (0.04, 0.06, 0.08)}
NOT_TUNED = "not tuned: a 3pi program keeps the gains compiled into it"


@dataclasses.dataclass(frozen=True)
class DesignResult:
    """One design: its parameters, tuned gains and converged lap times, or why it failed."""

    design: dict[str, float | str]  # a categorical parameter (motor.model) holds a name
    ok: bool
    error: str | None
    gains: dict[str, float]
    tuning_iterations: int
    tuning_laps: int
    converged: bool
    lap_times_s: tuple[float, ...]  # completed laps of the converged gains, one per seed
    failed_laps: int
    mean_cross_track_m: float
    wall_s: float
    evidence: dict = dataclasses.field(default_factory=dict)  # tuner.studies.evidence, from one traced lap
    search: str = ""  # how the gains' search ended: "converged: …", or the iteration cap it stopped at
    tuned_for: dict = dataclasses.field(default_factory=dict)  # the robot, motor and track (twin.core.identity)

    @property
    def tuned(self) -> str:
        """A short word on the gains: converged, or the best found when the search stopped at its limit."""
        return "converged" if self.converged else "not converged"

    @property
    def label(self) -> str:
        return ", ".join(f"{a.split('.')[-1]}={v}" if isinstance(v, str) else
                         f"{a.split('.')[-1]}={v * 1000:g} mm" if a.startswith("cad.") and a[-1] in "LSRd" else f"{a}={v:g}"
                         for a, v in self.design.items())

    @property
    def median_s(self) -> float:
        return float(np.median(self.lap_times_s)) if self.lap_times_s else math.nan


def grid(params: Mapping[str, Sequence[float]]) -> list[dict[str, float]]:
    """Every combination of the given values, in order."""
    names = list(params)
    return [dict(zip(names, combo)) for combo in itertools.product(*(params[n] for n in names))]


def steps_per_design(laps: int, max_iter: int) -> int:
    """What one design will do at most, in steps of progress: its tuning iterations, then its laps."""
    return max_iter + laps


def run_design(design: dict[str, float], base: dict, laps: int, max_iter: int,
               on_step: Callable[[str, int], None] | None = None) -> DesignResult:
    """Build, tune and evaluate one design (in a worker process). Never raises for a bad design.

    ``on_step("done", n)`` after each tuning iteration and lap; at the end ``on_step("skipped", n)`` for the steps of
    :func:`steps_per_design` it did not need (a search that converged early, a design that failed)."""
    t0 = time.perf_counter()
    done = 0

    def step(it=None) -> None:
        nonlocal done
        done += 1
        if on_step:
            on_step("done", 1)

    try:
        return _run_design(design, base, laps, max_iter, t0, step)
    finally:
        if on_step and steps_per_design(laps, max_iter) > done:
            on_step("skipped", steps_per_design(laps, max_iter) - done)


def _run_design(design: dict[str, float], base: dict, laps: int, max_iter: int, t0: float,
                step: Callable) -> DesignResult:
    try:
        twin = DigitalTwin(track=base["track"], track_metres_per_pixel=base.get("metres_per_pixel"))
        values = {**base["values"], **design}
        twin.update({a: v for a, v in values.items() if a != MOTOR_MODEL})
        if MOTOR_MODEL in values:  # a catalogue motor: its constants, and the firmware's full speed to match
            use_motor(twin, catalogue_motor(str(values[MOTOR_MODEL])))
        twin.model()  # builds the robot now: a design that cannot be built fails here, with its reason
        firmware = base.get("firmware")  # None: the C loop's laps; "avr" or a program file: laps on the MCU
        program = None if firmware in (None, "avr") else load_program(firmware)
        foreign = program is not None and not program.traced  # a 3pi program: its gains are its own
        space = SearchSpace(twin.space, (), robot_bounds(twin))  # bounds that follow the design's motor and S
        if base.get("robust"):
            envelope, risk = Envelope.of(dict(ROBUST_AXES), list(range(ROBUST_SEEDS))), Risk(ROBUST_RISK)
        else:
            envelope, risk = None, Risk("mean")
        if foreign:
            gains, iterations, tuning_laps, converged, reason = {}, 0, 0, True, NOT_TUNED
        else:
            objective = LapObjective(twin, space, seed=0, nthread=1, envelope=envelope, risk=risk)
            r = descend(objective, space.to_unit(space.start(twin.space)), DescentOptions(max_iter=max_iter),
                        on_iteration=step)
            gains = space.assignments(objective.best.x)
            iterations, tuning_laps, converged, reason = len(r.iterations), objective.laps, r.converged, r.reason
            twin.update(gains)
        if firmware is None:
            lap = lambda twin, s: run_laps(twin, [{}], seed=s, nthread=1, keep_traces=False)[0]  # noqa: E731
        else:
            script = base.get("operator")
            lap = firmware_lap(program, (lambda: load_script(script)) if script else Operator, LapLimits())
        evals = []
        for s in range(1, laps + 1):
            evals.append(lap(twin, s))
            step()
        done = [e for e in evals if e.completed]
        return DesignResult(
            design, True, None, gains, iterations, tuning_laps, converged,
            tuple(float(e.lap_time_s) for e in done), len(evals) - len(done),
            float(np.mean([e.mean_cross_track_m for e in done])) if done else math.nan, time.perf_counter() - t0,
            {} if foreign else evidence(twin, seed=1), reason, {} if foreign else tuned_for(twin))
    except LineFollowerError as e:
        return DesignResult(design, False, str(e), {}, 0, 0, False, (), 0, math.nan, time.perf_counter() - t0)


_steps = None  # in a worker: the queue its designs' steps go to (see study)


def _report_step(kind: str, n: int) -> None:
    """A worker's ``on_step``: the step to the parent's queue."""
    if _steps is not None:
        _steps.put((kind, n))


def _worker_start(parent_pid: int, steps=None) -> None:
    """In each worker: leave Ctrl-C to the parent (it reaches the whole process group), and exit when the
    parent is gone, however it died (SIGKILL leaves no chance to clean up), instead of running on as an orphan;
    ``steps``: the queue of its designs' progress."""
    global _steps
    _steps = steps
    signal.signal(signal.SIGINT, signal.SIG_IGN)

    def watch() -> None:
        while os.getppid() == parent_pid:
            time.sleep(PARENT_POLL_S)
        os._exit(1)

    threading.Thread(target=watch, name="parent-watch", daemon=True).start()


def study(designs: Sequence[dict[str, float]], base: dict, laps: int = 20, max_iter: int = 30, workers: int = 0,
          on_done: Callable[[DesignResult], None] | None = None,
          on_step: Callable[[str, int], None] | None = None) -> list[DesignResult]:
    """Run every design (in parallel processes); results in the order of ``designs``. ``on_step``: each design's
    progress (see :func:`run_design`), from the workers through a queue.

    An interrupt (Ctrl-C, SIGTERM raised as an exception in the main thread) stops the workers at once: the
    running designs are abandoned, not waited for.
    """
    workers = workers or os.cpu_count() or 1
    results: list[DesignResult | None] = [None] * len(designs)
    if workers == 1:
        for i, d in enumerate(designs):
            results[i] = run_design(d, base, laps, max_iter, on_step)
            if on_done:
                on_done(results[i])
        return results
    ctx = multiprocessing.get_context("spawn")  # fresh interpreters: MuJoCo and its callback set up per worker
    steps = ctx.Queue() if on_step else None
    drain = None
    if steps is not None:
        def relay() -> None:
            for item in iter(steps.get, None):
                on_step(*item)

        drain = threading.Thread(target=relay, name="design-steps", daemon=True)
        drain.start()
    pool = cf.ProcessPoolExecutor(max_workers=min(workers, len(designs)), mp_context=ctx, initializer=_worker_start,
                                  initargs=(os.getpid(), steps))
    try:
        futures = {pool.submit(run_design, d, base, laps, max_iter, _report_step if steps else None): i
                   for i, d in enumerate(designs)}
        for f in cf.as_completed(futures):
            results[futures[f]] = f.result()
            if on_done:
                on_done(results[futures[f]])
    except BaseException:
        # the executor would wait for the running designs (minutes): stop its processes instead
        for process in list(getattr(pool, "_processes", {}).values()):
            process.terminate()
        pool.shutdown(wait=False, cancel_futures=True)
        if steps is not None:
            steps.put(None)
        raise
    pool.shutdown(wait=True)  # the workers have exited, so every step they queued is in the pipe
    if drain is not None:
        steps.put(None)  # after them: the relay ends once it has passed them on
        drain.join(timeout=5.0)
    return results


def pareto(results: Sequence[DesignResult]) -> list[bool]:
    """Which designs no other beats on both median lap time and mean cross-track error."""
    pts = [(r.median_s, r.mean_cross_track_m) if r.ok and r.lap_times_s else None for r in results]
    out = []
    for p in pts:
        if p is None:
            out.append(False)
            continue
        out.append(not any(q is not None and q != p and q[0] <= p[0] and q[1] <= p[1] for q in pts))
    return out


def trend(results: Sequence[DesignResult], address: str) -> str:
    """A plain statement of how the median lap time moves with one parameter (others averaged), over the designs
    whose gains converged only: a design stopped at its iteration cap shows where its search was, not what the
    design can do, so a trend through it would compare searches, not designs."""
    by: dict = {}
    stopped = 0
    for r in results:
        if r.ok and r.lap_times_s:
            if not r.converged:
                stopped += 1
                continue
            by.setdefault(r.design[address], []).append(r.median_s)
    left = (f"; {stopped} design{'s' if stopped > 1 else ''} left out: gains not converged, raise --max-iter"
            if stopped else "")
    if len(by) < 2:
        return f"{address}: not enough designs with converged gains to tell" + (f" ({left[2:]})" if stopped else "")
    if any(isinstance(x, str) for x in by):  # categorical: no order to speak of, fastest first
        ranked = sorted(by, key=lambda x: float(np.mean(by[x])))
        values = ", ".join(f"{x} → {float(np.mean(by[x])):.3f} s" for x in ranked)
        return f"{address}, fastest first: {values} (mean of medians over the other parameters{left})"
    xs = sorted(by)
    means = [float(np.mean(by[x])) for x in xs]
    steps = np.sign(np.diff(means))
    shape = ("lowers" if np.all(steps < 0) else "raises" if np.all(steps > 0) else "does not move monotonically")
    values = ", ".join(f"{x:g} → {m:.3f} s" for x, m in zip(xs, means))
    return f"larger {address} {shape} the converged lap time ({values}; mean of medians over the other parameters{left})"
