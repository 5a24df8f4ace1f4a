"""Laps in closed loop: many simulations of one world stepped by ``mujoco.batch``, controlled from C.

Each simulation's userdata holds the firmware's parameters and state, the sensor model, its noise seed and
a ring of trace records (:mod:`twin.core.native`). The C callback runs sensors and firmware at every control tick;
Python only sets simulations up, moves them between phases and drains the trace rings every
``CHUNK_TICKS`` ticks to judge the laps (:mod:`twin.core.lap`). Simulations run in parallel on a thread pool,
and each one is bit-identical to running it alone: its state never mixes with another's.

Phases of a lap, as on the real robot: calibrate by turning in place over the start line (Eq. 8's min and
max), then be put back on the start line, and follow the line until the lap ends. Laps that differ only in
their gains calibrate identically, so each distinct calibration is simulated once per build of the twin and
reused (bit-identical to simulating it again). A turn longer than ``LapLimits.calibration_timeout_s`` is not
simulated at all: its laps fail at once.

Decided laps stop at once: the C loop judges every tick of a lap as Python does (``twin/csrc/sim/lap_judge.c``,
tested equal to :class:`twin.core.lap.LapJudge`) and, the tick a lap is decided, ends its ``mujoco.batch`` rollout
(it raises a warning counter, the batch's one per-simulation stop). The steps up to that tick are the same as
without stopping, so no decision, lap time or statistic changes; ``stop_decided=False`` steps every lap to the end
of its chunk instead, as before. A caller that needs a lap only while it could still matter stops it earlier:
past a simulated time (``deadline_s``, in C) or when it says so between chunks (``cut``); such a lap ends as
``stopped``, its ``simulated_s`` a lower bound of when it would have ended.
"""

from __future__ import annotations

import copy
import ctypes
import dataclasses
import logging
import math
from typing import Callable, Iterable, Mapping, Sequence

import mujoco
import mujoco.batch
import numpy as np

from mjcf.world import AXLE_SITE, LINE_SENSOR, MOTORS, START_KEY, PhysicsOptions
from twin.core import native as core
from twin.core.calibration import range_too_small, turn_too_long
from twin.model.control import CALIBRATE, IDLE, RUN, ControlParams, calibration_ticks
from twin.core.power_failure import does_not_start, shut_off
from twin.model.power import Power
from twin.model.timing import Timing
from twin.core.digital_twin import CENTRE_LINE, DigitalTwin, apply_fields
from twin.errors import TwinError
from twin.core.lap import CJudgeView, LapJudge, LapLimits, LapResult
from twin.core.maze import refuse_maze
from twin.core.outcomes import Outcome
from twin.core.variant import Variant, field_key

log = logging.getLogger(__name__)

CHUNK_TICKS = 320  # control ticks per batch call at most (1.6 s at 5 ms): Python runs once per chunk, not per step
# laps judged in C alone run longer calls, up to this many ticks over all their laps (a 64-lap chunk's worth, well
# under a second of CPU): one call for a few laps, and a Ctrl-C, heard between calls, still heard as soon as before
CALL_TICKS = 64 * CHUNK_TICKS
MIN_CHUNK_TICKS = 10  # near the finish, chunks shrink to what could still finish the lap, but not below this
SEED_SALT = 0x5DEECE66D  # mixes the user's seed into the C generator's state
SEED_MAX = 2**64 - 1  # the C generator's state is a uint64
MAX_LAPS = 20_000  # laps one command may ask for at most (a sweep's one batch, ~0.3 MB of state per lap; a learned graph)


