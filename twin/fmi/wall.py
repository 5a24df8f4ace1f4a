"""Foreign code behind a wall: a controller FMU runs in a process of its own (:mod:`twin.fmi.host`), stepped over two
pipes (:mod:`twin.fmi.protocol`), so that whatever it does cannot take the twin with it.

Each fault ends the lap with one TwinError line naming the FMU and what it did: a step that does not return within
``step_limit_s`` wall seconds (the process is killed: "hung for 5 s"), a crash ("crashed with signal 11
(SIGSEGV)"), an ``exit`` ("exited with status 0"), an output that is not finite ("returned NaN at t = … s"), and an
FMI call that failed (its own message). The twin waits for the controller in ``poll``, so Ctrl-C and SIGTERM reach
it at once; leaving a lap on an exception kills the process at once, and the process dies with the twin however the
twin dies (Linux's PR_SET_PDEATHSIG). A well-behaved FMU gives the very outputs it gives in process: the inputs and
outputs cross as float64, bit for bit.

One process (:class:`ControllerHost`) serves one controller's laps one after another, each on a fresh instance
extracted afresh (its library loaded anew: no state of one lap reaches the next); it starts once, so a second lap
does not pay for Python and fmpy again. :class:`WalledController` is one lap's view of it.
"""

from __future__ import annotations

import json
import logging
import math
import os
import select
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from typing import Sequence

from twin.errors import TwinError
from twin.fmi import protocol

STEP_LIMIT_S = 5.0  # [s] wall time one step of the controller may take
LOAD_LIMIT_S = 60.0  # [s] wall time its process may take to start, load and initialise the FMU
CLOSE_LIMIT_S = 2.0  # [s] wall time it may take to terminate and free the FMU at the end
_ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # where the twin package is


def _signal_name(number: int) -> str:
    try:
        return signal.Signals(number).name
    except ValueError:
        return "unknown"


