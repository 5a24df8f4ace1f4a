"""``emulate``: a stand-in robot: a twin with hidden parameters driving lap after lap and streaming its wire
telemetry at real-time pace on a pseudo-terminal it creates, or on a 127.0.0.1 TCP port, answering the twin's
commands (wire version 2); a hidden parameter may drift from lap to lap."""

from __future__ import annotations

import argparse
import contextlib
import os
import select
import time
from typing import TYPE_CHECKING

from lf_common.errors import OutputError
from twin.cli import options as o
from twin.cli import twin_options as tw
from twin.cli.library_values import COMMAND_MODES
from twin.cli.output import Output
from twin.cli.startup import loading
from twin.errors import TwinError

if TYPE_CHECKING:
    from twin.link.emulator import CommandPort
    from twin.link.robot_end import RobotEnd

HELP = "a stand-in robot streaming wire telemetry on a pty or a TCP port"


def add_parser(sub) -> None:
    p = sub.add_parser("emulate", help=HELP, description=(
        "A twin with hidden parameters (--set) and its own noise seed drives lap after lap and streams its telemetry "
        "(twin.telemetry.wire) at real-time pace (or --speed times faster) on a pseudo-terminal it creates (the path is printed) "
        "or on 127.0.0.1:--tcp PORT."))
    o.add_world(p)
    o.add_values(p, "a hidden model-space parameter, repeatable")
    o.add_seed(p, 7, "the robot's noise seed (lap k uses seed + k)")
    p.add_argument("--speed", type=o.number(0.01, 1000.0), default=1.0, metavar="X", help="faster than real time by this factor")
    p.add_argument("--every", type=o.number(1, 1000, integer=True), default=2, metavar="N", help="one sample line every N control ticks")
    p.add_argument("--laps", type=o.count_type, metavar="N", help="stop after this many laps (default: run until stopped)")
    p.add_argument("--tcp", type=o.number(0, 65535, integer=True), metavar="PORT",
                   help="serve on 127.0.0.1:PORT instead of a pty (0: any free port)")
    p.add_argument("--link", metavar="PATH", help="also make PATH a symlink to the pty, stable across restarts")
    p.add_argument("--echo", metavar="FILE", help="append every line sent to FILE")
    o.add_firmware(p, "the robot (with avr or a program file, the lines are the MCU's UART output)")
    p.add_argument("--drift", action="append", metavar="ADDRESS=START:END@LAPS[:SHAPE]",
                   help="a hidden parameter drifting from START (lap 0) to END (lap LAPS), e.g. worn tyres "
                        "motion.mu=0.9:0.55@80; SHAPE linear (default), accelerating (START + (END − START)·(lap/LAPS)²) "
                        "or step@K (renewed at lap K: back to START, drifting again); repeatable, one per parameter "
                        "(two causes at once: motion.mu=… and motor.supply_voltage=…)")
    p.add_argument("--robot-id", default="lf-1", metavar="ID", help="the robot's id in its wire headers (1-16 of A-Z a-z 0-9 _ -)")
    p.add_argument("--wire", type=int, choices=(1, 2), default=2,
                   help="the wire version it speaks: 2 (an id, answers commands) or 1 (an older robot: neither)")
    p.add_argument("--eeprom", metavar="FILE", help="its EEPROM (stored gains), kept in FILE across runs (created at the first STORE; "
                   "a file that is not its image is refused)")
    p.add_argument("--commands", choices=COMMAND_MODES, default="answer",
                   help="how it treats the twin's commands: answer them, refuse each SET and STORE (NAK,LOCKED), "
                        "ignore them (a receive line that is cut), or answer all but STORE, which it neither writes nor "
                        "answers (no-store: an EEPROM write that hangs)")
    p.add_argument("--lockstep", action="store_true",
                   help="after each lap wait for the twin's next command (live --act sends one every lap): runs at "
                        "--speed then see the twin's decisions on the lap they were taken")
    p.add_argument("--idle-timeout", type=o.number(0.1, 86400.0), default=60.0, metavar="WALL_S",
                   help="stop when nobody has read the stream for this long (no TCP client, a pty nobody reads); in "
                        "--lockstep, when the twin has given no sign of life (a command or a keep-alive) for this long")
    o.add_json(p)
    o.add_verbose(p)
    p.set_defaults(run=run)


def _echo_file(path: str | None):
    if not path:
        return None
    if os.path.isdir(path):
        raise TwinError(f"{path}: is a folder; name a file for --echo")
    if not os.path.isdir(os.path.dirname(os.path.abspath(path))):
        raise TwinError(f"{path}: folder {os.path.dirname(os.path.abspath(path))} does not exist")
    try:
        return open(path, "a", buffering=1)  # appended: never replaces what is there
    except OSError as e:
        raise TwinError(f"{path}: cannot append to it ({e.strerror or e})") from None


def _echo_writer(f):
    """Each line sent, appended to the --echo file; a write that fails stops the emulator naming the file (as an
    OSError it would pass for a reader that went away)."""

    def echo(line: str) -> None:
        try:
            f.write(line)
        except OSError as e:
            raise OutputError(f"{f.name}: cannot write the --echo file ({e.strerror or e})") from None

    return echo


