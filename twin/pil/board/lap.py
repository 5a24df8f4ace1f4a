"""A lap driven by any program for the 3pi, run unmodified on the board model (:func:`run_board_lap`), judged by the
physics alone.

The robot stands on the start line and is powered up at MuJoCo time 0; the program runs as it would on the robot:
welcome screens, prompts, calibration spins on the simulated floor, waits for buttons that the operator presses
(:mod:`twin.pil.board.operator`). The lap clock starts in the first physics step the motors drive after the
operator's last press (or after power-up, for a program that waits for nothing); a press while the lap is being
judged means that drive was a preparation (a calibration spin), and the clock starts again at the next drive. From
its start the lap is judged as every lap is (:class:`twin.core.lap.LapJudge`), from the trace the board writes out of
the physics: pose, progress, cross-track error, motor voltages and energy. Nothing is read from the program's memory,
so a program's loss of the line is not judged; leaving the line by more than the limit is (``off_track``).

A program that never drives ends at ``limits.timeout_s`` after power-up, and any run at twice that, as ``timeout``
with the reason; an MCU that stops (sleeps with interrupts off) or crashes ends it as ``firmware_stalled``.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Callable

import mujoco
import numpy as np

from twin.core import native as core
from twin.core.digital_twin import DigitalTwin
from twin.core.lap import COL, LapLimits, LapResult
from twin.core.maze import judge_for
from twin.core.outcomes import Outcome
from twin.core.variant import Variant
from twin.errors import TwinError
from twin.pil import firmware as fw
from twin.pil.board.display import BoardLog
from twin.pil.board.operator import BUTTONS, Operator, Press, Script, Seen
from twin.pil.board.report import BoardReport
from twin.pil.lap import BOARD_SENSORS, CHUNK_S, TRIMMER_V, McuReport, Telemetry, advance, place_robot, run_pil_lap, \
    runnable_firmware
from twin.pil.mcu import Mcu, glue
from twin.pil.program import Program, load_program

TRACE_PERIOD_S = 0.001  # the physics trace's period: every step at the default 1 ms
NO_WATCHDOG_S = 1e6  # a program may wait as long as it likes: the run's time limits end it


def check_board(twin: DigitalTwin) -> None:
    """What the board can run: its five sensor lines; TwinError naming the parameter otherwise."""
    count = twin.control_params().count
    if count != BOARD_SENSORS:
        raise TwinError(f"sensor.count: a 3pi program reads the board's {BOARD_SENSORS} reflectance sensors (PC0..PC4); "
                        f"the robot has {count} (--set sensor.count={BOARD_SENSORS})")


def runnable_program(twin: DigitalTwin, path: str) -> Program:
    """The program in ``path`` (ELF or HEX), checked against the twin before any lap: the twin's own firmware against
    its parameters (:func:`twin.pil.lap.runnable_firmware`), any other program against the board; a one-line
    TwinError otherwise (a missing simavr included)."""
    program = load_program(path)
    if program.traced:
        runnable_firmware(twin, path)
    else:
        check_board(twin)
        glue()
    return program


def run_program_lap(twin: DigitalTwin, program: Program, seed: int = 0, limits: LapLimits = LapLimits(),
                    keep_trace: bool = True, operator: Operator | Script | None = None,
                    on_line: Callable[[float, str], None] | None = None) -> tuple[LapResult, McuReport | BoardReport]:
    """A lap of ``program``: the twin's own firmware as :func:`twin.pil.lap.run_pil_lap` runs it (traced from its RAM),
    any other on the board (:func:`run_board_lap`)."""
    if program.traced:
        return run_pil_lap(twin, program.path, seed=seed, limits=limits, keep_trace=keep_trace, on_line=on_line)
    return run_board_lap(twin, program, seed=seed, limits=limits, keep_trace=keep_trace, operator=operator,
                         on_line=on_line)


class LapClock:
    """Starts the judge at the first drive after the last press, restarts it at a press during a drive, and rebases
    the trace to the lap: time and energy from the clock's start, cross-track sums over the lap only."""

    def __init__(self, twin: DigitalTwin, limits: LapLimits, keep_trace: bool):
        self.twin, self.limits, self.keep_trace = twin, limits, keep_trace
        self.armed_at, self.judge, self.start_s, self.restarts, self.ever = 0.0, None, None, 0, False
        self.e0, self.abs_sum, self.abs_max = 0.0, 0.0, 0.0

    def press(self, press: Press) -> None:
        self.armed_at = press.t + press.hold
        if self.judge is not None and not self.judge.done:
            self.judge, self.start_s = None, None
            self.restarts += 1

    def feed(self, rec: np.ndarray, sim: core.Sim) -> None:
        if self.judge is None:
            driven = (rec[:, COL["time_s"]] >= self.armed_at - 1e-9) & (
                (rec[:, COL["u_left_v"]] != 0) | (rec[:, COL["u_right_v"]] != 0))
            hit = np.flatnonzero(driven)
            if not len(hit):
                return
            rec = rec[hit[0]:]
            self.judge = judge_for(self.twin.track, self.limits, self.keep_trace)
            self.start_s, self.e0 = float(rec[0, COL["time_s"]]), float(rec[0, COL["energy_j"]])
            self.ever = True
            self.abs_sum = self.abs_max = 0.0
        if self.judge.done or not len(rec):
            return
        rec = rec.copy()
        rec[:, COL["time_s"]] -= self.start_s
        rec[:, COL["energy_j"]] -= self.e0
        off = np.abs(rec[:, COL["offset_m"]])
        rec[:, COL["offset_abs_sum_m"]] = self.abs_sum + np.cumsum(off)
        rec[:, COL["offset_abs_max_m"]] = np.maximum.accumulate(np.maximum(off, self.abs_max))
        self.abs_sum, self.abs_max = float(rec[-1, COL["offset_abs_sum_m"]]), float(rec[-1, COL["offset_abs_max_m"]])
        self.judge.feed(rec)

    def fail(self, code: Outcome, detail: str, now_s: float, energy_j: float) -> None:
        if self.judge is None:
            self.judge = judge_for(self.twin.track, self.limits, self.keep_trace)
        t0 = self.start_s or 0.0
        self.judge.fail(code, detail, now_s - t0, energy_j - (self.e0 if self.start_s is not None else 0.0))

    @property
    def done(self) -> bool:
        return self.judge is not None and self.judge.done


