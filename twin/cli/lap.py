"""``lap``: calibrate, then one closed-loop lap, reported as text or JSON. The firmware runs as C in the twin's
callback, or (``--firmware avr``) as the robot's ATmega328P binary in simavr, with the MCU's figures reported, or
(``--firmware FILE``, ELF or HEX) as any 3pi program on the 3pi's board, with what the robot showed."""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

from twin.cli import options as o
from twin.cli import twin_options as tw
from twin.cli.output import Output
from twin.cli.startup import loading

if TYPE_CHECKING:
    from twin.pil.board import BoardReport

HELP = "calibrate and run one closed-loop lap; print the lap time and a summary"
ACTUATIONS = {"voltage": "voltages", "setpoint": "wheel-speed set-points", "duty": "PWM duties"}


def add_parser(sub) -> None:
    p = sub.add_parser("lap", help=HELP, description=HELP + ". A lap that leaves the track is a result "
                       "(completed: false, with the reason), not an error. A 3pi program (--firmware FILE) runs from "
                       "power-up; its lap clock starts when the motors first drive after the operator's last press.")
    o.add_world(p)
    o.add_values(p)
    o.add_seed(p, 0)
    o.add_lap_timeout(p)
    p.add_argument("--timeout", dest="lap_timeout", type=o.number(0.0, 3600.0, lo_open=True),
                   action=o.deprecated(argparse._StoreAction, "--lap-timeout"), help=argparse.SUPPRESS)
    o.add_firmware(p, "the lap")
    o.add_controller(p)
    o.add_db(p, "the lap")
    o.add_json(p)
    o.add_recording(p, "the lap")
    o.add_verbose(p)
    p.set_defaults(run=run)


def lap_summary(result, twin, seed: int) -> dict:
    """The result with its track (a maze's length: its shortest path, as the result has it)."""
    return {**result.summary(), "track": twin.track.name, "track_length_m": result.track_length_m, "seed": seed}


def run(args: argparse.Namespace) -> int:
    with loading():
        from mjcf.maze import Maze
        from twin.core.closed_loop import run_laps
        from twin.core.lap import LapLimits
        from twin.fmi import run_controller_lap
        from twin.pil.board import BoardReport, Operator, run_program_lap, runnable_program
        from twin.pil.lap import run_pil_lap
        from twin.viz import recording

    out = Output(args.json)
    recording.check_targets(args.save, args.view)  # before the lap: a bad path fails now, not after
    o.check_db(args.db)
    program, script = tw.program_from_args(args)
    twin = tw.twin_from_args(args, robot="3pi" if program is not None and not program.traced else None)
    warning = tw.gains_warning(args, twin)
    limits, keep = LapLimits(timeout_s=args.lap_timeout), bool(args.save or args.view)
    mcu = None
    controller, peer = tw.controller_from_args(args, twin, out)
    if controller:
        for name, value in controller.left_at_start.items():
            out.say(f"note: the controller's input {name} keeps its start value {value} (no twin port maps to it)")
        try:
            result = run_controller_lap(twin, controller, seed=args.seed, limits=limits, keep_trace=keep)
        finally:
            controller.close()  # its process frees the FMU and ends
    elif args.firmware == "c":
        result = run_laps(twin, [{}], seed=args.seed, limits=limits, keep_traces=keep)[0]
    elif program is None:
        result, mcu = run_pil_lap(twin, None, seed=args.seed, limits=limits, keep_trace=keep)
    else:
        runnable_program(twin, program.path)
        result, mcu = run_program_lap(twin, program, seed=args.seed, limits=limits, keep_trace=keep,
                                      operator=script or Operator())
    board = mcu if isinstance(mcu, BoardReport) else None
    saved = recording.save_laps(args.save, args.view, twin.track, twin.texture, [result], ["robot"],
                                shows=board_shows(board) if board else None)
    summary = {**lap_summary(result, twin, args.seed), "firmware": args.firmware, "recording": saved,
               "gains_warning": warning}
    if board:
        summary["board"] = board.summary()
    elif mcu:
        summary["mcu"] = mcu.summary()
    if controller:
        summary["controller"] = controller.describe()
    if peer:
        summary["multi_model"] = {"file": args.multi_model, "stand_in": args.stand_in, "controller": peer.instance,
                                  "twin_values": peer.values}
    with loading():
        from tuner.history import record_lap

    summary["history"] = o.keep_history(args.db, lambda h: record_lap(h, twin, result), out)
    out.document(summary)
    if isinstance(twin.track, Maze):
        out.say((f"finish reached in {result.lap_time_s:.3f} s" if result.completed else
                 f"finish not reached: {result.failure} ({result.detail}) after {result.simulated_s:.2f} s")
                + f" in the {twin.track.name} (shortest path {result.track_length_m:.2f} m); {result.distance_m:.2f} m driven")
    elif result.completed:
        out.say(f"lap completed in {result.lap_time_s:.3f} s on {twin.track.name} ({twin.track.length_m:.2f} m)")
    else:
        out.say(f"lap not completed: {result.failure} ({result.detail}) after {result.simulated_s:.2f} s, "
                f"{result.distance_m:.2f} of {twin.track.length_m:.2f} m")
    out.say(f"cross-track error: max {result.max_cross_track_m * 1000:.1f} mm, mean {result.mean_cross_track_m * 1000:.1f} mm")
    out.say(f"energy drawn by the motors: {result.energy_j:.2f} J")
    p = result.parameters
    if board:
        _say_board(out, board)
    elif controller:
        out.say(f"driven by {controller.path} (FMI {controller.fmi_version}, every "
                f"{controller.sample_time * 1000:g} ms; {ACTUATIONS[controller.actuation]} out); seed {args.seed}")
    else:
        out.say(f"gains: v_max={p['control.v_max']:g} m/s, K_B={p['control.kb']:g}, K_P={p['control.kp']:g}, "
                f"K_I={p['control.ki']:g}, K_D={p['control.kd']:g}, Δt={p['control.dt'] * 1000:g} ms; "
                + (f"physics step {p['motion.timestep'] * 1000:.6g} ms; " if "motion.timestep" in p else "")
                + f"seed {args.seed}")
    if mcu and not board:
        out.say(f"MCU: {mcu.mcu} at {mcu.f_cpu_hz / 1e6:g} MHz ({mcu.board}): busy {mcu.busy_cycles_mean:.0f} cycles "
                f"per tick on average, {mcu.busy_cycles_max} at most, of {mcu.period_cycles} (headroom "
                f"{mcu.headroom * 100:.1f} %, {mcu.overruns} overruns); flash {mcu.flash_bytes} of {mcu.flash_total_bytes} B, "
                f"RAM {mcu.ram_bytes} of {mcu.ram_total_bytes} B (static); {mcu.telemetry_lines} telemetry lines")
        if mcu.overruns:
            out.say(f"warning: the firmware overran its {p['control.dt'] * 1000:g} ms period {mcu.overruns} times: the MCU "
                    "cannot keep up at this control.dt, so its ticks stretched")
    if saved:
        out.say(f"recording: {saved}")
    return 0