def run_laps(
    twin: DigitalTwin,
    variants: Sequence[Mapping[str, float]] = ({},),
    seed: int | Sequence[int] = 0,
    limits: LapLimits = LapLimits(),
    nthread: int = 0,
    keep_traces: bool = True,
    on_chunk: Callable[[float, int], None] | None = None,
    reuse_calibration: bool = True,
    stop_decided: bool = True,
    deadline_s: Sequence[float] | None = None,
    cut: Callable[[list["Progress"]], Iterable[int]] | None = None,
) -> list[LapResult]:
    """Run one lap per variant, all at once, and return their results in order.

    Args:
      twin: the robot on its track; its current values are every lap's base. It is not changed.
      variants: per lap, addresses to change from the base (``control.*``, ``sensor.*`` other than count and
        pitch, ``motion.*``, ``motor.*``); the robot and track (``cad.*``, ``environment.*``) are shared.
      seed: noise seed in [0, 2**64 − 1]: one for every lap (common random numbers), or one per lap.
      limits: failure thresholds.
      nthread: threads of the batch, 0 for all cores. Results do not depend on it.
      keep_traces: keep each lap's per-tick trace (memory: ~400 B per tick per lap).
      on_chunk: called after each batch call with (simulated seconds of the slowest lap, laps still running).
      reuse_calibration: use a calibration turn this twin already simulated (bit-identical); False simulates
        every distinct turn again, e.g. to time it.
      stop_decided: stop each lap at the tick it is decided (the results are the same either way); False steps it
        to the end of its chunk.
      deadline_s: per lap, the simulated time [s] past which it ends as ``stopped`` if still undecided (inf: never).
      cut: called after every chunk with each lap's :class:`Progress`; the running laps whose indices it returns end
        as ``stopped``.
    """
    if not variants:
        return []
    seeds = list(seed) if isinstance(seed, (list, tuple, range, np.ndarray)) else [seed] * len(variants)
    if len(seeds) != len(variants):
        raise TwinError(f"seeds: {len(seeds)} given for {len(variants)} laps")
    deadlines = [math.inf] * len(variants) if deadline_s is None else [float(t) for t in deadline_s]
    if len(deadlines) != len(variants) or any(math.isnan(t) for t in deadlines):
        raise TwinError(f"deadline_s: one time per lap ({len(variants)}), not NaN")
    if not stop_decided and (deadline_s is not None or cut is not None):
        raise TwinError("deadline_s and cut stop laps early: they need stop_decided")
    for s in seeds:
        check_seed(s)
    model = twin.model()
    refuse_maze(twin.track, "the twin's controller")
    laps = [Variant.of(twin, v) for v in variants]
    core.install_callback()
    fleet = Fleet(twin, model, _batch(twin, model, laps, nthread), laps, seeds, limits, keep_traces, stop_decided)
    _refuse_long_turns(fleet, limits)
    _refuse_dead_supplies(fleet)
    keys = [lap.calibration_key(s) for lap, s in zip(laps, seeds)]
    turns = twin.calibrations.of(twin.rebuilds) if reuse_calibration else {}
    failed = _calibrate(fleet, keys, turns)
    fleet.cal = _start_laps(fleet, keys, turns, failed, limits, deadlines)
    _drive(fleet, twin.track.length_m, on_chunk, cut)
    return [fleet.result(i) for i in range(len(laps))]


@dataclasses.dataclass(frozen=True)
class Progress:
    """A lap between two chunks: its result once it has ended (else None), and the simulated time of its last tick
    [s]. Whatever it still does, a running lap ends after ``time_s``."""

    result: LapResult | None
    time_s: float


def check_seed(seed) -> None:
    """A noise seed must be a whole number in [0, 2**64 − 1]: larger ones would wrap onto smaller ones' noise."""
    if not isinstance(seed, (int, np.integer)) or not 0 <= seed <= SEED_MAX:
        raise TwinError(f"seed: must be a whole number in [0, 2**64 - 1], got {seed!r}")


def _batch(twin: DigitalTwin, model: mujoco.MjModel, laps: list[Variant], nthread: int) -> mujoco.batch.Batch:
    """The twin's batch, holding each lap's model fields (one model shared by laps whose fields agree)."""
    batch = twin.batches.get(twin.rebuilds, model, len(laps), nthread)
    base = field_key(twin, twin.space.values)
    if all(lap.field_key == base for lap in laps):
        # a Batch simulates a copy of the model it was made with: hand it the twin's model as it is now, so a
        # field the twin changed since (motion.mu, motor.*) is the one simulated
        batch.set_models(model)
        return batch
    models: dict[tuple, mujoco.MjModel] = {}
    for lap in laps:
        if lap.field_key not in models:
            models[lap.field_key] = copy.copy(model)
            apply_fields(models[lap.field_key], twin.info, lap.motor, lap.physics)
    batch.set_models([models[lap.field_key] for lap in laps])
    return batch