def run_board_lap(twin: DigitalTwin, program: Program, seed: int = 0, limits: LapLimits = LapLimits(),
                  keep_trace: bool = True, operator: Operator | Script | None = None,
                  on_line: Callable[[float, str], None] | None = None,
                  battery_v: float | None = None, trimmer_v: float = TRIMMER_V) -> tuple[LapResult, BoardReport]:
    """Run ``program`` (any 3pi program, :func:`twin.pil.program.load_program`) on the board in the twin until its lap
    ends (module docstring). ``operator``: who presses the buttons (default :class:`Operator`); ``on_line(t, line)``:
    each line the program sent on its UART [s since power-up]; ``battery_v``: the battery's open-circuit voltage,
    which ADC6 sees through the 3pi's divider and which feeds the motors' supply (twin.model.power; default the twin's
    ``motor.supply_voltage``: the 3pi's four AAA cells);
    ``trimmer_v``: what ADC7 sees from the user trimmer, 0..5 V [V] (default: mid travel)."""
    if not 0.0 <= trimmer_v <= 5.0:
        raise TwinError(f"trimmer_v: the trimmer gives 0..5 V (AVCC), got {trimmer_v!r}")
    check_board(twin)
    lap = Variant.of(twin, {} if battery_v is None else {"motor.supply_voltage": battery_v})
    model = twin.model()
    data = mujoco.MjData(model)
    board_limits = dataclasses.replace(limits, max_line_lost_s=2 * limits.timeout_s + 1)  # not judged: see above
    clock = LapClock(twin, board_limits, keep_trace)
    operator = operator or Operator()
    log, telemetry, presses = BoardLog(fw.F_CPU_HZ), Telemetry(on_line, wire=False), []
    battery = lap.power.battery_v
    steps = max(1, round(CHUNK_S / model.opt.timestep))
    release_at = None
    with Mcu(program) as mcu:
        mcu.board(True, battery, trimmer_v, max(1, round(TRACE_PERIOD_S / model.opt.timestep)))
        sim = place_robot(model, data, twin, lap, seed)
        mcu.attach(model, data, sim, NO_WATCHDOG_S)  # the watchdog is the twin firmware's alone
        mcu.zero_time()
        consumed = 0
        while not clock.done:
            failure = advance(mcu, data, telemetry, steps)
            now = float(data.time)
            clock.feed(core.records_since(data.userdata, sim, consumed), sim)
            consumed = sim.records_written
            status = mcu.board_status()
            log.take(mcu.lcd_frames(), mcu.notes(), mcu.leds(), status.used)
            if clock.done:
                break
            if failure:
                clock.fail(*failure, now, float(sim.energy_j))
                break
            if release_at is not None and now >= release_at - 1e-9:
                mcu.buttons(0)
                release_at = None
            if release_at is None:
                seen = Seen(now, log.seconds(status.last_poll) if status.polls else -math.inf,
                            log.seconds(status.last_drive) if status.last_drive else -math.inf, log.screen)
                press = operator.decide(seen)
                if press is not None:
                    presses.append(press)
                    mcu.buttons(BUTTONS[press.button])
                    release_at = now + press.hold
                    clock.press(press)
            if why := _over_time(clock, now, limits):
                clock.fail(Outcome.TIMEOUT, why, now, float(sim.energy_j))
        status, board = mcu.status(), mcu.board_status()
        log.take(mcu.lcd_frames(flush=True), mcu.notes(), mcu.leds(), board.used)  # the screen as the run ends
        log.close(board.note, float(data.time))
    result = clock.judge.result(BOARD_SENSORS, [], [], lap.values)
    report = BoardReport.of(
        log, mcu=fw.MCU, board=fw.BOARD, f_cpu_hz=fw.F_CPU_HZ, program=program.path, format=program.kind,
        flash_bytes=program.flash_bytes, flash_total_bytes=fw.FLASH_BYTES, ram_bytes=program.ram_bytes,
        ram_total_bytes=fw.RAM_BYTES, cycles=int(status.cycle), awake_share=int(status.awake) / max(1, int(status.cycle)),
        lap_start_s=clock.start_s, restarts=clock.restarts, presses=tuple(presses), uart_lines=telemetry.lines,
        events_lost=int(board.frames_lost + board.notes_lost + board.leds_lost), resets=int(board.resets),
        led_lit_s=(int(board.red_lit) / fw.F_CPU_HZ, int(board.green_lit) / fw.F_CPU_HZ),
        reset_span_s=(log.seconds(board.first_reset), log.seconds(board.last_reset)) if board.resets else None)
    return result, report


def _over_time(clock: LapClock, now: float, limits: LapLimits) -> str | None:
    """Why the run ends now for want of a lap, or None: no drive by the lap timeout after power-up, no lap by twice it."""
    if not clock.ever and now >= limits.timeout_s:
        return f"the program did not drive the motors within {limits.timeout_s:g} s of power-up"
    if now >= 2 * limits.timeout_s:
        return f"no lap within {2 * limits.timeout_s:g} s of power-up"
    return None
