"""Helpers of the live-link tests (tests/test_link.py, tests/test_live_twin.py): a scripted TCP robot, wire lines,
``live`` run in this process, and waiting on conditions and events rather than on the clock.

Every wait here has a deadline, and every deadline is far beyond what the awaited thing takes on an idle machine:
a busy machine makes a test slower, never wrong."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import threading
import time
from typing import Callable

import pytest

from twin.cli.main import main
from twin.telemetry.wire import Event, Header, Sample, encode

RUN = [sys.executable, "-m", "twin.run"]
OVAL = ["--track", "oval"]
DEADLINE_S = 120.0  # the longest any awaited thing may take before the test fails


def wait_until(condition: Callable[[], object], what: str, timeout: float = DEADLINE_S):
    """Poll ``condition`` until it returns something true (returned), or fail naming ``what`` after ``timeout``."""
    end = time.monotonic() + timeout
    while True:
        value = condition()
        if value:
            return value
        if time.monotonic() > end:
            raise AssertionError(f"waited {timeout:g} s for {what}")
        time.sleep(0.02)


# --- wire lines --------------------------------------------------------------------------------------------------

def samples(n: int, first: int = 0) -> list[bytes]:
    return [encode(Sample(0.01 * i, 3500, 1, 40.0, 40.0)).encode() for i in range(first, first + n)]


def lap_lines(lap_time_s: float, t0: float = 0.0) -> list[str]:
    """One whole wire lap of ``lap_time_s`` with a sample every 0.05 s."""
    rows = [encode(Sample(t0 + 0.05 * i, 3500, 1, 40.0, 40.0)) for i in range(1, int(lap_time_s / 0.05))]
    return [encode(Header(8, 0.005, 2)), encode(Event(t0, "START")), *rows,
            encode(Event(t0 + lap_time_s, "LAP", lap_time_s=lap_time_s))]


def stop_lap(t0: float = 1000.0) -> list[bytes]:
    """A 1 ms lap: implausible, so never compared or aligned on, but a lap, so ``live --laps 1`` stops right
    after reading it. A robot that ends its lines with this tells live when it has had everything."""
    return [encode(Event(t0, "START")).encode(), encode(Event(t0 + 0.001, "LAP", lap_time_s=0.001)).encode()]


# --- a scripted robot on TCP ------------------------------------------------------------------------------------

def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Robot:
    """A TCP 'robot' serving ``connections`` in turn. Each connection is a list of steps: bytes are sent as soon as
    the client connects, a ``threading.Event`` pauses the robot until it is set. After its steps a connection is
    hung up, except the last, which stays open until :meth:`close` (or the test's end). ``sent``: (time, line)."""

    def __init__(self, connections: list[list], port: int = 0):
        self.server = socket.socket()
        self.server.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self.server.bind(("127.0.0.1", port))
        self.server.listen(1)
        self.server.settimeout(DEADLINE_S)
        self.port = self.server.getsockname()[1]
        self.url = f"socket://127.0.0.1:{self.port}"
        self.sent: list[tuple[float, bytes]] = []
        self.released = threading.Event()
        self.thread = threading.Thread(target=self._run, args=(connections,), daemon=True)
        self.thread.start()

    def _run(self, connections) -> None:
        with self.server:
            for i, steps in enumerate(connections):
                try:
                    conn, _ = self.server.accept()
                except OSError:
                    return
                with conn:
                    try:
                        for step in steps:
                            if isinstance(step, threading.Event):
                                if not step.wait(DEADLINE_S):
                                    return
                            else:
                                conn.sendall(step)
                                self.sent.append((time.monotonic(), step))
                        if i == len(connections) - 1:
                            self.released.wait(DEADLINE_S)
                    except OSError:
                        pass  # the reader went away: the test decides what that means

    def close(self) -> None:
        self.released.set()


@pytest.fixture
def robots():
    """Robots made by a test, each let go when it ends."""
    made: list[Robot] = []

    def make(connections: list[list], port: int = 0) -> Robot:
        made.append(Robot(connections, port))
        return made[-1]

    yield make
    for r in made:
        r.close()


# --- processes whose output is read as it comes -------------------------------------------------------------------

class Pumped:
    """A child process whose stdout and stderr lines are collected by threads as they arrive, so a test can wait
    for a line (an event the child reports) without blocking on a pipe."""

    def __init__(self, args: list[str], cwd=None):
        self.proc = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=cwd)
        self.lines: dict[str, list[str]] = {"stdout": [], "stderr": []}
        self.changed = threading.Condition()
        self.pumps = [threading.Thread(target=self._pump, args=(name, getattr(self.proc, name)), daemon=True)
                      for name in self.lines]
        for t in self.pumps:
            t.start()

    def _pump(self, name: str, stream) -> None:
        for line in stream:
            with self.changed:
                self.lines[name].append(line)
                self.changed.notify_all()
        with self.changed:
            self.changed.notify_all()

    def wait_line(self, name: str, matches: Callable[[str], bool], what: str, timeout: float = DEADLINE_S) -> str:
        """The first line of ``name`` (stdout or stderr) that ``matches``, waiting for it if need be."""
        end = time.monotonic() + timeout
        with self.changed:
            while True:
                found = next((line for line in self.lines[name] if matches(line)), None)
                if found is not None:
                    return found.strip()
                left = end - time.monotonic()
                if left <= 0 or (self.proc.poll() is not None and not any(t.is_alive() for t in self.pumps)):
                    raise AssertionError(f"no {what} from {self.proc.args[2:4]}: {''.join(self.lines['stderr'])[-2000:]}")
                self.changed.wait(min(left, 1.0))

    def wait(self, timeout: float = DEADLINE_S) -> tuple[int, str, str]:
        """Wait for the process to end; (exit code, stdout, stderr)."""
        code = self.proc.wait(timeout=timeout)
        for t in self.pumps:
            t.join(timeout)
        return code, "".join(self.lines["stdout"]), "".join(self.lines["stderr"])

    def kill(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
        self.proc.wait()


def emulator(*args, cwd) -> Pumped:
    return Pumped([*RUN, "emulate", *map(str, args)], cwd=cwd)


# --- live in this process ---------------------------------------------------------------------------------------------

def live_here(capsys, *args) -> tuple[int, str, str]:
    """``live`` run in this process: (exit code, stdout, stderr)."""
    capsys.readouterr()
    code = main(["live", *OVAL, *map(str, args)])
    out, err = capsys.readouterr()
    return code, out, err


def live_until(capsys, stop_when: Callable[[], object], *args, timeout: float = DEADLINE_S) -> tuple[int, str, str, float]:
    """``live`` run in this process until ``stop_when()`` holds, then stopped as a user would, with SIGTERM (which
    live turns into a clean stop). Returns (exit code, stdout, stderr, seconds from the signal to the return).

    The signal goes to this process while live's own handler is installed: live cannot end by itself before it
    (no --laps, --duration or give-up is passed). A signal that would come after live has put the previous
    handler back lands on a harmless one installed here for the duration."""
    signalled: list[float] = []
    met, finished = threading.Event(), threading.Event()

    def watch() -> None:
        end = time.monotonic() + timeout
        while not finished.is_set() and time.monotonic() < end:
            if stop_when():
                met.set()
                break
            time.sleep(0.02)
        if not finished.is_set():  # met, or out of time: stop it either way
            signalled.append(time.monotonic())
            os.kill(os.getpid(), signal.SIGTERM)

    previous = signal.signal(signal.SIGTERM, lambda signum, frame: None)
    watcher = threading.Thread(target=watch, daemon=True)
    try:
        capsys.readouterr()
        watcher.start()
        try:
            code = main(["live", *OVAL, *map(str, args)])
        finally:
            finished.set()
            watcher.join()
        returned = time.monotonic()
    finally:
        signal.signal(signal.SIGTERM, previous)
    out, err = capsys.readouterr()
    assert met.is_set(), f"live ended (exit {code}) or ran {timeout:g} s without the awaited condition: {err}"
    return code, out, err, returned - signalled[0]
