"""Laps in closed loop: many simulations of one world stepped by ``mujoco.batch``, controlled from C.

Each simulation's userdata holds the firmware's parameters and state, the sensor model, its noise seed and
a ring of trace records (:mod:`twin.core`). The C callback runs sensors and firmware at every control tick;
Python only sets simulations up, moves them between phases and drains the trace rings every
``CHUNK_TICKS`` ticks to judge the laps (:mod:`twin.lap`). Simulations run in parallel on a thread pool,
and each one is bit-identical to running it alone: its state never mixes with another's.

Phases of a lap, as on the real robot: calibrate by turning in place over the start line (Eq. 8's min and
max), then be put back on the start line, and follow the line until the lap ends. Laps that differ only in
their gains calibrate identically, so each distinct calibration is simulated once per build of the twin and
reused (bit-identical to simulating it again).
"""

from __future__ import annotations

import copy
import ctypes
import dataclasses
import logging
from typing import Callable, Mapping, Sequence

import mujoco
import mujoco.batch
import numpy as np

from mjcf.world import AXLE_SITE, LINE_SENSOR, MOTORS, START_KEY
from twin import core
from twin.controller import CALIBRATE, IDLE, RUN, ControlParams, calibration_ticks
from twin.digital_twin import CENTRE_LINE, DigitalTwin, apply_fields
from twin.errors import TwinError
from twin.lap import CALIBRATION, DIVERGED, LapJudge, LapLimits, LapResult
from twin.model_space import ChangeCost

log = logging.getLogger(__name__)

CHUNK_TICKS = 320  # control ticks per batch call at most (1.6 s at 5 ms): Python runs once per chunk, not per step
MIN_CHUNK_TICKS = 10  # near the finish, chunks shrink to what could still finish the lap, but not below this
SEED_SALT = 0x5DEECE66D  # mixes the user's seed into the C generator's state


def _setup(row: np.ndarray, model: mujoco.MjModel, twin: DigitalTwin, params: ControlParams, sensor, seed: int) -> core.Sim:
    """Write one simulation's userdata head: where to find things in the model, and what to run."""
    row[:] = 0.0
    sim = core.sim_view(row)
    sim.magic, sim.layout_version, sim.nsensor = core.MAGIC, core.LAYOUT_VERSION, params.count
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
    sim.supply_voltage = float(model.actuator_ctrlrange[sim.actuator_left, 1])
    sim.timestep = model.opt.timestep
    sim.sensor = core.sensor_to_c(sensor)
    sim.firmware = core.params_to_c(params)
    sim.seed = (int(seed) * SEED_SALT + 1) & (2**64 - 1)
    sim.rng = sim.seed
    core.lib.lf_calibrate_reset(ctypes.byref(sim.fw), int(sensor.timeout_us))
    _start_phase(sim, CALIBRATE)
    return sim


def _start_phase(sim: core.Sim, mode: int) -> None:
    """Begin calibration or the lap at simulated time 0 (the calibration and the RNG state carry over)."""
    core.lib.lf_reset(ctypes.byref(sim.fw), mode)
    sim.ticks = sim.records_written = 0
    sim.segment = -1  # the first tick searches the whole centre line
    sim.phase_start_time = sim.last_time = sim.energy_j = sim.offset_abs_sum_m = sim.offset_abs_max_m = 0.0


class Variant:
    """One lap's parameters: the twin's values with some addresses changed (controller or model fields)."""

    def __init__(self, twin: DigitalTwin, changes: Mapping[str, float]):
        base = dict(twin.space.values)
        try:
            for address, value in changes.items():
                if twin.set(address, value) is ChangeCost.REBUILD and twin.space.values[address] != base[address]:
                    raise TwinError(
                        f"{address}: rebuilds the robot or track, so it cannot vary between the laps of one batch"
                    )
            self.values = dict(twin.space.values)
            self.params = twin.control_params()
            self.sensor = twin.sensor_model()
            self.motor, self.physics = twin.motor(), twin.physics()
            self.field_key = tuple(
                v for a, v in self.values.items() if twin.space.parameter(a).cost is ChangeCost.MODEL_FIELD
            )
        finally:
            twin.space.values.update(base)
            twin.model()  # puts the base values back into the shared model's fields