class ControllerHost:
    """The process a controller FMU runs in, and the protocol with deadlines; any fault kills it (then
    :attr:`alive` is False) and is raised as one TwinError line.

    Args:
      controller: the checked and mapped :class:`twin.fmi.controller.ControllerFmu`.
      step_limit_s: wall seconds one step may take before the FMU counts as hung.
      load_limit_s: wall seconds the process may take to load and initialise the FMU.
    """

    def __init__(self, controller, step_limit_s: float = STEP_LIMIT_S, load_limit_s: float = LOAD_LIMIT_S):
        self.path, self.step_limit_s, self.load_limit_s = controller.path, step_limit_s, load_limit_s
        self.ports = list(controller.sense.values())  # the inputs' twin ports, in the order their values cross
        self.outputs = [controller.drive[p] for p in sorted(controller.drive)]  # *_left before *_right
        self._layout = protocol.request(len(self.ports))
        self._folders: list[str] = []  # each lap's extracted FMU; removed once the process is done with them
        self._pending = 0  # laps asked for and not yet answered ready (a lap may end before its first step)
        requests_in, self._requests = os.pipe()
        self._replies, replies_out = os.pipe()
        setup = {"path": os.path.abspath(self.path), "fmi_version": controller.fmi_version,
                 "sense": list(controller.sense.items()), "drive": dict(controller.drive),
                 "parameters": [list(p) for p in controller.parameters],
                 "request_fd": requests_in, "reply_fd": replies_out, "parent_pid": os.getpid(),
                 "log_level": logging.getLogger("twin.fmi.controller").getEffectiveLevel()}
        env = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in (_ROOT, os.environ.get("PYTHONPATH")) if p)}
        try:
            # its own session: Ctrl-C at the terminal is the twin's, which then ends it; its stdout is our stderr
            self.process = subprocess.Popen([sys.executable, "-m", "twin.fmi.host", json.dumps(setup)],
                                            stdin=subprocess.DEVNULL, stdout=2,
                                            pass_fds=(requests_in, replies_out), start_new_session=True, env=env)
        except OSError as e:
            self._close_fds()
            raise TwinError(f"--controller-fmu {self.path}: cannot start its process ({e.strerror or e})") from None
        finally:
            os.close(requests_in)
            os.close(replies_out)
        self._poll = select.poll()
        self._poll.register(self._replies, select.POLLIN | select.POLLHUP | select.POLLERR)

    @property
    def alive(self) -> bool:
        return self.process.returncode is None and self._requests >= 0

    # --- the protocol, with deadlines ------------------------------------------------------------------------------

    def _read(self, n: int, deadline: float, doing: str, limit_s: float) -> bytes:
        parts, got = [], 0
        while got < n:
            left_ms = (deadline - time.monotonic()) * 1000.0
            if left_ms <= 0 or not self._poll.poll(max(1, math.ceil(left_ms))):
                if time.monotonic() < deadline:
                    continue
                self.kill()
                raise TwinError(f"--controller-fmu {self.path}: hung for {limit_s:g} s {doing} without returning "
                                "(its process was stopped)")
            chunk = os.read(self._replies, n - got)
            if not chunk:
                raise self._died(doing)
            parts.append(chunk)
            got += len(chunk)
        return b"".join(parts)

    def _reply(self, expected: bytes, doing: str, limit_s: float) -> float:
        """Wait for a reply of kind ``expected``; its deadline. An error reply is raised as its TwinError line."""
        deadline = time.monotonic() + limit_s
        kind = self._read(1, deadline, doing, limit_s)
        if kind == protocol.ERROR:
            (n,) = protocol.LENGTH.unpack(self._read(protocol.LENGTH.size, deadline, doing, limit_s))
            text = self._read(n, deadline, doing, limit_s).decode("utf-8", "replace")
            self.kill()
            raise TwinError(text)
        if kind != expected:
            self.kill()
            raise TwinError(f"--controller-fmu {self.path}: its process answered {kind!r} {doing}, out of the protocol")
        return deadline

    def _send(self, data: bytes, doing: str) -> None:
        try:
            protocol.write_all(self._requests, data)
        except BrokenPipeError:  # it died after its last answer
            raise self._died(doing) from None

    def _died(self, doing: str) -> TwinError:
        try:
            code = self.process.wait(CLOSE_LIMIT_S)
        except subprocess.TimeoutExpired:
            self.kill()
            return TwinError(f"--controller-fmu {self.path}: closed its pipe {doing}")
        self.kill()  # (reaped: this closes the pipes and removes the extracted files)
        what = f"crashed with signal {-code} ({_signal_name(-code)})" if code < 0 else f"exited with status {code}"
        return TwinError(f"--controller-fmu {self.path}: {what} {doing}; a controller FMU must return to the twin")

    # --- laps ------------------------------------------------------------------------------------------------------

    def begin_lap(self) -> None:
        """Ask for a fresh instance, extracted into a new folder, initialised at time 0 (awaited at the first step)."""
        folder = tempfile.mkdtemp(prefix="twin-controller-")
        self._folders.append(folder)
        self._pending += 1
        self._send(protocol.lap_request(folder), "while loading")

    def wait_ready(self) -> None:
        """Wait until this lap's instance is loaded and initialised; its refusal, crash or hang is one TwinError."""
        if self._pending:
            while self._pending:
                self._reply(protocol.READY, "while loading", self.load_limit_s)
                self._pending -= 1
            for folder in self._folders[:-1]:  # the earlier laps' instances are closed by now
                shutil.rmtree(folder, ignore_errors=True)
            del self._folders[:-1]

    def step(self, t: float, h: float, values: Sequence[float]) -> tuple[float, float]:
        """Step the FMU from ``t`` to ``t + h`` [s] on ``values`` (of :attr:`ports`, in order): its (left, right)
        outputs."""
        self.wait_ready()
        doing = f"in its step at t = {t:.6g} s"
        self._send(protocol.STEP + self._layout.pack(t, h, *values), doing)
        deadline = self._reply(protocol.OUTPUTS, doing, self.step_limit_s)
        left, right = protocol.OUT.unpack(self._read(protocol.OUT.size, deadline, doing, self.step_limit_s))
        for name, value in zip(self.outputs, (left, right)):
            if not math.isfinite(value):
                shown = "NaN" if math.isnan(value) else repr(value)
                raise TwinError(f"--controller-fmu {self.path}: returned {shown} at t = {t:.6g} s (its output {name}); "
                                "a controller's outputs must be finite numbers")
        return left, right

    # --- the end ---------------------------------------------------------------------------------------------------

    def _close_fds(self) -> None:
        for name in ("_requests", "_replies"):
            fd = getattr(self, name)
            if fd >= 0:
                try:
                    os.close(fd)
                except OSError:
                    pass
                setattr(self, name, -1)

    def _forget_folders(self) -> None:
        for folder in self._folders:
            shutil.rmtree(folder, ignore_errors=True)
        self._folders.clear()

    def kill(self) -> None:
        """End the process now (a fault, Ctrl-C, SIGTERM); remove the extracted files."""
        if self.process.poll() is None:
            self.process.kill()
        self.process.wait()
        self._close_fds()
        self._forget_folders()

    def close(self) -> None:
        """At the end of the requests the process terminates and frees the FMU and exits (killed if that takes over
        ``CLOSE_LIMIT_S``); the extracted files are removed."""
        if self._requests >= 0:
            os.close(self._requests)
            self._requests = -1
        try:
            self.process.wait(CLOSE_LIMIT_S)
        except subprocess.TimeoutExpired:
            pass
        self.kill()


class WalledController:
    """One lap of a controller FMU in its process (:class:`ControllerHost`): use it in a ``with`` block, which
    leaves the process for the next lap, or kills it when the lap ends in an exception (Ctrl-C included)."""

    def __init__(self, host: ControllerHost):
        self.host, self.ports = host, host.ports
        host.begin_lap()

    def wait_ready(self) -> None:
        self.host.wait_ready()

    def step(self, t: float, h: float, values: Sequence[float]) -> tuple[float, float]:
        return self.host.step(t, h, values)

    def __enter__(self) -> "WalledController":
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is not None:
            self.host.kill()
