"""Every command against a table of bad inputs: exit status 2, one ``error: …`` line naming the input, no
traceback; and the phases that must end: calibration, start-up interrupts, orphaned workers."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from PIL import Image

from conftest import minimal_urdf
from live_helpers import Pumped
from twin.cli.main import main

PY = sys.executable
HEADER = {"type": "header", "format": "lf-telemetry", "version": 1, "dt_s": 0.005, "sensors": 8}
SAMPLES = ('{"type":"sample","t":0.1,"pos":3500,"seen":1,"wl":1,"wr":1}\n'
           '{"type":"sample","t":0.2,"pos":3500,"seen":1,"wl":1,"wr":1}\n')


@pytest.fixture(scope="module")
def bad(tmp_path_factory):
    """The bad inputs, made once: {name: path}."""
    d = tmp_path_factory.mktemp("bad")
    files = {}

    def put(name, data: bytes | str):
        p = d / name
        p.write_bytes(data if isinstance(data, bytes) else data.encode())
        files[name] = str(p)

    put("deep.json", "[" * 100_000 + "]" * 100_000)
    put("long_number.json", '{"control.kp": ' + "9" * 5000 + "}")
    put("not_json.json", "{control.kp: 3")
    put("list.json", "[1, 2]")
    put("non_gain.json", '{"gains": {"motion.mu": 0.5}}')
    put("user.rrd", b"my own notes")
    put("user.json", '{"mine": true}')
    put("user.xml", "<mujoco/>")
    put("not_a_png.png", b"not a png at all")
    put("tel_binary.jsonl", bytes(range(256)) * 4)
    put("tel_latin1.jsonl", json.dumps({**HEADER, "track": "ov\u00e9l"}, ensure_ascii=False).encode("latin-1") + b"\n" + SAMPLES.encode())
    put("tel_gains_abc.jsonl", json.dumps({**HEADER, "gains": {"control.kp": "abc"}}) + "\n" + SAMPLES)
    put("tel_gains_null.jsonl", json.dumps({**HEADER, "gains": None}) + "\n" + SAMPLES)
    put("tel_gains_mu.jsonl", json.dumps({**HEADER, "gains": {"motion.mu": 0.3}}) + "\n" + SAMPLES)
    put("tel_track_123.jsonl", json.dumps({**HEADER, "track": 123}) + "\n" + SAMPLES)
    put("urdf_garbage.urdf", "<robot><link name='a'>")
    put("urdf_cycle.urdf", """<robot name="c"><link name="a"/><link name="b"/>
        <joint name="j" type="fixed"><parent link="a"/><child link="a"/></joint></robot>""")
    mesh_robot = minimal_urdf().replace('<cylinder radius="0.02" length="0.01"/>', '<mesh filename="wheel.stl"/>')
    put("wheel.stl", b"solid garbage\n this is not an STL at all")
    put("urdf_garbage_mesh.urdf", mesh_robot)
    put("urdf_tiny_wheel.urdf", minimal_urdf().replace('radius="0.02"', 'radius="1e-9"'))
    d.joinpath("big").mkdir()
    with open(d / "big" / "wheel.stl", "wb") as f:
        f.truncate(65_000_000)  # a sparse 65 MB file: refused by its size, never read
    (d / "big" / "robot.urdf").write_text(mesh_robot)
    files["urdf_big_mesh.urdf"] = str(d / "big" / "robot.urdf")
    white = np.full((400, 400), 255, np.uint8)
    Image.fromarray(white).save(d / "white.png", dpi=(254, 254))
    files["white.png"] = str(d / "white.png")
    ring = np.full((400, 400), 255, np.uint8)
    yy, xx = np.mgrid[:400, :400]
    r = np.hypot(yy - 200, xx - 200)
    ring[(r > 150) & (r < 160)] = 0
    Image.fromarray(ring).save(d / "dpi_1e8.png", dpi=(1e8, 1e8))
    files["dpi_1e8.png"] = str(d / "dpi_1e8.png")
    Image.fromarray(ring).save(d / "no_dpi.png")
    files["no_dpi.png"] = str(d / "no_dpi.png")
    noise = (np.random.default_rng(0).random((400, 400)) > 0.5).astype(np.uint8) * 255
    Image.fromarray(noise).save(d / "noise.png", dpi=(254, 254))
    files["noise.png"] = str(d / "noise.png")
    two = np.full((400, 800), 255, np.uint8)
    yy, xx = np.mgrid[:400, :800]
    for cx in (200, 600):
        rr_ = np.hypot(yy - 200, xx - cx)
        two[(rr_ > 150) & (rr_ < 160)] = 0
    Image.fromarray(two).save(d / "two_loops.png", dpi=(254, 254))
    files["two_loops.png"] = str(d / "two_loops.png")
    Image.new("1", (20000, 20000), 1).save(d / "huge.png", dpi=(254, 254))  # 20000² pixels, a small file
    files["huge.png"] = str(d / "huge.png")
    files["dir"] = str(d)
    files["missing_dir"] = str(d / "no" / "such")
    return files


# (args with {name} placeholders, text the one error line must contain)
CASES = [
    # lap: world, values, seed, outputs
    ("lap --track nowhere", "unknown track"),
    ("lap --seed 18446744073709551616", "outside"),
    ("lap --seed -1", "outside"),
    ("lap --lap-timeout nan", "outside"),
    ("lap --set control.kp=nan", "must be finite"),
    ("lap --set cad.Q=1", "unknown parameter address"),
    ("lap --set control.kp", "expected ADDRESS=VALUE"),
    ("lap --gains {deep.json}", "nested too deeply"),
    ("lap --gains {long_number.json}", "unreadable JSON"),
    ("lap --gains {not_json.json}", "not JSON"),
    ("lap --gains {list.json}", "expected an object"),
    ("lap --gains {non_gain.json}", "control.* parameters only"),
    ("lap --gains /dev/zero", "not a regular file"),
    ("lap --gains {missing_dir}/g.json", "no such"),
    ("lap --gains {dir}", "is a folder"),
    ("lap --robot {dir}", "{dir}"),
    ("lap --robot {urdf_garbage.urdf}", "well-formed"),
    ("lap --robot {urdf_cycle.urdf}", "{urdf_cycle.urdf}"),
    ("lap --robot {urdf_garbage_mesh.urdf}", "wheel.stl"),
    ("lap --robot {urdf_tiny_wheel.urdf}", "wheel radius"),
    ("lap --robot {urdf_big_mesh.urdf}", "MB limit"),
    ("lap --track {not_a_png.png}", "unreadable track image"),
    ("lap --track {white.png}", "{white.png}"),
    ("lap --track {dpi_1e8.png}", "{dpi_1e8.png}"),
    ("lap --track {no_dpi.png} --metres-per-pixel 1e-300", "{no_dpi.png}"),
    ("lap --track {noise.png}", "{noise.png}"),
    ("lap --track {two_loops.png}", "{two_loops.png}"),
    ("lap --track {huge.png}", "{huge.png}"),
    ("lap --save {missing_dir}/x.rrd", "does not exist"),
    ("lap --save {dir}", "is a folder"),
    ("lap --save /proc/line-follower-x.rrd", "cannot write"),
    ("lap --save {user.rrd}", "was not written by"),
    # tune
    ("tune --out {missing_dir}/g.json", "does not exist"),
    ("tune --out {user.json}", "was not written by"),
    ("tune --param cad.L", "rebuilds"),
    ("tune --param control.cal_sweeps", "whole-number"),
    ("tune --bounds control.kp=1", "expected LOWER,UPPER"),
    ("tune --bounds control.kp=60,1", "inverted"),
    ("tune --max-iter 0", "outside"),
    ("tune --workers -1", "outside"),
    # align
    ("align", "give either"),
    ("align --measured-lap-time 7 --param motion.mu --param motor.R_M", "one parameter"),
    ("align --telemetry {tel_binary.jsonl}", "not UTF-8"),
    ("align --telemetry {tel_latin1.jsonl}", "not UTF-8"),
    ("align --telemetry {tel_gains_abc.jsonl}", "must be a finite number"),
    ("align --telemetry {tel_gains_null.jsonl}", "gains"),
    ("align --telemetry {tel_gains_mu.jsonl}", "control.* parameters only"),
    ("align --telemetry {tel_track_123.jsonl}", "track"),
    ("align --telemetry /dev/zero", "not a regular file"),
    ("align --measured-lap-time 7 --out {dir}", "is a folder"),
    # design
    ("design --out-dir {user.json}", "is a file"),
    ("design --out-dir {missing_dir}/study", "does not exist"),
    ("design --grid cad.L=0.04,0.04", "given twice"),
    ("design --grid control.kp=5,9", "gains are tuned"),
    ("design --grid motor.model=nope", "not in the motor catalogue"),
    # record, emulate, live
    ("record --out {dir}", "is a folder"),
    ("emulate --tcp 99999", "outside"),
    ("emulate --speed 1e-300", "outside"),
    ("emulate --speed nan", "outside"),
    ("live --duration nan --port loop://", "outside"),
    ("live", "--port"),
    ("live --replay {missing_dir}/log", "no such"),
    # view, build, graph, generate, convert
    ("view {user.rrd}", "not a rerun recording"),
    ("view {missing_dir}/x.rrd", "no such recording"),
    ("build -o {missing_dir}/w.xml", "does not exist"),
    ("build -o {user.xml}", "was not written by"),
    ("graph --set x", "expected ADDRESS=VALUE"),
    ("generate --out-dir .", "current folder"),
    ("generate --out-dir {dir}/r --set cad.R=0", "cad.R"),
    ("generate --out-dir {dir}/r --set motion.mu=1", "not a CAD parameter"),
    ("convert {missing_dir}/r.urdf -o {dir}/w.xml", "not found"),
    ("convert {dir} -o {dir}/w.xml", "{dir}"),
]


def fill(text: str, files: dict) -> str:
    return re.sub(r"\{([^}]+)\}", lambda m: files[m.group(1)], text)


@pytest.mark.parametrize("args, needle", CASES, ids=[c[0] for c in CASES])
def test_bad_input_is_one_line_and_exit_2(bad, args, needle, capsys):
    assert main([fill(a, bad) for a in args.split()]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    err = [e for e in err if not e.startswith("warning: ")]
    assert len(err) == 1 and err[0].startswith("error: "), err
    assert fill(needle, bad) in err[0]


def test_a_fresh_process_never_shows_a_traceback(bad):
    for args in (["lap", "--track", bad["huge.png"]], ["align", "--telemetry", bad["tel_binary.jsonl"]],
                 ["lap", "--robot", bad["urdf_cycle.urdf"]]):
        r = subprocess.run([PY, "-m", "twin.run", *args], capture_output=True, text=True, timeout=120)
        assert r.returncode == 2 and "Traceback" not in r.stderr and r.stderr.count("\n") == 1, r.stderr


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