class Fleet:
    """The laps' simulations in one batch: their userdata heads, their judges, stepping and draining them. A lap the
    C judges (``stop_decided``) whose trace is not kept is judged in C alone (``c_only``): nothing to drain."""

    def __init__(self, twin: DigitalTwin, model: mujoco.MjModel, batch: mujoco.batch.Batch, laps: list[Variant],
                 seeds: list[int], limits: LapLimits, keep_traces: bool, stop_decided: bool):
        self.twin, self.model, self.batch, self.laps, self.seeds, self.limits = twin, model, batch, laps, seeds, limits
        self.stop_decided = stop_decided
        self.c_only = stop_decided and not keep_traces
        self.judges = [self.c_judge(i) if self.c_only else LapJudge(twin.track, limits, keep_traces)
                       for i in range(len(laps))]
        self.steps = [round(lap.params.dt_s / lap.physics.timestep) for lap in laps]  # physics steps per tick
        self.sims: list[core.Sim] = []
        self.consumed = np.zeros(len(laps), dtype=np.int64)  # records each judge has read
        self.cal: list[tuple] = [([], [])] * len(laps)  # each lap's calibration (min, max)
        self.results: dict[int, LapResult] = {}

    def c_judge(self, i: int) -> CJudgeView:
        """Lap i judged by the C loop alone, read from its current head and trace ring."""
        return CJudgeView(lambda: self.sims[i] if self.sims else None,
                          lambda k: core.records_view(self.batch.userdata[i])[k % self.sims[i].record_capacity],
                          self.limits, self.twin.track.length_m)

    def result(self, i: int) -> LapResult:
        """Lap i's result, once it has ended (made once); a lap whose regulator shut off ends as ``power``."""
        if i not in self.results:
            r = self.judges[i].result(self.laps[i].params.count, *self.cal[i], self.laps[i].values)
            if self.sims[i].power_off and not r.completed:
                r = dataclasses.replace(r, failure=Outcome.POWER.value,
                                        detail=f"{shut_off(self.laps[i].power, self.sims[i])}; then: {r.detail}")
            self.results[i] = r
        return self.results[i]

    def progress(self) -> list[Progress]:
        return [Progress(self.result(i) if j.done else None, j.prev[0]) for i, j in enumerate(self.judges)]

    def run(self, ids: np.ndarray, nstep: int) -> None:
        """Step running laps ``nstep`` steps. With stop_decided, a lap stops at the step the C judge decided it or it
        passed its deadline; a lap that one of MuJoCo's own warnings stopped (a rollout stops at any) is stepped on
        to the chunk's end, as a plain step would have."""
        if not self.stop_decided:
            return self.step(ids, nstep)
        t0 = self.batch.time[ids].copy()
        self.step(ids, nstep, rollout=True)
        rest: dict[int, list[int]] = {}
        for i, t in zip(ids, t0):
            done = round((float(self.batch.time[i]) - t) / self.laps[i].physics.timestep)
            if done < nstep and not self.sims[i].stop_raised and not self.judges[i].done:
                rest.setdefault(nstep - done, []).append(int(i))
        for n, left in sorted(rest.items()):
            self.step(np.array(left), n)

    def end_stopped(self, ids: list[int]) -> None:
        """After a drain: the laps the C stopped undecided (past their deadline) end as ``stopped``."""
        for i in ids:
            j, sim = self.judges[i], self.sims[i]
            if j.done or not sim.stop_raised:
                continue
            if sim.judge.status != 0:  # the C decided a lap that Python, fed the same records, did not
                raise TwinError(f"lap {i}: the C judge ended it ({sim.judge.status}) and Python's did not")
            self.stop(i, f"past its deadline of {sim.deadline_s:g} s")

    def stop(self, i: int, why: str) -> None:
        t, _, energy = self.judges[i].prev
        self.judges[i].fail(Outcome.STOPPED, f"stopped at {t:.3f} s, undecided: {why}", t, energy)

    def reset(self) -> None:
        """Every simulation on the start line with a fresh head, uncalibrated and in the calibration phase."""
        self.batch.reset(keyframe=np.full(len(self.laps), self.model.key(START_KEY).id), stage=mujoco.mjtStage.mjSTAGE_NONE)
        rows = self.batch.userdata  # (nsim, nuserdata), live view of the state rows
        self.sims = [setup(rows[i], self.model, self.twin, lap.params, lap.sensor, self.seeds[i], lap.physics,
                           lap.timing, lap.power)
                     for i, lap in enumerate(self.laps)]

    def step(self, ids: np.ndarray, nstep: int, rollout: bool = False) -> None:
        """Step some simulations (as a rollout: each stops where its warning counters rise); a lap ends as
        ``diverged`` where MuJoCo raises or the state turns non-finite, and as ``refused`` where the C loop refused
        its userdata."""
        try:
            if rollout:
                self.batch.rollout(nstep, record=(), ids=ids)
            else:
                self.batch.step(ids=ids, nstep=nstep)
        except mujoco.batch.SimulationError as e:
            for i in e.ids:
                self._fail(int(i), Outcome.DIVERGED, f"MuJoCo: {self.batch.error(int(i))}")
        finally:
            core.flush_mujoco_log()
        for i in ids:
            why = core.refusal(self.sims[i])
            if why:
                self._fail(int(i), Outcome.REFUSED, why)
        for i in ids[~np.isfinite(self.batch.qpos[ids]).all(axis=1)]:
            self._fail(int(i), Outcome.DIVERGED, "the physics produced a non-finite state")

    def _fail(self, i: int, code: Outcome, detail: str) -> None:
        self.judges[i].fail(code, detail, float(self.batch.time[i]), 0.0)

    def drain(self, ids: list[int]) -> None:
        """Feed each running lap's judge the trace records written since the last drain (none to feed when the C
        judges alone)."""
        if self.c_only:
            return
        rows = self.batch.userdata
        for i in ids:
            if self.judges[i].done:
                continue
            try:
                records = core.records_since(rows[i], self.sims[i], int(self.consumed[i]))
            except TwinError as e:
                raise TwinError(f"lap {i}: {e}") from None
            self.judges[i].feed(records)
            self.consumed[i] = self.sims[i].records_written


