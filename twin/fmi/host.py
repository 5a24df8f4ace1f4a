"""The far side of the wall (:mod:`twin.fmi.wall`): a child process that loads one controller FMU with fmpy and steps
it on request, so that a step that hangs, crashes or calls ``exit`` takes only this process with it.

Run as ``python -m twin.fmi.host SETUP_JSON`` by the wall, never by hand. It reads requests on file descriptor
``request_fd`` and answers on ``reply_fd`` (:mod:`twin.fmi.protocol`): laps one after another, each on a fresh
instance extracted into the folder the twin names (so the FMU's library is loaded anew), stepped on request. The
wall makes its stdout the twin's stderr (a foreign library's prints never reach the twin's JSON). It dies with the
twin (Linux's PR_SET_PDEATHSIG), ignores Ctrl-C (the twin ends it), and at the end of the requests terminates and
frees the FMU and exits 0.
"""

from __future__ import annotations

import ctypes
import json
import logging
import os
import resource
import signal
import sys
from types import SimpleNamespace

from twin.fmi import protocol


def _die_with_parent(parent_pid: int) -> None:
    try:
        ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGKILL)  # 1: PR_SET_PDEATHSIG
    except (OSError, AttributeError):  # not Linux: the end of the requests still ends it
        pass
    if os.getppid() != parent_pid:  # the parent died before the line above
        os._exit(1)


def _open(setup: dict, md, folder: str):
    """A fresh instance of the FMU extracted into ``folder``: the session, or the error line to send."""
    from twin.errors import TwinError
    from twin.fmi.session import ControllerSession

    controller = SimpleNamespace(path=setup["path"], md=md, fmi_version=setup["fmi_version"],
                                 sense=dict(setup["sense"]), drive=dict(setup["drive"]),
                                 parameters=[tuple(p) for p in setup["parameters"]])
    try:
        return ControllerSession(controller, folder), None
    except TwinError as e:
        return None, str(e)
    except Exception as e:  # fmpy's own errors: one line all the same
        return None, f"--controller-fmu {setup['path']}: it failed to load ({' '.join(str(e).split())[:200]})"


def serve(setup: dict) -> int:
    """Answer the twin's requests: a lap opens a fresh instance of the FMU (closing the lap before), a step steps
    it; the end of the requests closes it. A failed call is sent as its error line, and ends this process."""
    from fmpy import read_model_description

    from twin.errors import TwinError

    requests, replies = setup["request_fd"], setup["reply_fd"]
    names = [name for name, _ in setup["sense"]]  # the FMU's inputs, in the order their values come
    layout = protocol.request(len(names))
    md, session = None, None
    try:
        while (kind := protocol.read_exact(requests, 1)) is not None:
            if kind == protocol.LAP:
                (n,) = protocol.LENGTH.unpack(protocol.read_exact(requests, protocol.LENGTH.size) or b"\0" * 4)
                folder = (protocol.read_exact(requests, n) or b"").decode("utf-8")
                if session is not None:
                    session, old = None, session
                    old.close()
                if md is None:
                    md = read_model_description(setup["path"], validate=False)
                session, why = _open(setup, md, folder)
                if session is None:
                    protocol.send_error(replies, why)
                    return 0
                protocol.send_ready(replies)
                continue
            raw = protocol.read_exact(requests, layout.size)
            if raw is None or kind != protocol.STEP or session is None:
                return 1  # not the protocol: the twin sees this process end
            t, h, *values = layout.unpack(raw)
            try:
                left, right = session.step(t, h, dict(zip(names, values)))
            except TwinError as e:
                protocol.send_error(replies, str(e))
                return 0
            protocol.send_outputs(replies, left, right)
    finally:
        if session is not None:
            session.close()
    return 0


def main(argv: list[str]) -> int:
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the twin's to handle: it ends this process
    resource.setrlimit(resource.RLIMIT_CORE, (0, 0))  # a crashing FMU leaves no core file in the user's folder
    setup = json.loads(argv[0])
    _die_with_parent(setup["parent_pid"])
    logging.basicConfig(stream=sys.stderr, level=setup["log_level"], format="%(levelname)s %(name)s: %(message)s")
    return serve(setup)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
