"""A stand-in for the physical robot: a twin with hidden parameters and its own noise seed, driving lap after lap
and streaming its telemetry in the wire form (:mod:`twin.telemetry.wire`) at real-time pace (or ``speed`` times faster),
on a pseudo-terminal it creates or on a TCP port of 127.0.0.1, so the live link is tested through a real
serial device.

Each lap is simulated ahead of time (from the start line, as the robot crosses it) and then streamed with its
own sample times, offset by the laps before it; lap k uses noise seed ``seed + k``.

It speaks wire version 2 (:mod:`twin.telemetry.wire`): its id in every header, and the twin's commands answered
between lines by its :class:`twin.link.robot_end.RobotEnd`; gains a SET changed take effect at the next lap start,
which is simulated only then. Hidden parameters may drift (:class:`Drift`: worn tyres, a tiring battery), from lap to
lap: linearly, accelerating, or renewed at a lap (a step), several at once. With ``lockstep`` the robot waits after each lap until the twin has sent it a command (a live twin
that acts sends one every lap): at any ``speed`` the laps then run with the gains the twin chose after the lap
before, as they would at real time on a twin that keeps up.

It never outlives its purpose: with nobody reading (no TCP client connected, or a pty whose buffer stays full)
for ``idle_timeout_s`` it stops (:class:`NoReader`). A TCP client that leaves is waited for again, for that long,
so a reader that restarts carries on with the same robot.
"""

from __future__ import annotations

import fcntl
import logging
import os
import select
import socket
import struct
import termios
import time
import tty
import dataclasses
from typing import Callable, Iterator, Sequence

from twin.core.closed_loop import run_laps
from twin.core.digital_twin import DigitalTwin
from twin.errors import TwinError
from twin.core.lap import COL
from twin.link.robot_end import RobotEnd
from twin.model.space import ChangeCost
from twin.telemetry.wire import Event, Header, Sample, WireError, decode, encode

log = logging.getLogger(__name__)


SHAPES = ("linear", "accelerating", "step")


@dataclasses.dataclass(frozen=True)
class Drift:
    """A hidden parameter that drifts from ``start`` (lap 0) to ``end`` (lap ``laps``), then stays, in a ``shape``:

    * ``linear``: at a constant rate;
    * ``accelerating``: start + (end − start)·(lap/laps)²: its rate grows lap by lap (worn tyres wear faster);
    * ``step``: linearly, but at lap ``step_lap`` the part is renewed (a tyre swapped, a battery charged): the value
      is back at ``start`` and drifts again from there.
    """

    address: str
    start: float
    end: float
    laps: int
    shape: str = "linear"
    step_lap: int | None = None

    def at(self, lap: int) -> float:
        if self.shape == "step" and lap >= self.step_lap:
            lap -= self.step_lap
        f = min(lap / self.laps, 1.0)
        return self.start + (self.end - self.start) * (f * f if self.shape == "accelerating" else f)

    @classmethod
    def parse(cls, text: str, twin: DigitalTwin) -> "Drift":
        """``ADDRESS=START:END@LAPS[:linear|accelerating|step@K]``, checked against the model space (a parameter
        that rebuilds the robot cannot change between laps)."""
        address, eq, rest = text.partition("=")
        span, at, tail = rest.partition("@")
        start, colon, end = span.partition(":")
        laps, _, shape = tail.partition(":")
        shape, step, step_lap = shape.partition("@")
        try:
            if not (eq and at and colon) or (shape or "linear") not in SHAPES or bool(step) != (shape == "step"):
                raise ValueError
            drift = cls(address.strip(), float(start), float(end), int(laps), shape or "linear",
                        int(step_lap) if step else None)
        except ValueError:
            raise TwinError(f"--drift {text}: expected ADDRESS=START:END@LAPS[:linear|accelerating|step@K], e.g. "
                            "motion.mu=0.9:0.55@80 or motion.mu=0.9:0.55@80:step@50") from None
        p = twin.space.parameter(drift.address)
        if p.cost is ChangeCost.REBUILD:
            raise TwinError(f"--drift {drift.address}: rebuilds the robot or track, so it cannot drift between laps")
        if drift.laps < 1:
            raise TwinError(f"--drift {text}: LAPS must be at least 1")
        if drift.step_lap is not None and drift.step_lap < 1:
            raise TwinError(f"--drift {text}: the step's lap K must be at least 1")
        p.check(f"--drift {drift.address} start", drift.start)
        p.check(f"--drift {drift.address} end", drift.end)
        return drift