def setup(row: np.ndarray, model: mujoco.MjModel, twin: DigitalTwin, params: ControlParams, sensor, seed: int,
          physics: PhysicsOptions | None = None, timing: Timing | None = None, power: Power | None = None) -> core.Sim:
    """Write one simulation's userdata head: where to find things in the model, and what to run.

    ``physics``: the lap's own battery voltage (PWM duty 1 → this voltage) and timestep; default the model's,
    which are the twin's base values, not a batch variant's. ``timing``: the robot's reaction, ``power``: the motors'
    supply (default the twin's)."""
    row[:] = 0.0
    sim = core.sim_view(row)
    sim.magic, sim.layout_version, sim.nsensor = core.MAGIC, core.LAYOUT_VERSION, params.count
    sim.model_signature[:] = core.model_signature(model)
    for i in range(params.count):
        sim.sensor_site[i] = model.site(LINE_SENSOR.format(i)).id
    sim.sensor_body = model.body(twin.info.sensor_body).id
    sim.texture_id = model.texture("track").id
    sim.actuator_left, sim.actuator_right = (model.actuator(n).id for n in MOTORS)
    sim.dof_left, sim.dof_right = (model.jnt_dofadr[model.joint(j).id] for j in twin.info.wheel_joints)
    sim.axle_site = model.site(AXLE_SITE).id
    sim.root_body = model.body(twin.info.root_body).id
    sim.record_capacity = (model.nuserdata - core.SIM_WORDS) // core.RECORD_WORDS
    centre = model.numeric(CENTRE_LINE)
    sim.centre_adr, sim.centre_count = int(model.numeric_adr[centre.id]), (int(model.numeric_size[centre.id]) - 1) // 3
    sim.texture_origin_x, sim.texture_origin_y = twin.texture.origin_xy
    sim.texture_metres_per_pixel = twin.texture.metres_per_pixel
    physics = physics or twin.physics()
    sim.supply_voltage = physics.supply_voltage
    sim.timestep = physics.timestep
    sim.sensor = core.sensor_to_c(sensor)
    sim.firmware = core.params_to_c(params)
    sim.timing = core.timing_to_c(timing or twin.timing())
    power = power or twin.power()
    sim.power = core.power_to_c(power)
    sim.terminal_min_v, sim.power_off = power.battery_v, 0
    sim.seed = (int(seed) * SEED_SALT + 1) & SEED_MAX
    core.lib.lf_calibrate_reset(ctypes.byref(sim.fw), int(sensor.timeout_us))
    start_phase(sim, CALIBRATE)
    return sim


