"""Commands against a table of bad flags and outputs: exit status 2, one ``error: …`` line naming the input, no
traceback (:mod:`bad_input`); and the phases that must end: calibration, start-up interrupts, orphaned workers.
Descriptions, tracks and value files have their own tables (``test_bad_descriptions``, ``test_bad_tracks``,
``test_bad_value_files``)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time

import pytest

from bad_input import BadFiles, check_bad_input
from live_helpers import Pumped

PY = sys.executable


@pytest.fixture(scope="module")
def bad(tmp_path_factory) -> BadFiles:
    """The bad inputs, made once."""
    files = BadFiles(tmp_path_factory.mktemp("bad"))
    files.put("user.rrd", b"my own notes")
    return files


# (args with {name} placeholders, text the one error line must contain)
CASES = [
    # lap: values, seed (descriptions, tracks, value files, outputs, the link and firmware: test_bad_<family>.py)
    ("lap --seed 18446744073709551616", "outside"),
    ("lap --seed -1", "outside"),
    ("lap --lap-timeout nan", "outside"),
    ("lap --set control.kp=nan", "must be finite"),
    ("lap --set cad.Q=1", "unknown parameter address"),
    ("lap --set control.kp", "expected ADDRESS=VALUE"),
    # tune
    ("tune --param cad.L", "rebuilds"),
    ("tune --param control.cal_sweeps", "whole-number"),
    ("tune --bounds control.kp=1", "expected LOWER,UPPER"),
    ("tune --bounds control.kp=60,1", "inverted"),
    ("tune --max-iter 0", "outside"),
    ("tune --workers -1", "outside"),
    # align
    ("align", "give either"),
    ("align --measured-lap-time 7 --param motion.mu --param motor.R_M", "one parameter"),
    # design
    ("design --grid cad.L=0.04,0.04", "given twice"),
    ("design --grid control.kp=5,9", "gains are tuned"),
    ("design --grid motor.model=nope", "not in the motor catalogue"),
    # view, graph, generate
    ("view {user.rrd}", "not a rerun recording"),
    ("view {missing_dir}/x.rrd", "no such recording"),
    ("graph --set x", "expected ADDRESS=VALUE"),
    # about 10 M laps (2.5-3 GB within 2 minutes) were accepted; sweep refuses over 20,000
    ("graph --learn --samples 1048576 --out-dir {dir}/g", "would run up to 10,"),
    ("graph --learn --samples 8192 --param motion.mu --out-dir {dir}/g", "24,600 laps, about"),
    # a range's ends in full (it said 1.04858e+06)
    ("graph --learn --samples 4000000", "outside [8, 1048576]"),
    ("lap --seed 99999999999999999999999", "outside [0, 18446744073709551615]"),
    ("generate --out-dir {dir}/r --set cad.R=0", "cad.R"),
    ("generate --out-dir {dir}/r --set motion.mu=1", "not a CAD parameter"),
]


@pytest.mark.parametrize("args, needle", CASES, ids=[c[0] for c in CASES])
def test_bad_input_is_one_line_and_exit_2(bad, args, needle, capsys):
    check_bad_input(args, needle, bad, capsys)


def test_an_endless_calibration_is_a_result_not_a_hang():
    t0 = time.monotonic()
    r = subprocess.run([PY, "-m", "twin.run", "lap", "--json", "--set", "control.full_speed=1", "--set",
                        "control.cal_duty=0.01", "--set", "control.cal_sweeps=10", "--set", "control.cal_sweep=3"],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    lap = json.loads(r.stdout)
    assert not lap["completed"] and lap["failure"] == "calibration"
    assert time.monotonic() - t0 < 30


@pytest.mark.parametrize("delay_s", [0.05, 0.2, 0.4, 0.6, 0.8, 1.2])
def test_ctrl_c_from_the_first_instant_is_clean(delay_s):
    """While the libraries load and while the lap runs: exit 130 and no traceback (0 or death by SIGINT with
    nothing on stderr: the lap had already finished and the process was on its way out). The delay counts from
    the program's first instant, when its first module has loaded (``-X importtime`` says so on stderr), not from
    the start of the process: on a busy machine Python's own start-up (site, .pth files) alone took over 50 ms,
    and a signal there is the interpreter's, before any of the program exists."""
    p = Pumped([PY, "-X", "importtime", "-m", "twin.run", "lap"])
    try:
        p.wait_line("stderr", lambda line: line.rstrip().endswith("| twin.cli.startup"), "the program's first module")
        time.sleep(delay_s)  # (the moment to interrupt: the parameter of this test, not a wait for something)
        p.proc.send_signal(signal.SIGINT)
        code, out, err = p.wait(timeout=120)
    finally:
        p.kill()
    assert "Traceback" not in err, err
    assert code == 130 or (code in (0, -signal.SIGINT) and "lap completed" in out), (code, err[-2000:])


def test_no_child_process_starts_while_the_libraries_load():
    """MuJoCo's OpenGL rendering (unused here) imports pyGLFW, which starts a Python child to probe GLFW; a Ctrl-C
    while it ran left that child a broken pipe and a traceback on our stderr. Unless the user picks a backend
    (MUJOCO_GL), start-up leaves rendering off and pyGLFW unimported, also when MuJoCo loads later, as a command
    starts its work (``graph`` builds a twin: it loads MuJoCo, and runs no lap)."""
    env = {k: v for k, v in os.environ.items() if k != "MUJOCO_GL"}
    r = subprocess.run([PY, "-X", "importtime", "-m", "twin.run", "graph", "--json"], capture_output=True, text=True,
                       timeout=120, env=env)
    assert r.returncode == 0, r.stderr[-2000:]
    assert "mujoco.rendering" in r.stderr  # the import trace is there, and MuJoCo's own rendering package loaded
    imported = {line.rsplit("|", 1)[-1].strip() for line in r.stderr.splitlines() if line.startswith("import time:")}
    assert "mujoco.rendering.classic.gl_context" in imported  # MuJoCo looked for a backend, and
    assert "glfw" not in imported  # found it turned off


def test_design_workers_die_with_their_parent(tmp_path):
    p = subprocess.Popen([PY, "-m", "twin.run", "design", "--track", "oval", "--grid", "cad.S=0.05,0.06,0.07",
                          "--laps", "50", "--workers", "2", "--out-dir", str(tmp_path / "study"), "-q"],
                         stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    children = []
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and len(children) < 2:
        time.sleep(0.5)
        children = _children(p.pid)
    assert children, "the study started no workers"
    p.kill()  # SIGKILL: the parent cannot clean up; the workers must notice on their own
    p.wait(timeout=10)
    deadline = time.monotonic() + 15
    while time.monotonic() < deadline and any(_alive(c) for c in children):
        time.sleep(0.2)
    assert not any(_alive(c) for c in children)


def _children(pid: int) -> list[int]:
    out = []
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                with open(f"/proc/{entry}/stat") as f:
                    fields = f.read().rsplit(")", 1)[1].split()
            except OSError:
                continue
            if int(fields[1]) == pid:
                out.append(int(entry))
    return out


def _alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False