def check_drifts(drifts: Sequence[Drift]) -> None:
    """Several causes at once, one drift each."""
    seen = [d.address for d in drifts]
    twice = sorted({a for a in seen if seen.count(a) > 1})
    if twice:
        raise TwinError(f"--drift {twice[0]}: given more than once (one drift per parameter)")


def drifted(drifts: Sequence[Drift], lap: int) -> dict[str, float]:
    return {d.address: d.at(lap) for d in drifts}


def _header(twin: DigitalTwin, every: int, robot: RobotEnd | None, gains_seq: int) -> str:
    count, dt = int(twin.space.get("sensor.count")), twin.space.get("control.dt")
    return encode(Header(count, dt, every) if robot is None else Header(count, dt, every, robot.robot_id, gains_seq))


def lap_records(twin: DigitalTwin, seed: int, every: int, laps: int | None, robot: RobotEnd | None = None,
                drifts: Sequence[Drift] = ()) -> Iterator[tuple[float, str]]:
    """(time since power-up [s], wire line) for lap after lap. With a ``robot`` (wire version 2) its BOOT line
    comes first and each lap runs with the gains in force at its start; without one, version 1 lines."""
    offset = 0.0
    k = 0
    if robot is not None:
        yield 0.0, _header(twin, every, robot, robot.seq)
        yield 0.0, robot.boot(0.0)
    while laps is None or k < laps:
        gains, gains_seq = robot.lap_start() if robot is not None else ({}, 0)
        values = {**gains, **drifted(drifts, k)}
        lap = run_laps(twin, [values], seed=seed + k)[0]
        yield offset, _header(twin, every, robot, gains_seq)
        yield offset, encode(Event(offset, "START"))
        # a lap that ended before its first control tick (no power to start on) has no samples: START, then FAIL
        for r in (lap.trace.records[::every] if lap.trace is not None else ()):
            t = offset + float(r[COL["time_s"]])
            yield t, encode(Sample(t, int(r[COL["position"]]), int(r[COL["line_seen"]]),
                                   float(r[COL["wheel_left_radps"]]), float(r[COL["wheel_right_radps"]])))
        end = offset + (lap.lap_time_s if lap.completed else lap.simulated_s)
        yield end, encode(Event(end, "LAP", lap_time_s=lap.lap_time_s) if lap.completed
                          else Event(end, "FAIL", reason=lap.failure))
        log.info("lap %d: %s (%s)", k, f"{lap.lap_time_s:.3f} s" if lap.completed else lap.failure,
                 ", ".join(f"{a}={v:.4g}" for a, v in values.items()) or "as built")
        offset = end
        k += 1


def firmware_lap_records(twin: DigitalTwin, elf: str | None, seed: int, every: int, laps: int | None,
                         operator=None, drifts: Sequence[Drift] = ()) -> Iterator[tuple[float, str]]:
    """(time since power-up [s], wire line) for lap after lap of the robot's own firmware on the emulated MCU
    (:func:`twin.pil.lap.run_pil_lap`): its UART lines as it sent them, and after each lap the LAP or FAIL event of a
    timing gate at the finish line (the robot itself cannot tell a lap from the next). Any other 3pi program runs
    on the board (:func:`twin.pil.board.run_board_lap`, ``operator()`` making each lap's operator) from power-up: its
    UART lines as it sent them, whatever they are, then the gate's event."""
    from twin.pil.board import Operator, run_board_lap  # needs the simavr glue only when asked for
    from twin.pil.lap import run_pil_lap
    from twin.pil.program import load_program

    program = load_program(elf) if elf else None
    offset, k = 0.0, 0
    while laps is None or k < laps:
        lines: list[tuple[float, str]] = []
        if drifts:
            twin.update(drifted(drifts, k))
        if program is not None and not program.traced:
            lap, report = run_board_lap(twin, program, seed=seed + k, keep_trace=False,
                                        operator=operator() if operator else Operator(),
                                        on_line=lambda t, line: lines.append((t, line)))
            start = report.lap_start_s or 0.0
            span = start + (lap.lap_time_s if lap.completed else lap.simulated_s)
            yield from ((offset + t, line) for t, line in lines if t <= span)
            yield offset + span, encode(Event(span, "LAP", lap_time_s=lap.lap_time_s) if lap.completed
                                        else Event(span, "FAIL", reason=lap.failure))
            offset += span
            k += 1
            continue
        lap, _ = run_pil_lap(twin, elf, seed=seed + k, keep_trace=False, telemetry_every=every,
                             on_line=lambda t, line: lines.append((t, line)))
        span = lap.lap_time_s if lap.completed else lap.simulated_s
        for t, line in lines:
            sample = _sample_time(line)  # its own clock; other lines come with their 0.1 s chunk's time
            t = sample if sample is not None else max(t, 0.0)  # what came before the button press, at the start
            if t <= span:  # the robot is picked up at the finish: what it sends after goes unheard
                yield offset + t, line
        yield offset + span, encode(Event(span, "LAP", lap_time_s=lap.lap_time_s) if lap.completed
                                    else Event(span, "FAIL", reason=lap.failure))
        log.info("lap %d (firmware on the MCU): %s", k, f"{lap.lap_time_s:.3f} s" if lap.completed else lap.failure)
        offset += span
        k += 1


