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
"""

from __future__ import annotations

import copy
import ctypes
import logging
from typing import Callable, Mapping, Sequence

import mujoco
import mujoco.batch
import numpy as np

from mjcf.world import AXLE_SITE, LINE_SENSOR, MOTORS, START_KEY, PhysicsOptions
from twin.core import native as core
from twin.core.calibration import range_too_small, turn_too_long
from twin.model.control import CALIBRATE, IDLE, RUN, ControlParams, calibration_ticks
from twin.core.digital_twin import CENTRE_LINE, DigitalTwin, apply_fields
from twin.errors import TwinError
from twin.core.lap import LapJudge, LapLimits, LapResult
from twin.core.outcomes import Outcome
from twin.core.variant import Variant, field_key

log = logging.getLogger(__name__)

CHUNK_TICKS = 320  # control ticks per batch call at most (1.6 s at 5 ms): Python runs once per chunk, not per step
MIN_CHUNK_TICKS = 10  # near the finish, chunks shrink to what could still finish the lap, but not below this
SEED_SALT = 0x5DEECE66D  # mixes the user's seed into the C generator's state
SEED_MAX = 2**64 - 1  # the C generator's state is a uint64


def run_laps(
    twin: DigitalTwin,
    variants: Sequence[Mapping[str, float]] = ({},),
    seed: int | Sequence[int] = 0,
    limits: LapLimits = LapLimits(),
    nthread: int = 0,
    keep_traces: bool = True,
    on_chunk: Callable[[float, int], None] | None = None,
    reuse_calibration: bool = True,
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
    """
    if not variants:
        return []
    seeds = list(seed) if isinstance(seed, (list, tuple, range, np.ndarray)) else [seed] * len(variants)
    if len(seeds) != len(variants):
        raise TwinError(f"seeds: {len(seeds)} given for {len(variants)} laps")
    for s in seeds:
        check_seed(s)
    model = twin.model()
    laps = [Variant.of(twin, v) for v in variants]
    core.install_callback()
    fleet = Fleet(twin, model, _batch(twin, model, laps, nthread), laps, seeds,
                  [LapJudge(twin.track, limits, keep_traces) for _ in laps])
    _refuse_long_turns(fleet, limits)
    keys = [lap.calibration_key(s) for lap, s in zip(laps, seeds)]
    turns = twin.calibrations.of(twin.rebuilds) if reuse_calibration else {}
    failed = _calibrate(fleet, keys, turns)
    cal = _start_laps(fleet, keys, turns, failed, limits)
    _drive(fleet, twin.track.length_m, on_chunk)
    return [j.result(lap.params.count, *cal[i], lap.values) for i, (j, lap) in enumerate(zip(fleet.judges, laps))]


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
    """The laps' simulations in one batch: their userdata heads, their judges, stepping and draining them."""

    def __init__(self, twin: DigitalTwin, model: mujoco.MjModel, batch: mujoco.batch.Batch, laps: list[Variant],
                 seeds: list[int], judges: list[LapJudge]):
        self.twin, self.model, self.batch, self.laps, self.seeds, self.judges = twin, model, batch, laps, seeds, judges
        self.steps = [round(lap.params.dt_s / lap.physics.timestep) for lap in laps]  # physics steps per tick
        self.sims: list[core.Sim] = []
        self.consumed = np.zeros(len(laps), dtype=np.int64)  # records each judge has read

    def reset(self) -> None:
        """Every simulation on the start line with a fresh head, uncalibrated and in the calibration phase."""
        self.batch.reset(keyframe=np.full(len(self.laps), self.model.key(START_KEY).id), stage=mujoco.mjtStage.mjSTAGE_NONE)
        rows = self.batch.userdata  # (nsim, nuserdata), live view of the state rows
        self.sims = [setup(rows[i], self.model, self.twin, lap.params, lap.sensor, self.seeds[i], lap.physics)
                     for i, lap in enumerate(self.laps)]

    def step(self, ids: np.ndarray, nstep: int) -> None:
        """Step some simulations; a lap ends as ``diverged`` where MuJoCo raises or the state turns non-finite,
        and as ``refused`` where the C loop refused its userdata."""
        try:
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
        """Feed each running lap's judge the trace records written since the last drain."""
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
          physics: PhysicsOptions | None = None) -> core.Sim:
    """Write one simulation's userdata head: where to find things in the model, and what to run.

    ``physics``: the lap's own battery voltage (PWM duty 1 → this voltage) and timestep; default the model's,
    which are the twin's base values, not a batch variant's."""
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
    sim.seed = (int(seed) * SEED_SALT + 1) & SEED_MAX
    sim.rng = sim.seed
    core.lib.lf_calibrate_reset(ctypes.byref(sim.fw), int(sensor.timeout_us))
    start_phase(sim, CALIBRATE)
    return sim


