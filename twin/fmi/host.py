"""The far side of the wall (:mod:`twin.fmi.wall`): a child process that loads one controller FMU with fmpy and steps
it on request, so that a step that hangs, crashes or calls ``exit`` takes only this process with it.

Run as ``python -m twin.fmi.host SETUP_JSON`` by the wall, never by hand. It reads requests on file descriptor
``request_fd`` and answers on ``reply_fd`` (:mod:`twin.fmi.protocol`); the wall makes its stdout the twin's stderr
(a foreign library's prints never reach the twin's JSON). It dies with the twin (Linux's PR_SET_PDEATHSIG), ignores Ctrl-C
(the twin ends it), and at the end of the requests terminates and frees the FMU and exits 0.
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


def serve(setup: dict) -> int:
    """Load the FMU that ``setup`` names, answer its step requests, and close it at the end of the requests."""
    from fmpy import read_model_description

    from twin.errors import TwinError
    from twin.fmi.session import ControllerSession

    requests, replies = setup["request_fd"], setup["reply_fd"]
    try:
        md = read_model_description(setup["path"], validate=False)
        controller = SimpleNamespace(path=setup["path"], md=md, fmi_version=setup["fmi_version"],
                                     sense=dict(setup["sense"]), drive=dict(setup["drive"]))
        session = ControllerSession(controller, setup["folder"])
    except TwinError as e:
        protocol.send_error(replies, str(e))
        return 0
    except Exception as e:  # fmpy's own errors: one line all the same
        protocol.send_error(replies, f"--controller-fmu {setup['path']}: it failed to load ({' '.join(str(e).split())[:200]})")
        return 0
    ports = [port for _, port in setup["sense"]]
    protocol.send_ready(replies)
    try:
        while (request := protocol.read_request(requests, len(ports))) is not None:
            t, h, values = request
            try:
                left, right = session.step(t, h, dict(zip(ports, values)))
            except TwinError as e:
                protocol.send_error(replies, str(e))
                return 0
            protocol.send_outputs(replies, left, right)
    finally:
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