def start_phase(sim: core.Sim, mode: int) -> None:
    """Begin calibration or the lap at simulated time 0 (the calibration carries over); the phase's readings draw
    their noise from a base of the seed and the phase alone (lf_noise_base), as the processor in the loop's do."""
    core.lib.lf_reset(ctypes.byref(sim.fw), mode)
    sim.rng, sim.reads = core.lib.lf_noise_base(sim.seed, mode), 0
    sim.duty_now[:] = sim.duty_next[:] = (0.0, 0.0)  # the motors braked, as the keyframe's controls
    sim.pending = 0
    sim.ticks = sim.records_written = 0
    sim.segment = -1  # the first tick searches the whole centre line
    sim.phase_start_time = sim.last_time = sim.energy_j = sim.offset_abs_sum_m = sim.offset_abs_max_m = 0.0


# --- the calibration turn
def _refuse_long_turns(fleet: Fleet, limits: LapLimits) -> None:
    """End, before any simulation, the laps whose turn would take longer than the limit (no wall time spent)."""
    for lap, judge in zip(fleet.laps, fleet.judges):
        if why := turn_too_long(lap.params, limits):
            judge.fail(Outcome.CALIBRATION, why, 0.0, 0.0)


def _refuse_dead_supplies(fleet: Fleet) -> None:
    """End, before any simulation, the laps whose regulator would not start on their battery."""
    for lap, judge in zip(fleet.laps, fleet.judges):
        if why := does_not_start(lap.power):
            judge.fail(Outcome.POWER, why, 0.0, 0.0)


def _calibrate(fleet: Fleet, keys: list[tuple], turns: dict) -> dict[tuple, tuple]:
    """Simulate each distinct turn not in ``turns`` once, add what it calibrated to ``turns``, and leave every
    simulation on the start line. Returns {key: failure outcome} of the turns that failed."""
    todo: dict[tuple, int] = {}  # key: the lap that turns for all laps with that key
    for i, k in enumerate(keys):
        if k not in turns and k not in todo and not fleet.judges[i].done:
            todo[k] = i
    fleet.reset()
    if not todo:
        return {}
    # each turn steps exactly its own length: a longer one in the batch must not give it extra idle ticks, whose
    # sensor reads would draw noise and make its lap depend on the laps it shares a batch with
    groups: dict[int, list[int]] = {}
    for i in sorted(todo.values()):
        groups.setdefault((calibration_ticks(fleet.laps[i].params) + 2) * fleet.steps[i], []).append(i)
    for nstep, ids in sorted(groups.items()):
        fleet.step(np.array(ids), nstep)
    failed = {}
    for k, i in todo.items():
        s = fleet.sims[i]
        if fleet.judges[i].done:
            failed[k] = fleet.judges[i].outcome  # not kept: every lap with this turn fails alike
        elif s.power_off:
            failed[k] = (Outcome.POWER, f"{shut_off(fleet.laps[i].power, s)} during the calibration turn",
                         float(fleet.batch.time[i]), 0.0, 0.0)
        elif s.fw.mode != IDLE:
            raise TwinError(f"lap {i}: calibration did not finish in {(calibration_ticks(fleet.laps[i].params) + 2) * fleet.steps[i]} steps")
        else:
            turns[k] = (tuple(s.fw.cal_min[: s.nsensor]), tuple(s.fw.cal_max[: s.nsensor]))
    fleet.reset()  # the turn moved them: back to the start
    return failed