def start_phase(sim: core.Sim, mode: int) -> None:
    """Begin calibration or the lap at simulated time 0 (the calibration and the RNG state carry over)."""
    core.lib.lf_reset(ctypes.byref(sim.fw), mode)
    sim.ticks = sim.records_written = 0
    sim.segment = -1  # the first tick searches the whole centre line
    sim.phase_start_time = sim.last_time = sim.energy_j = sim.offset_abs_sum_m = sim.offset_abs_max_m = 0.0


# --- the calibration turn
def _refuse_long_turns(fleet: Fleet, limits: LapLimits) -> None:
    """End, before any simulation, the laps whose turn would take longer than the limit (no wall time spent)."""
    for lap, judge in zip(fleet.laps, fleet.judges):
        if why := turn_too_long(lap.params, limits):
            judge.fail(Outcome.CALIBRATION, why, 0.0, 0.0)


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
        elif s.fw.mode != IDLE:
            raise TwinError(f"lap {i}: calibration did not finish in {(calibration_ticks(fleet.laps[i].params) + 2) * fleet.steps[i]} steps")
        else:
            turns[k] = (tuple(s.fw.cal_min[: s.nsensor]), tuple(s.fw.cal_max[: s.nsensor]), int(s.rng))
    fleet.reset()  # the turn moved them: back to the start
    return failed


def _start_laps(fleet: Fleet, keys: list[tuple], turns: dict, failed: dict, limits: LapLimits) -> list[tuple]:
    """Put each lap in the run phase with the calibration (min, max and noise generator state) its turn made;
    a lap whose turn failed or left a sensor with too small a range ends here. Returns (min, max) per lap."""
    cal = []
    for lap, sim, judge, k in zip(fleet.laps, fleet.sims, fleet.judges, keys):
        if k not in turns:
            if k in failed:
                code, detail, t, _, energy = failed[k]
                judge.fail(code, detail, t, energy)
            cal.append(([], []))
            continue
        lo, hi, rng = turns[k]
        for j, (a, b) in enumerate(zip(lo, hi)):
            sim.fw.cal_min[j], sim.fw.cal_max[j] = a, b
        sim.rng = rng
        cal.append((list(lo), list(hi)))
        if why := range_too_small(fleet.twin, lap.params, lap.sensor, lo, hi, limits):
            judge.fail(Outcome.CALIBRATION, why, 0.0, 0.0)
        start_phase(sim, RUN)
    return cal


# --- the lap
def _drive(fleet: Fleet, length_m: float, on_chunk: Callable[[float, int], None] | None) -> None:
    """Step the running laps chunk by chunk, judging each chunk, until every lap has ended."""
    # no lap can be faster than its wheels' no-load speed: step no further than that could finish it
    tick_m = [lap.params.wheel_speed_max * lap.params.wheel_radius_m * lap.physics.timestep * k
              for lap, k in zip(fleet.laps, fleet.steps)]
    while True:
        active = [i for i, j in enumerate(fleet.judges) if not j.done]
        if not active:
            return
        # laps with the same power-of-two chunk step together, so a lap near its end does not hold back the rest
        groups: dict[int, list[int]] = {}
        for i in active:
            ticks = chunk_ticks(length_m - (fleet.judges[i].u_last or 0.0), tick_m[i])
            groups.setdefault(ticks * fleet.steps[i], []).append(i)
        for nstep, ids in sorted(groups.items()):
            fleet.step(np.array(ids), nstep)
        fleet.drain(active)
        if on_chunk is not None:
            on_chunk(float(fleet.batch.time[active].max()), int(sum(not j.done for j in fleet.judges)))


def chunk_ticks(remaining_m: float, tick_m: float) -> int:
    """Control ticks to step a lap with ``remaining_m`` to go at most ``tick_m`` per tick: as many as could not
    finish it, rounded down to MIN_CHUNK_TICKS times a power of two, within [MIN_CHUNK_TICKS, CHUNK_TICKS]."""
    bound = remaining_m / tick_m + 1 if tick_m > 0 else float("inf")
    if not bound < CHUNK_TICKS:  # also inf and NaN (a wheel so small its step underflows): the longest chunk
        return CHUNK_TICKS
    return min(MIN_CHUNK_TICKS * 2 ** int(np.floor(np.log2(max(1.0, bound / MIN_CHUNK_TICKS)))), CHUNK_TICKS)