def run_laps(
    twin: DigitalTwin,
    variants: Sequence[Mapping[str, float]] = ({},),
    seed: int = 0,
    limits: LapLimits = LapLimits(),
    nthread: int = 0,
    keep_traces: bool = True,
    on_chunk: Callable[[float, int], None] | None = None,
    reuse_calibration: bool = True,
) -> list[LapResult]:
    """Run one lap per variant, all at once, and return their results in order.

    Args:
      twin: the robot on its track; its current values are every lap's base.
      variants: per lap, addresses to change from the base (``control.*``, ``sensor.*`` other than count and
        pitch, ``motion.*``, ``motor.*``); the robot and track (``cad.*``, ``environment.*``) are shared.
      seed: noise seed; every lap gets the same noise stream (common random numbers).
      limits: failure thresholds.
      nthread: threads of the batch, 0 for all cores. Results do not depend on it.
      keep_traces: keep each lap's per-tick trace (memory: ~400 B per tick per lap).
      on_chunk: called after each batch call with (simulated seconds of the slowest lap, laps still running).
      reuse_calibration: use a calibration turn this twin already simulated (bit-identical); False simulates
        every distinct turn again, e.g. to time it.
    """
    if not variants:
        return []
    if not isinstance(seed, (int, np.integer)) or seed < 0:
        raise TwinError(f"seed: must be a whole number >= 0, got {seed!r}")
    model = twin.model()
    base_key = Variant(twin, {}).field_key
    laps = [Variant(twin, v) for v in variants]
    nsim = len(laps)
    batch = _batch(twin, model, nsim, nthread)
    if any(lap.field_key != base_key for lap in laps):
        models: dict[tuple, mujoco.MjModel] = {}
        for lap in laps:
            if lap.field_key not in models:
                m = copy.copy(model)
                apply_fields(m, twin.info, lap.motor, lap.physics)
                models[lap.field_key] = m
        batch.set_models([models[lap.field_key] for lap in laps])
    else:
        # a Batch simulates a copy of the model it was made with: hand it the twin's model as it is now, so a
        # field the twin changed since (motion.mu, motor.*) is the one simulated
        batch.set_models(model)
    core.install_callback()
    key = np.full(nsim, model.key(START_KEY).id)
    judges = [LapJudge(twin.track, limits, keep_traces) for _ in laps]

    # --- calibration: turn in place over the start line. Laps that differ only in gains calibrate identically
    # (the turn does not use them), so each distinct calibration runs once and is kept on the twin.
    done = _calibrations(twin) if reuse_calibration else {}
    cal_keys = [_calibration_key(lap, seed) for lap in laps]
    steps = [round(lap.params.dt_s / lap.physics.timestep) for lap in laps]
    batch.reset(keyframe=key, stage=mujoco.mjtStage.mjSTAGE_NONE)
    userdata = batch.userdata  # (nsim, nuserdata), live view of the state rows
    sims = [_setup(userdata[i], model, twin, lap.params, lap.sensor, seed) for i, lap in enumerate(laps)]
    todo: dict[tuple, int] = {}
    for i, k in enumerate(cal_keys):
        if k not in done and k not in todo:
            todo[k] = i
    if todo:
        ids = np.array(sorted(todo.values()))
        cal_steps = max((calibration_ticks(laps[i].params) + 2) * steps[i] for i in ids)
        failed = _step(batch, ids, cal_steps, judges)
        for k, i in todo.items():
            s = sims[i]
            if i in failed:
                continue  # not kept: every lap with this calibration fails below
            if s.fw.mode != IDLE:
                raise TwinError(f"lap {i}: calibration did not finish in {cal_steps} steps")
            done[k] = (tuple(s.fw.cal_min[: s.nsensor]), tuple(s.fw.cal_max[: s.nsensor]), int(s.rng))
        batch.reset(keyframe=key, stage=mujoco.mjtStage.mjSTAGE_NONE)  # the turn moved them: back to the start
        sims = [_setup(userdata[i], model, twin, lap.params, lap.sensor, seed) for i, lap in enumerate(laps)]

    # --- the lap: on the start line, with the calibration (min, max and the noise generator's state) it made
    cal = []
    for i, (sim, lap) in enumerate(zip(sims, laps)):
        if cal_keys[i] not in done:
            judges[i].fail(DIVERGED, "the calibration turn diverged", 0.0, 0.0)
            cal.append(([], []))
            continue
        lo, hi, rng = done[cal_keys[i]]
        for j, (a, b) in enumerate(zip(lo, hi)):
            sim.fw.cal_min[j], sim.fw.cal_max[j] = a, b
        sim.rng = rng
        cal.append((list(lo), list(hi)))
        spans = np.array(hi) - np.array(lo)
        if np.min(spans) < limits.min_calibration_range_us:
            bad = int(np.argmin(spans))
            judges[i].fail(CALIBRATION, f"sensor {bad} spans only {spans[bad]} µs after the calibration turn "
                           "(turn further: control.cal_sweep, control.cal_duty)", 0.0, 0.0)
        _start_phase(sim, RUN)
    consumed = np.zeros(nsim, dtype=np.int64)
    capacity = sims[0].record_capacity
    # no lap can be faster than its wheels' no-load speed: step no further than that could finish it
    top_step_m = [lap.params.wheel_speed_max * lap.params.wheel_radius_m * lap.physics.timestep for lap in laps]
    while True:
        active = [i for i, j in enumerate(judges) if not j.done]
        if not active:
            break
        # each lap steps as far as could still not finish it (at least MIN_CHUNK_TICKS, at most CHUNK_TICKS);
        # laps with the same power-of-two chunk step together, so a lap near its end does not hold back the rest
        groups: dict[int, list[int]] = {}
        for i in active:
            ticks = (twin.track.length_m - (judges[i].u_last or 0.0)) / (top_step_m[i] * steps[i]) + 1
            ticks = MIN_CHUNK_TICKS * 2 ** int(np.floor(np.log2(max(1.0, ticks / MIN_CHUNK_TICKS))))
            groups.setdefault(min(ticks, CHUNK_TICKS) * steps[i], []).append(i)
        for nstep, ids in sorted(groups.items()):
            _step(batch, np.array(ids), nstep, judges)
        for i in active:
            written = sims[i].records_written
            n = written - consumed[i]
            if n > capacity:
                raise TwinError(f"lap {i}: trace ring overflowed ({n} records for {capacity} slots)")
            judges[i].feed(core.records_view(userdata[i])[np.arange(consumed[i], written) % capacity])
            consumed[i] = written
        if on_chunk is not None:
            on_chunk(float(batch.time[active].max()), int(sum(not j.done for j in judges)))
    return [j.result(lap.params.count, *cal[i], lap.values) for i, (j, lap) in enumerate(zip(judges, laps))]


