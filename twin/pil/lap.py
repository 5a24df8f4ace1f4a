"""Processor in the loop: a lap driven by the robot's firmware binary on an emulated ATmega328P (:mod:`twin.pil.mcu`).

The lap runs as on the robot: power-up, the firmware's calibration turn over the start line, the robot put back on
the start line, button B pressed, line following. It is judged as every lap is (:class:`twin.core.lap.LapJudge`), from
a trace the glue writes at each tick the firmware finishes, out of the firmware's own RAM. On top of a lap's
result it reports the MCU's figures (:class:`McuReport`) and the UART's telemetry lines.

A firmware that stops (the MCU halts or crashes), stops ticking, never releases a sensor line or never writes
its motors' PWM for ``stall_s`` of simulated time ends its lap as ``firmware_stalled``: a result, not a hang.
"""

from __future__ import annotations

import dataclasses
from typing import Callable

import mujoco
import numpy as np

from mjcf.world import START_KEY
from twin.pil import firmware as fw
from twin.core import native as core
from twin.core.calibration import range_too_small, turn_too_long
from twin.core.closed_loop import check_seed, setup
from twin.model.control import CALIBRATE, IDLE, RUN
from twin.model.timing import COMPUTE_PATHS
from twin.core.digital_twin import DigitalTwin
from twin.core.lap import LapJudge, LapLimits, LapResult
from twin.core.maze import refuse_maze
from twin.core.outcomes import Outcome, Status, outcome_of
from twin.errors import TwinError
from twin.pil.mcu import Mcu, state_size
from twin.core.variant import Variant
from twin.telemetry.wire import LineSplitter, WireError, decode

BOARD_SENSORS = 5  # LF_BOARD_SENSORS: the 3pi's own sensor lines, PC0..PC4
BUTTON_B = 2  # lf_avr_buttons: A 1, B 2, C 4
TRIMMER_V = 2.5  # the user trimmer on ADC7, at mid travel [V]
PIL_MAGIC = core.MAGIC + 1.0  # the C callback acts on core.MAGIC only: this head is the glue's
CHUNK_S = 0.1  # simulated seconds per call into the glue: Python judges the lap and drains the UART this often
TELEMETRY_EVERY = 2  # one sample line every 2 ticks, as the emulator's default


@dataclasses.dataclass(frozen=True)
class McuReport:
    """What the firmware cost the MCU, and how well it timed its sensors. Cycles at ``f_cpu_hz``; busy = awake (not
    in SLEEP), per control tick of the lap (calibration excluded); headroom = 1 − max busy / period."""

    mcu: str
    board: str
    f_cpu_hz: int
    elf: str
    flash_bytes: int
    flash_total_bytes: int
    ram_bytes: int
    ram_total_bytes: int
    period_cycles: int
    busy_cycles_max: int
    busy_cycles_mean: float
    headroom: float
    ticks: int
    overruns: int
    read_error_max_us: float  # |sensor reading the MCU timed − the physics' decay time|, lines that fell in time
    read_error_mean_us: float  # signed mean of the same: the timing's bias
    release_mean_us: float  # the tick to the sensor lines' release (the readings' instant), mean over timed ticks
    release_max_us: float
    compute_mean_us: float  # the read's end (the last line's fall or the timeout) to the first PWM write
    compute_min_us: float
    compute_max_us: float
    timed_ticks: int  # ticks whose reaction was timed (twin/csrc/pil/avr_timing.c)
    compute_path_mean_us: dict  # compute's mean per code path that was timed (twin.model.timing.COMPUTE_PATHS)
    compute_path_ticks: dict  # timed ticks per code path
    telemetry_lines: int
    telemetry_bad_lines: int
    telemetry_dropped_lines: int
    uart_bytes_lost: int

    def summary(self) -> dict:
        return dataclasses.asdict(self)


def stall_limit_s(dt_s: float) -> float:
    """The watchdog's window: ten control periods, at least 0.1 s."""
    return max(0.1, 10 * dt_s)


def runnable_firmware(twin: DigitalTwin, elf_path: str | None = None) -> fw.ElfInfo:
    """The ELF (default: built from twin/csrc/firmware/avr), checked against the twin's parameters, the board and
    the simavr glue; TwinError naming the problem otherwise."""
    fw.check_config(twin.control_params(), twin.sensor_model().timeout_us)
    elf = fw.check_elf(elf_path or fw.build("robot"), need=fw.TRACE_SYMBOLS)
    if elf.sizes["fw_state"] != state_size():  # state_size() loads the glue: a missing simavr is said here
        raise TwinError(f"{elf.path}: its fw_state is {elf.sizes['fw_state']} bytes, the twin reads {state_size()}: it was "
                        "built from another version of line_follower.h")
    return elf