def board_shows(board: BoardReport) -> dict:
    """What the robot showed, for the recording: times from the lap clock's start (before it: negative)."""
    t0 = board.lap_start_s or 0.0
    return {"lcd": [(t - t0, text) for t, text in board.lcd],
            "notes": [(a - t0, b - t0, hz) for a, b, hz, _ in board.notes],
            "leds": [(t - t0, red, green) for t, red, green in board.leds]}


def _say_board(out: Output, board: BoardReport) -> None:
    ram = f", RAM {board.ram_bytes} of {board.ram_total_bytes} B (static)" if board.ram_bytes is not None else ""
    out.say(f"program: {board.program} ({board.format}) on the {board.mcu} at {board.f_cpu_hz / 1e6:g} MHz, "
            f"{board.board}: flash {board.flash_bytes} of {board.flash_total_bytes} B{ram}; awake "
            f"{board.awake_share * 100:.1f} % of its cycles")
    presses = ", ".join(f"{p.button} at {p.t:.2f} s" for p in board.presses) or "none"
    start = f"{board.lap_start_s:.2f} s after power-up" if board.lap_start_s is not None else "never (no drive)"
    out.say(f"button presses ({board.presses[0].by if board.presses else 'operator'}): {presses}; lap clock started "
            f"{start}" + (f" ({board.restarts} earlier drive{'s' if board.restarts > 1 else ''} before a press: "
                          "preparation)" if board.restarts else ""))
    final = " / ".join(line.strip() for line in board.lcd_final.split("\n") if line.strip()) or "(blank)"
    leds = board.led_summary(board.cycles / board.f_cpu_hz)["final"]
    out.say(f"LCD at the end: {final}; {len(board.lcd)} screens; buzzer: {len(board.notes)} notes; LEDs at the end: "
            f"red {'on' if leds['red'] else 'off'}, green {'on' if leds['green'] else 'off'}")
    if line := board.resets_line():
        out.say(line)
    for line in board.unmodelled:
        out.say(f"note: the program used a peripheral the board model does not connect: {line}")