def run(args: argparse.Namespace) -> int:
    with loading():
        from twin.link.emulator import (Drift, NoReader, check_drifts, check_link_path, firmware_lap_records,
                                        lap_records)
        from twin.pil.board import load_script

    out = Output(args.json)
    if args.link:
        check_link_path(args.link)
    echo_file = _echo_file(args.echo)
    try:
        program, script = tw.program_from_args(args)
        twin = tw.twin_from_args(args, robot="3pi" if program is not None and not program.traced else None)
        args.gains_warning = tw.gains_warning(args, twin)
        twin.model()
        drifts = [Drift.parse(d, twin) for d in args.drift or ()]
        check_drifts(drifts)
        robot = _robot_end(args, twin)
        if args.firmware == "c":
            lines = lap_records(twin, args.seed, args.every, args.laps, robot, drifts)
        else:
            if robot is not None and args.eeprom:
                raise TwinError("--eeprom: the firmware on the MCU keeps its gains in the MCU's own EEPROM")
            elf = None if args.firmware == "avr" else args.firmware
            tw.check_program_runs(twin, program)  # a bad program or a missing simavr fails now, not at the first reader
            operator = (lambda: load_script(args.operator)) if script else None
            lines = firmware_lap_records(twin, elf, args.seed, args.every, args.laps, operator, drifts)
            robot = None  # its program answers (or not) for itself
        echo = _echo_writer(echo_file) if echo_file else None
        if args.tcp is not None:
            _serve_tcp(args, lines, echo, out, robot)
        else:
            _serve_pty(args, lines, echo, out, robot)
    except NoReader as e:
        out.say(f"robot emulator stops: {e}")
    finally:
        if echo_file:
            with contextlib.suppress(OSError):  # (what could not be written was reported above)
                echo_file.close()
    return 0


def _robot_end(args, twin) -> RobotEnd | None:
    """The robot's end of the command link (None for a version 1 robot)."""
    with loading():
        from twin.link.robot_end import EepromFile, RobotEnd
        from twin.telemetry.wire import GAIN_ADDRESSES, valid_robot_id

    if args.wire == 1:
        for flag, given in (("--eeprom", args.eeprom), ("--lockstep", args.lockstep),
                            ("--commands", args.commands != "answer")):
            if given:
                raise TwinError(f"{flag}: a version 1 robot takes no commands (--wire 1)")
        return None
    if not valid_robot_id(args.robot_id):
        raise TwinError(f"--robot-id {args.robot_id!r}: give 1-16 of A-Z a-z 0-9 _ -")
    eeprom = EepromFile(args.eeprom) if args.eeprom else None
    limits = {a: (twin.space.parameter(a).lower, twin.space.parameter(a).upper) for a in GAIN_ADDRESSES}
    return RobotEnd(args.robot_id, {a: twin.space.get(a) for a in GAIN_ADDRESSES}, limits, eeprom, args.commands)


class _Receiver:
    """Bytes the twin sent on ``fd`` (a pty master or a socket), waiting at most ``timeout``; b"" once it closed."""

    def __init__(self, fd: int):
        self.fd, self.closed = fd, False

    def __call__(self, timeout: float) -> bytes:
        if self.closed:
            time.sleep(timeout)
            return b""
        ready, _, _ = select.select([self.fd], [], [], timeout)
        if not ready:
            return b""
        try:
            data = os.read(self.fd, 4096)
        except (BlockingIOError, InterruptedError):
            return b""
        except OSError:
            data = b""
        self.closed = not data
        return data


def _commands(args, robot: RobotEnd | None, fd: int) -> CommandPort | None:
    with loading():
        from twin.link.emulator import CommandPort

    return None if robot is None else CommandPort(_Receiver(fd), robot, args.lockstep, args.idle_timeout, args.laps)


def _serve_tcp(args, lines, echo, out: Output, robot: RobotEnd | None) -> None:
    with loading():
        from twin.link.emulator import accept, serve_tcp, stream

    server = serve_tcp(args.tcp)
    with server:
        url = f"socket://127.0.0.1:{server.getsockname()[1]}"
        out.document({"link": url, "gains_warning": args.gains_warning})
        out.say(f"robot emulator on {url}")
        commands = _commands(args, robot, -1)  # one robot across connections; each brings its own way back
        while True:
            conn = accept(server, args.idle_timeout)
            if commands is not None:
                commands.receive = _Receiver(conn.fileno())
            try:
                stream(lines, conn.sendall, args.speed, echo, commands)
                return
            except OSError:
                continue  # the reader went away: wait (at most --idle-timeout) for the next one, carry on with the laps
            finally:
                conn.close()


def _serve_pty(args, lines, echo, out: Output, robot: RobotEnd | None) -> None:
    with loading():
        from twin.link.emulator import drain_pty, open_pty, pty_writer, release_link, stream

    master, slave, tty_path = open_pty(args.link)
    try:
        path = args.link or tty_path
        out.document({"link": path, "gains_warning": args.gains_warning})
        out.say(f"robot emulator on {path}")
        stream(lines, pty_writer(master, args.idle_timeout), args.speed, echo, _commands(args, robot, master))
        drain_pty(slave, args.idle_timeout)  # the last lap reaches the reader before the pty goes
    finally:
        if args.link:
            release_link(args.link, tty_path)
        os.close(master)
        os.close(slave)