def run_pil_lap(twin: DigitalTwin, elf_path: str | None = None, seed: int = 0, limits: LapLimits = LapLimits(),
                keep_trace: bool = True, on_line: Callable[[float, str], None] | None = None,
                telemetry_every: int = TELEMETRY_EVERY) -> tuple[LapResult, McuReport]:
    """Run one lap with the firmware ELF (default: built from twin/csrc/firmware/avr) on the MCU.

    ``on_line(t, line)`` receives each telemetry line the UART sent, with the simulated time [s] of the chunk it
    came in (lap time from the button press; calibration lines have negative times); the firmware sends a sample
    line every ``telemetry_every`` ticks."""
    check_seed(seed)
    lap = Variant.of(twin, {})
    params, sensor = lap.params, lap.sensor
    elf = runnable_firmware(twin, elf_path)
    model = twin.model()
    refuse_maze(twin.track, "the twin's own firmware")
    data = mujoco.MjData(model)
    judge = LapJudge(twin.track, limits, keep_trace)
    telemetry = Telemetry(on_line)
    with Mcu(elf) as mcu:
        mcu.eeprom(fw.config_image(params, sensor.timeout_us, telemetry_every))
        # more than the board's five sensors take the LCD's control lines: the LCD is unplugged (board_3pi.h)
        mcu.board(params.count <= BOARD_SENSORS, lap.power.battery_v, TRIMMER_V, 0)
        sim = place_robot(model, data, twin, lap, seed)
        mcu.attach(model, data, sim, stall_limit_s(params.dt_s))
        steps = max(1, round(CHUNK_S / model.opt.timestep))
        cal_min, cal_max, overruns_before = [], [], 0
        if why := turn_too_long(params, limits):
            judge.fail(Outcome.CALIBRATION, why, 0.0, 0.0)
        else:
            _calibrate(mcu, data, sim, judge, telemetry, steps, limits)
        if not judge.done:
            state = mcu.state()
            cal_min, cal_max = list(state.cal_min[: params.count]), list(state.cal_max[: params.count])
            if why := range_too_small(twin, params, sensor, cal_min, cal_max, limits):
                judge.fail(Outcome.CALIBRATION, why, 0.0, 0.0)
        if not judge.done:
            sim = place_robot(model, data, twin, lap, seed)  # put back on the start line: MuJoCo's time 0
            sim.rng = core.lib.lf_noise_base(sim.seed, RUN)  # the lap's readings draw the noise the C loop's do
            mcu.attach(model, data, sim, stall_limit_s(params.dt_s))
            mcu.zero_time_at_tick(params.dt_s, BUTTON_B)  # the lap begins with a tick, as the C loop's does
            mcu.reset_stats()
            overruns_before = int.from_bytes(mcu.peek("fw_overruns", 2), "little")  # the turn's ten-read ticks overrun
            telemetry.offset = 0.0
            _drive(mcu, data, sim, judge, telemetry, steps)
        status = mcu.status()
        overruns = (int.from_bytes(mcu.peek("fw_overruns", 2), "little") - overruns_before) % 65536
        dropped = int.from_bytes(mcu.peek("uart_dropped", 2), "little") if "uart_dropped" in elf.symbols else 0
    return judge.result(params.count, cal_min, cal_max, lap.values), _report(elf, params.dt_s, status, overruns, dropped,
                                                                           telemetry)


def _report(elf: fw.ElfInfo, dt_s: float, status, overruns: int, dropped: int, telemetry: "Telemetry") -> McuReport:
    period = round(dt_s * fw.F_CPU_HZ)
    return McuReport(
        mcu=fw.MCU, board=fw.BOARD, f_cpu_hz=fw.F_CPU_HZ, elf=elf.path, flash_bytes=elf.flash_bytes,
        flash_total_bytes=fw.FLASH_BYTES, ram_bytes=elf.ram_bytes, ram_total_bytes=fw.RAM_BYTES, period_cycles=period,
        busy_cycles_max=int(status.busy_max),
        busy_cycles_mean=float(status.busy_sum / status.busy_ticks) if status.busy_ticks else 0.0,
        headroom=1.0 - int(status.busy_max) / period, ticks=int(status.busy_ticks), overruns=overruns,
        read_error_max_us=float(status.read_error_max_us),
        read_error_mean_us=float(status.read_error_sum_us / status.read_errors) if status.read_errors else 0.0,
        **_reaction_us(status),
        telemetry_lines=telemetry.lines, telemetry_bad_lines=telemetry.bad, telemetry_dropped_lines=dropped,
        uart_bytes_lost=int(status.uart_lost),
    )