def _calibration_key(lap: "Variant", seed: int) -> tuple:
    """Everything the calibration turn depends on: physics fields, sensor model, geometry and turn settings,
    the seed. Not the gains: the turn does not use them."""
    turn = dataclasses.replace(lap.params, v_max=0.0, k_b=0.0, k_p=0.0, k_i=0.0, k_d=0.0, accel_max=0.0,
                               integral_limit=0.0)
    return lap.field_key, dataclasses.astuple(lap.sensor), turn, int(seed)


def _calibrations(twin: DigitalTwin) -> dict:
    """Calibrations made on the twin's current build: {key: (min, max, RNG state after the turn)}."""
    store = twin.__dict__.setdefault("_calibrations", {"build": None, "done": {}})
    if store["build"] != twin.rebuilds:  # a rebuilt robot or track calibrates anew
        store["build"], store["done"] = twin.rebuilds, {}
    return store["done"]


def _batch(twin: DigitalTwin, model: mujoco.MjModel, nsim: int, nthread: int) -> mujoco.batch.Batch:
    """A batch for this model and size, made once per twin: making one costs ~10 ms, a lap ~200 ms."""
    cache = twin.__dict__.setdefault("_batches", {})
    key = (twin.rebuilds, nsim, nthread)  # the build count, not id(model): ids are reused after a rebuild
    if key not in cache:
        cache.clear()  # a rebuilt model makes the old batches useless
        cache[key] = (model, mujoco.batch.Batch(model, nsim=nsim, nthread=nthread))
    return cache[key][1]


def _step(batch: mujoco.batch.Batch, ids: np.ndarray, nstep: int, judges: list[LapJudge]) -> set[int]:
    """Step some simulations; those where MuJoCo raises or the state turns non-finite end as ``diverged``."""
    failed: set[int] = set()
    try:
        batch.step(ids=ids, nstep=nstep)
    except mujoco.batch.SimulationError as e:
        for i in e.ids:
            failed.add(int(i))
            judges[int(i)].fail(DIVERGED, f"MuJoCo: {batch.error(int(i))}", float(batch.time[int(i)]), 0.0)
    bad = ids[~np.isfinite(batch.qpos[ids]).all(axis=1)]
    for i in bad:
        failed.add(int(i))
        judges[int(i)].fail(DIVERGED, "the physics produced a non-finite state", float(batch.time[int(i)]), 0.0)
    return failed