def _start_laps(fleet: Fleet, keys: list[tuple], turns: dict, failed: dict, limits: LapLimits,
                deadlines: list[float]) -> list[tuple]:
    """Put each lap in the run phase with the calibration (min, max) its turn made,
    judged in C if decided laps stop; a lap whose turn failed or left a sensor with too small a range ends here.
    Returns (min, max) per lap."""
    cal = []
    for lap, sim, judge, k, deadline in zip(fleet.laps, fleet.sims, fleet.judges, keys, deadlines):
        if k not in turns:
            if k in failed:
                code, detail, t, _, energy = failed[k]
                judge.fail(code, detail, t, energy)
            cal.append(([], []))
            continue
        lo, hi = turns[k]
        for j, (a, b) in enumerate(zip(lo, hi)):
            sim.fw.cal_min[j], sim.fw.cal_max[j] = a, b
        cal.append((list(lo), list(hi)))
        if why := range_too_small(fleet.twin, lap.params, lap.sensor, lo, hi, limits):
            judge.fail(Outcome.CALIBRATION, why, 0.0, 0.0)
        start_phase(sim, RUN)
        if fleet.stop_decided:
            start_judge(sim, fleet.twin.track.length_m, limits, deadline)
    return cal


def start_judge(sim: core.Sim, length_m: float, limits: LapLimits, deadline_s: float = math.inf) -> None:
    """Judge the phase in C too, so that the simulation stops the tick it is decided or passes ``deadline_s``."""
    c = core.LapLimitsC.of(limits)
    core.lib.lf_judge_start(ctypes.byref(sim.judge), length_m, ctypes.byref(c))
    sim.deadline_s = deadline_s
    sim.stop_raised = 0
    sim.judge_on = 1


# --- the lap
def _drive(fleet: Fleet, length_m: float, on_chunk: Callable[[float, int], None] | None,
           cut: Callable[[list[Progress]], Iterable[int]] | None = None) -> None:
    """Step the running laps chunk by chunk, judging each chunk, until every lap has ended. Laps judged in C alone,
    with no caller to hear between chunks (``on_chunk``, ``cut``), run in longer calls (``CALL_TICKS`` shared by the
    laps): a few laps run to their end in one call, the tick they are decided or at the latest the one past the
    timeout."""
    whole = fleet.c_only and on_chunk is None and cut is None
    # no lap can be faster than its wheels' no-load speed: step no further than that could finish it (needed only
    # when laps do not stop themselves once decided)
    tick_m = [lap.params.wheel_speed_max * lap.params.wheel_radius_m * lap.physics.timestep * k
              for lap, k in zip(fleet.laps, fleet.steps)]
    while True:
        active = [i for i, j in enumerate(fleet.judges) if not j.done]
        if not active:
            return
        # laps with the same chunk step together, so a lap near its end does not hold back the rest
        groups: dict[int, list[int]] = {}
        for i in active:
            if whole:  # the ticks left until the first one past the timeout, within the call's share
                left = math.ceil(fleet.limits.timeout_s / fleet.laps[i].params.dt_s) + 2 - fleet.sims[i].ticks
                ticks = max(CHUNK_TICKS, min(left, CALL_TICKS // len(active)))
            elif fleet.stop_decided:
                ticks = CHUNK_TICKS
            else:
                ticks = chunk_ticks(length_m - (fleet.judges[i].u_last or 0.0), tick_m[i])
            groups.setdefault(ticks * fleet.steps[i], []).append(i)
        for nstep, ids in sorted(groups.items()):
            fleet.run(np.array(ids), nstep)
        fleet.drain(active)
        fleet.end_stopped(active)
        if cut is not None:
            for i in sorted(set(int(i) for i in cut(fleet.progress()))):
                if not fleet.judges[i].done:
                    fleet.stop(i, "its caller no longer needs it")
        if on_chunk is not None:
            on_chunk(float(fleet.batch.time[active].max()), int(sum(not j.done for j in fleet.judges)))


def chunk_ticks(remaining_m: float, tick_m: float) -> int:
    """Control ticks to step a lap with ``remaining_m`` to go at most ``tick_m`` per tick: as many as could not
    finish it, rounded down to MIN_CHUNK_TICKS times a power of two, within [MIN_CHUNK_TICKS, CHUNK_TICKS]."""
    bound = remaining_m / tick_m + 1 if tick_m > 0 else float("inf")
    if not bound < CHUNK_TICKS:  # also inf and NaN (a wheel so small its step underflows): the longest chunk
        return CHUNK_TICKS
    return min(MIN_CHUNK_TICKS * 2 ** int(np.floor(np.log2(max(1.0, bound / MIN_CHUNK_TICKS)))), CHUNK_TICKS)
