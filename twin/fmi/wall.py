"""Foreign code behind a wall: a controller FMU runs in a process of its own (:mod:`twin.fmi.host`), stepped over two
pipes (:mod:`twin.fmi.protocol`), so that whatever it does cannot take the twin with it.

Each fault ends the lap with one TwinError line naming the FMU and what it did: a step that does not return within
``step_limit_s`` wall seconds (the process is killed: "hung for 5 s"), a crash ("crashed with signal 11
(SIGSEGV)"), an ``exit`` ("exited with status 0"), an output that is not finite ("returned NaN at t = … s"), and an
FMI call that failed (its own message). The twin waits for the controller in ``poll``, so Ctrl-C and SIGTERM reach
it at once; leaving the ``with`` block on an exception kills the process at once, and the process dies with the
twin however the twin dies (Linux's PR_SET_PDEATHSIG). A well-behaved FMU gives the very outputs it gives in
process: the inputs and outputs cross as float64, bit for bit.
"""

from __future__ import annotations

import json
import logging
import math
import os
import select
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


class WalledController:
    """A controller FMU in its own process; start it early (loading overlaps the twin's own work), step it, close it.

    Args:
      controller: the checked and mapped :class:`twin.fmi.controller.ControllerFmu`.
      step_limit_s: wall seconds one step may take before the FMU counts as hung.
      load_limit_s: wall seconds the process may take to load and initialise the FMU.
    """

    def __init__(self, controller, step_limit_s: float = STEP_LIMIT_S, load_limit_s: float = LOAD_LIMIT_S):
        self.path, self.step_limit_s, self.load_limit_s = controller.path, step_limit_s, load_limit_s
        self.ports = list(controller.sense.values())  # the inputs' twin ports, in the order the host maps them
        self.outputs = [controller.drive[p] for p in sorted(controller.drive)]  # *_left before *_right
        self._layout = protocol.request(len(self.ports))
        self._ready = False
        self._folder = tempfile.TemporaryDirectory(prefix="twin-controller-")
        requests_in, self._requests = os.pipe()
        self._replies, replies_out = os.pipe()
        setup = {"path": os.path.abspath(self.path), "folder": self._folder.name, "fmi_version": controller.fmi_version,
                 "sense": list(controller.sense.items()), "drive": dict(controller.drive),
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
            self._folder.cleanup()
            raise TwinError(f"--controller-fmu {self.path}: cannot start its process ({e.strerror or e})") from None
        finally:
            os.close(requests_in)
            os.close(replies_out)
        self._poll = select.poll()
        self._poll.register(self._replies, select.POLLIN | select.POLLHUP | select.POLLERR)

    # --- the protocol, with deadlines ------------------------------------------------------------------------------

    def _read(self, n: int, deadline: float, doing: str, limit_s: float) -> bytes:
        parts, got = [], 0
        while got < n:
            left_ms = (deadline - time.monotonic()) * 1000.0
            if left_ms <= 0 or not self._poll.poll(max(1, math.ceil(left_ms))):
                if time.monotonic() < deadline:
                    continue
                self._kill()
                raise TwinError(f"--controller-fmu {self.path}: hung for {limit_s:g} s {doing} without returning "
                                "(its process was stopped)")
            chunk = os.read(self._replies, n - got)
            if not chunk:
                raise self._died(doing)
            parts.append(chunk)
            got += len(chunk)
        return b"".join(parts)

    def _reply(self, doing: str, limit_s: float) -> bytes:
        """(the next reply's kind, its deadline); an error reply is raised as its TwinError line."""
        deadline = time.monotonic() + limit_s
        kind = self._read(1, deadline, doing, limit_s)
        if kind == protocol.ERROR:
            (n,) = protocol.LENGTH.unpack(self._read(protocol.LENGTH.size, deadline, doing, limit_s))
            text = self._read(n, deadline, doing, limit_s).decode("utf-8", "replace")
            self._kill()
            raise TwinError(text)
        if kind not in (protocol.READY, protocol.OUTPUTS):
            self._kill()
            raise TwinError(f"--controller-fmu {self.path}: its process answered {kind!r} {doing}, not the protocol")
        return kind, deadline

    def _died(self, doing: str) -> TwinError:
        try:
            code = self.process.wait(CLOSE_LIMIT_S)
        except subprocess.TimeoutExpired:
            self._kill()
            return TwinError(f"--controller-fmu {self.path}: closed its pipe {doing}")
        if code < 0:
            what = f"crashed with signal {-code} ({_signal_name(-code)})"
        else:
            what = f"exited with status {code}"
        return TwinError(f"--controller-fmu {self.path}: {what} {doing}; a controller FMU must return to the twin")

    # --- the face ---------------------------------------------------------------------------------------------------

    def wait_ready(self) -> None:
        """Wait until the FMU is loaded and initialised; its refusal, crash or hang is one TwinError line."""
        if not self._ready:
            kind, _ = self._reply("while loading", self.load_limit_s)
            if kind != protocol.READY:
                self._kill()
                raise TwinError(f"--controller-fmu {self.path}: its process answered before it was ready")
            self._ready = True

    def step(self, t: float, h: float, values: Sequence[float]) -> tuple[float, float]:
        """Step the FMU from ``t`` to ``t + h`` [s] on ``values`` (of :attr:`ports`, in order): its (left, right)
        outputs."""
        self.wait_ready()
        doing = f"in its step at t = {t:.6g} s"
        try:
            os.write(self._requests, self._layout.pack(t, h, *values))
        except BrokenPipeError:  # it died after its last answer
            raise self._died(doing) from None
        kind, deadline = self._reply(doing, self.step_limit_s)
        if kind != protocol.OUTPUTS:
            self._kill()
            raise TwinError(f"--controller-fmu {self.path}: its process answered out of turn {doing}")
        left, right = protocol.OUT.unpack(self._read(protocol.OUT.size, deadline, doing, self.step_limit_s))
        for name, value in zip(self.outputs, (left, right)):
            if not math.isfinite(value):
                shown = "NaN" if math.isnan(value) else repr(value)
                raise TwinError(f"--controller-fmu {self.path}: returned {shown} at t = {t:.6g} s (its output {name}); "
                                "a controller's outputs must be finite numbers")
        return left, right

    def _kill(self) -> None:
        if self.process.poll() is None:
            self.process.kill()
        self.process.wait()

    def _close_fds(self) -> None:
        for fd in (self._requests, self._replies):
            try:
                os.close(fd)
            except OSError:
                pass

    def close(self, at_once: bool = False) -> None:
        """End the FMU's process: at the end of the requests it terminates and frees the FMU (it is killed if that
        takes over ``CLOSE_LIMIT_S``); ``at_once`` kills it now. Its extracted files are removed."""
        try:
            os.close(self._requests)
        except OSError:
            pass
        try:
            if at_once:
                self._kill()
            else:
                try:
                    self.process.wait(CLOSE_LIMIT_S)
                except subprocess.TimeoutExpired:
                    self._kill()
        finally:
            try:
                os.close(self._replies)
            except OSError:
                pass
            self._folder.cleanup()

    def __enter__(self) -> "WalledController":
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        self.close(at_once=exc_type is not None)