def _reaction_us(status) -> dict[str, float | int]:
    """The firmware's reaction times [µs] from the glue's cycle counts (0 where no tick was timed)."""
    n = int(status.timed_ticks)
    us = 1e6 / fw.F_CPU_HZ
    mean = (lambda total: float(total) * us / n) if n else (lambda total: 0.0)
    return dict(release_mean_us=mean(status.release_cycles_sum), release_max_us=float(status.release_cycles_max) * us,
                compute_mean_us=mean(status.compute_cycles_sum), compute_min_us=float(status.compute_cycles_min) * us,
                compute_max_us=float(status.compute_cycles_max) * us, timed_ticks=n,
                compute_path_mean_us={path: float(status.compute_path_cycles_sum[i]) * us / status.compute_path_ticks[i]
                                      for i, path in enumerate(COMPUTE_PATHS) if status.compute_path_ticks[i]},
                compute_path_ticks={path: int(status.compute_path_ticks[i]) for i, path in enumerate(COMPUTE_PATHS)})


def place_robot(model: mujoco.MjModel, data: mujoco.MjData, twin: DigitalTwin, lap: Variant, seed: int) -> core.Sim:
    """The robot on the start line at time 0, with a fresh head the glue (not the C callback) owns."""
    mujoco.mj_resetDataKeyframe(model, data, model.key(START_KEY).id)
    sim = setup(data.userdata, model, twin, lap.params, lap.sensor, seed, lap.physics, lap.timing, lap.power)
    sim.magic = PIL_MAGIC
    return sim


class Telemetry:
    """The UART's bytes as lines (cut by the wire's own :class:`LineSplitter`): counted, checked against the wire
    format (unless ``wire`` is False: any program's own lines), handed on. A line longer than any wire line is
    counted as bad and not handed on."""

    def __init__(self, on_line: Callable[[float, str], None] | None, wire: bool = True):
        self.on_line, self.splitter, self.lines, self.bad, self.offset = on_line, LineSplitter(), 0, 0, 0.0
        self.wire = wire

    def take(self, data: bytes, t: float) -> None:
        for raw in self.splitter.feed(data):
            self.lines += 1
            if raw is None:
                self.bad += 1
                continue
            line = raw.decode("ascii", errors="replace")
            try:
                if self.wire:
                    decode(line)
            except WireError:
                self.bad += 1
            if self.on_line:
                self.on_line(t + self.offset, line)


def advance(mcu: Mcu, data: mujoco.MjData, telemetry: Telemetry, steps: int) -> tuple[Outcome, str] | None:
    """One chunk in lockstep; (failure, detail) if the lap cannot go on (stalled, diverged, refused)."""
    status, why = mcu.lockstep(steps)
    core.flush_mujoco_log()
    telemetry.take(mcu.uart(), float(data.time))
    if status != Status.OK:
        return outcome_of(status), why
    if not np.isfinite(data.qpos).all():
        return Outcome.DIVERGED, "the physics produced a non-finite state"
    return None


def _calibrate(mcu: Mcu, data: mujoco.MjData, sim: core.Sim, judge: LapJudge, telemetry: Telemetry, steps: int,
               limits: LapLimits) -> None:
    """Power-up to the end of the firmware's calibration turn (its mode leaves CALIBRATE)."""
    telemetry.offset = 0.0
    while True:
        failure = advance(mcu, data, telemetry, steps)
        if failure:
            judge.fail(*failure, float(data.time), 0.0)
            return
        sim.records_written = 0  # the turn's trace is not judged
        mode = mcu.state().mode
        if mode == IDLE:
            telemetry.offset = -float(data.time)  # lap times count from the button press
            return
        if mode != CALIBRATE:
            judge.fail(Outcome.FIRMWARE_STALLED, f"the firmware left its calibration turn for mode {mode}, not idle",
                       float(data.time), 0.0)
            return
        if data.time > limits.calibration_timeout_s + 1.0:
            judge.fail(Outcome.CALIBRATION,
                       f"the firmware's calibration turn did not end in {limits.calibration_timeout_s:g} s",
                       float(data.time), 0.0)
            return


def _drive(mcu: Mcu, data: mujoco.MjData, sim: core.Sim, judge: LapJudge, telemetry: Telemetry, steps: int) -> None:
    """The lap: button B held until the firmware runs, then chunks judged until the lap ends."""
    consumed, pressed = 0, True
    while not judge.done:
        failure = advance(mcu, data, telemetry, steps)
        if pressed and mcu.state().mode == RUN:
            mcu.buttons(0)
            pressed = False
        try:
            judge.feed(core.records_since(data.userdata, sim, consumed))
        except TwinError as e:
            judge.fail(Outcome.REFUSED, str(e), float(data.time), float(sim.energy_j))
            return
        consumed = sim.records_written
        if failure:  # after the chunk's ticks: a lap completed before the firmware stalled is completed
            judge.fail(*failure, float(data.time), float(sim.energy_j))
            return
        if pressed and data.time > 1.0:
            judge.fail(Outcome.FIRMWARE_STALLED, "the firmware did not start within 1 s of button B being pressed",
                       float(data.time), float(sim.energy_j))
            return