def _sample_time(line: str) -> float | None:
    try:
        record = decode(line)
    except WireError:
        return None
    return record.t if isinstance(record, Sample) else None


class CommandPort:
    """The receiving side of the emulator's link: what the twin sends, handed to the robot's end, answered at once.

    Args:
      receive: waits at most ``timeout`` [s] for bytes from the twin; b"" if none came (or the link has no way back).
      robot: the robot's end of the command link.
      lockstep: wait after each lap for a command (at most ``idle_timeout_s`` from the twin's last sign of life: a
        command or a keep-alive, which a twin busy re-tuning sends; then :class:`NoReader`).
    """

    def __init__(self, receive: Callable[[float], bytes], robot: RobotEnd, lockstep: bool = False,
                 idle_timeout_s: float = 60.0, laps: int | None = None):
        self.receive, self.robot, self.lockstep, self.idle_timeout_s = receive, robot, lockstep, idle_timeout_s
        self.laps, self.ended = laps, 0  # after its last lap the robot waits for nothing
        self.heard = time.monotonic()  # the twin's last sign of life (bytes from it)

    def serve(self, timeout: float, send: Callable[[str], None]) -> None:
        """Answer what arrives within ``timeout`` [s] (0: only what is there now)."""
        end = time.monotonic() + timeout
        while True:
            data = self.receive(max(0.0, end - time.monotonic()))
            if data:
                self.heard = time.monotonic()
            for answer in self.robot.receive(data) if data else ():
                send(answer)
            if time.monotonic() >= end:
                return

    def await_command(self, send: Callable[[str], None]) -> None:
        """Lockstep: after a lap (but its last), wait for the twin's next command (answered); keep-alives are
        answered and restart the idle time, but the robot waits on. A twin that closed the link is gone
        (:class:`ConnectionResetError`: a TCP robot then waits for the next one)."""
        self.ended += 1
        if self.laps is not None and self.ended >= self.laps:
            return
        seen, self.heard = self.robot.received, time.monotonic()
        while self.robot.received == seen:
            if time.monotonic() > self.heard + self.idle_timeout_s:
                raise NoReader(f"lockstep: no sign of life from the twin for {self.idle_timeout_s:g} s after a lap")
            if getattr(self.receive, "closed", False):
                raise ConnectionResetError("lockstep: the twin closed the link")
            self.serve(0.05, send)


def _lap_end(line: str) -> bool:
    return line.startswith("$LFE,") and (",LAP," in line or ",FAIL," in line)


def stream(lines: Iterator[tuple[float, str]], write: Callable[[bytes], None], speed: float,
           echo: Callable[[str], None] | None = None, commands: CommandPort | None = None) -> None:
    """Write lines when their time comes: simulated time / speed from the call (the robot's power-up is time 0, so
    a program that sends nothing for a lap still takes the lap's time to report it); with ``commands``, answer the
    twin's commands between lines (and in lockstep, wait for one after each lap)."""

    def send(line: str) -> None:
        write(line.encode("ascii"))
        if echo:
            echo(line)

    start = time.monotonic()  # power-up (the first lap is simulated when the loop asks for its first line)
    for t, line in lines:
        now = time.monotonic()
        delay = start + t / speed - now
        if delay > 0:
            if commands is not None:
                commands.serve(delay, send)
            else:
                time.sleep(delay)
        elif delay < -0.5:  # fell behind (a lap was being simulated): carry on from here, keep the spacing
            start -= delay
        elif commands is not None:
            commands.serve(0.0, send)
        send(line)
        if commands is not None and commands.lockstep and _lap_end(line):
            waited = time.monotonic()
            commands.await_command(send)
            start += time.monotonic() - waited  # the robot's clock stood still while it waited


