"""``lap --controller-fmu`` against bad and faulty controller FMUs: exit 2 and one last ``error: …`` line naming the
FMU and what it did (see :mod:`bad_cli`). The faulty FMUs are the tests' own controller (tests/fmu/controller.c)
with one fault injected into its 100th step (t = 0.495 s): it hangs, segfaults, calls exit(0) or outputs NaN. Each
runs in a process of its own behind the twin's wall; Ctrl-C and SIGTERM end a lap whose FMU hangs at once."""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import threading
import time

import pytest

pytest.importorskip("fmpy")

from bad_cli import check_row  # noqa: E402
from fmu_helpers import build_controller, controller_processes, have_compiler  # noqa: E402
from twin.core import DigitalTwin  # noqa: E402
from twin.fmi.wall import STEP_LIMIT_S  # noqa: E402

pytestmark = pytest.mark.skipif(not have_compiler(), reason="the controller FMUs are compiled from C (gcc)")
FAULTS = ("hang", "segfault", "exit", "nan")
# (command line, exit status, words the one error line must hold)
ROWS = [
    ("lap --controller-fmu {hang}", 2, ["{hang}", f"hung for {STEP_LIMIT_S:g} s", "step at t = 0.495 s"]),
    ("lap --controller-fmu {segfault}", 2, ["{segfault}", "crashed with signal 11 (SIGSEGV)", "t = 0.495 s"]),
    ("lap --controller-fmu {exit} --json", 2, ["{exit}", "exited with status 0", "t = 0.495 s"]),
    ("lap --controller-fmu {nan}", 2, ["{nan}", "returned NaN at t = 0.495 s", "voltage_left"]),
    # not "no such file": what it is instead
    ("lap --controller-fmu {dir}", 2, ["{dir}", "is a folder, not a regular file"]),
    ("lap --controller-fmu {fifo}", 2, ["{fifo}", "is a FIFO, not a regular file"]),
    ("lap --controller-fmu {dir}/missing.fmu", 2, ["{dir}/missing.fmu", "no such file"]),
]


@pytest.fixture(scope="module")
def places(tmp_path_factory):
    d = tmp_path_factory.mktemp("controllers")
    twin = DigitalTwin()
    out = {f: build_controller(twin, str(d / f"{f}.fmu"), fault=f) for f in FAULTS}
    os.mkfifo(d / "fifo.fmu")
    return {**out, "dir": str(d), "fifo": str(d / "fifo.fmu")}


@contextlib.contextmanager
def watchdog(seconds: float):
    """End the whole test run (exit 1, with a word on stderr) if the block runs past ``seconds``: an FMU that hangs
    the twin's own thread cannot be interrupted from inside the process."""
    def expire():
        os.write(2, f"\nFAILED: the command still runs after {seconds:g} s: it hangs\n".encode())
        os._exit(1)

    timer = threading.Timer(seconds, expire)
    timer.daemon = True
    timer.start()
    try:
        yield
    finally:
        timer.cancel()


@pytest.mark.parametrize("line, status, words", ROWS, ids=[r[0] for r in ROWS])
def test_a_bad_controller_is_one_last_line(capfd, places, line, status, words):
    t0 = time.monotonic()
    with watchdog(STEP_LIMIT_S + 120):
        out = check_row(capfd, places, line, status, words)
    assert out == ""  # no half a document on stdout (--json), nothing the FMU printed
    assert time.monotonic() - t0 < STEP_LIMIT_S + 60


@pytest.mark.parametrize("signum, code", [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_a_hung_controller_ends_at_once_on_ctrl_c_or_sigterm(places, signum, code):
    p = subprocess.Popen([sys.executable, "-m", "twin.run", "lap", "--controller-fmu", places["hang"]],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline, hosts = time.monotonic() + 60, []
        while not hosts and time.monotonic() < deadline and p.poll() is None:
            time.sleep(0.05)
            hosts = controller_processes(p.pid)
        assert hosts, "the controller's process never started"
        time.sleep(1.0)  # it loads and steps 99 times well within this; then it hangs (for 5 s, at most)
        sent = time.monotonic()
        p.send_signal(signum)
        out, err = p.communicate(timeout=30)
        took = time.monotonic() - sent
    finally:
        p.kill()
    assert p.returncode == code, err
    assert "Traceback" not in err and "error:" not in err, err
    # waiting out the hang would take the rest of STEP_LIMIT_S (4-5 s); 3 s leaves a loaded machine room
    assert took < STEP_LIMIT_S - 2.0, f"it took {took:.1f} s to end"
    time.sleep(0.2)
    assert not any(os.path.exists(f"/proc/{h}") and open(f"/proc/{h}/stat").read().rsplit(")", 1)[1].split()[0] != "Z"
                   for h in hosts), "the controller's process outlived the twin"