class NoReader(Exception):
    """Nobody read the stream for the idle time: the emulator's job is over."""


def check_link_path(link: str) -> None:
    """``--link`` may be created, or replace a symlink of ours (one pointing at a pty); nothing else is replaced."""
    if os.path.islink(link):
        if not os.readlink(link).startswith("/dev/pts/"):
            raise TwinError(f"{link}: is a symbolic link to {os.readlink(link)}, not one this emulator made; choose another --link")
    elif os.path.exists(link):
        raise TwinError(f"{link}: exists and is not a link this emulator made; choose another --link")
    elif not os.path.isdir(os.path.dirname(os.path.abspath(link))):
        raise TwinError(f"{link}: folder {os.path.dirname(os.path.abspath(link))} does not exist")


def open_pty(link: str | None = None) -> tuple[int, int, str]:
    """A pseudo-terminal pair in raw mode: (master fd, slave fd, slave path); optionally a stable symlink to the
    slave at ``link`` (see :func:`check_link_path`; :func:`release_link` removes it)."""
    if link:
        check_link_path(link)
    master, slave = os.openpty()
    tty.setraw(slave)  # no echo, no newline translation: bytes pass as sent
    path = os.ttyname(slave)
    if link:
        tmp = f"{link}.{os.getpid()}.tmp"
        os.symlink(path, tmp)
        os.replace(tmp, link)
    return master, slave, path


def release_link(link: str, tty_path: str) -> None:
    """Remove ``link`` if it still points at our pty: the kernel soon gives that pty's number to another
    program (a terminal), which a reader following a stale link would open."""
    try:
        if os.readlink(link) == tty_path:
            os.unlink(link)
    except OSError:
        pass  # gone, or replaced by another emulator: not ours any more


def pty_writer(master: int, idle_timeout_s: float) -> Callable[[bytes], None]:
    """Write to a pty master; a buffer that stays full for ``idle_timeout_s`` (nobody reads) raises NoReader."""

    def write(data: bytes) -> None:
        while data:
            _, ready, _ = select.select([], [master], [], idle_timeout_s)
            if not ready:
                raise NoReader(f"nobody read the pty for {idle_timeout_s:g} s")
            data = data[os.write(master, data):]

    return write


DRAINED_S = 0.25  # [s] the pty must stay empty this long: a byte just written sits in the kernel's flip buffer,
                  # uncounted, until a worker moves it to the reader's queue


def drain_pty(slave: int, idle_timeout_s: float) -> None:
    """Wait until the reader has taken everything written (closing the master discards what is left unread):
    until the pty has stayed empty for ``DRAINED_S``; NoReader if the reader takes nothing for ``idle_timeout_s``."""
    waiting, progress, empty_since = _unread(slave), time.monotonic(), time.monotonic()
    while True:
        time.sleep(0.02)
        now, left = time.monotonic(), _unread(slave)
        if left == 0 and now - empty_since >= DRAINED_S:
            return
        if left:
            empty_since = now
        if left < waiting:
            progress = now
        elif left and now - progress > idle_timeout_s:
            raise NoReader(f"nobody read the last {left} bytes on the pty for {idle_timeout_s:g} s")
        waiting = left


def _unread(slave: int) -> int:
    """Bytes written to the pty that its reader has not read yet."""
    return struct.unpack("i", fcntl.ioctl(slave, termios.FIONREAD, b"\0\0\0\0"))[0]


def serve_tcp(port: int) -> socket.socket:
    server = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    server.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        server.bind(("127.0.0.1", port))
    except OSError as e:
        server.close()
        raise TwinError(f"--tcp {port}: cannot listen on 127.0.0.1:{port} ({e.strerror or e})") from None
    server.listen(1)
    return server


def accept(server: socket.socket, idle_timeout_s: float) -> socket.socket:
    """The next client, waiting at most ``idle_timeout_s``; NoReader otherwise."""
    server.settimeout(idle_timeout_s)
    try:
        conn, _ = server.accept()
    except socket.timeout:
        raise NoReader(f"no client connected for {idle_timeout_s:g} s") from None
    conn.settimeout(idle_timeout_s)  # a client that stops reading is gone
    return conn
