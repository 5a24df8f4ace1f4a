"""Design studies on a real Ray cluster (a local head started with ``ray start --head``, 2 CPUs): the result
equals the local run's, design for design; a design whose worker is killed mid-task is retried, never lost and
never counted twice. Skipped without Ray, except in CI (``CI`` set), where Ray is part of the test extra."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import threading
import time

import pytest

if os.environ.get("CI"):
    import ray  # noqa: F401  (in CI a missing package fails instead of skipping)
else:
    pytest.importorskip("ray")

from tuner.studies.cluster import local_head, study_on_ray
from tuner.studies.design import grid, study

# every test here holds the machine's Ray lock (conftest.one_ray_head): under pytest -n 2 the other process's Ray
# users (bench_cluster's run) wait, since 'ray stop --force' stops every head and 'auto' joins whichever is there
pytestmark = pytest.mark.usefixtures("one_ray_head")

RUN = [sys.executable, "-m", "twin.run"]
DESIGNS = {"cad.S": (0.05, 0.07)}
SMALL = ["--track", "oval", "--laps", "2", "--max-iter", "2"]
BASE = {"track": "oval", "metres_per_pixel": None, "values": {}}


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture
def head(one_ray_head, tmp_path_factory):
    """A local Ray head with 2 CPUs, serving Ray Client too; yields its ray:// address; stopped after the test (a
    head per test: a module's head would hold the machine's Ray lock while this process runs other modules' tests)."""
    with local_head(2, str(tmp_path_factory.mktemp("ray")), client_port=_free_port()) as client:
        yield client


def comparable(designs: list[dict]) -> list[dict]:
    return [{k: d[k] for k in ("design", "ok", "median_lap_time_s", "laps_completed", "mean_cross_track_m", "gains")}
            for d in designs]


def test_a_study_on_the_cluster_equals_the_local_one(head, tmp_path):
    local = subprocess.run([*RUN, "design", *SMALL, "--grid", "cad.S=0.05,0.07", "--workers", "1", "--json", "-q",
                            "--out-dir", tmp_path / "local"], capture_output=True, text=True, timeout=600)
    assert local.returncode == 0, local.stderr
    ray_run = subprocess.run([*RUN, "design", *SMALL, "--grid", "cad.S=0.05,0.07", "--cluster", "auto", "--json", "-q",
                              "--out-dir", tmp_path / "ray"], capture_output=True, text=True, timeout=600)
    assert ray_run.returncode == 0, ray_run.stderr
    a, b = json.loads(local.stdout)["designs"], json.loads(ray_run.stdout)["designs"]
    assert len(a) == 2 and all(d["ok"] for d in a)
    assert comparable(a) == comparable(b)


def test_a_sweep_on_the_cluster_equals_the_local_one(head, tmp_path):
    """One Ray task per grid point: the points' laps equal the local one-batch sweep's, point for point."""
    args = ["sweep", "control.v_max=0.5:0.9:3", "--track", "oval", "--seeds", "2", "--json"]
    local = subprocess.run([*RUN, *args, "--out-dir", tmp_path / "local"], capture_output=True, text=True, timeout=600)
    assert local.returncode == 0, local.stderr
    ray_run = subprocess.run([*RUN, *args, "--cluster", "auto", "--out-dir", tmp_path / "ray"], capture_output=True,
                             text=True, timeout=600)
    assert ray_run.returncode == 0, ray_run.stderr
    a, b = json.loads(local.stdout)["points"], json.loads(ray_run.stdout)["points"]
    assert len(a) == 3 and a == b
    assert len({p["median_lap_time_s"] for p in a}) == 3  # the points differ: an order mix-up would show


def test_a_sweep_through_ray_client_equals_the_local_one_line_for_line(head, tmp_path):
    """--cluster ray://HOST:PORT (Ray Client, the 'cluster' extra's ray[client]): the same sweep.csv, line for line."""
    args = ["sweep", "control.kp=10:20:2", "--track", "oval", "--seeds", "2"]
    local = subprocess.run([*RUN, *args, "--out-dir", tmp_path / "local"], capture_output=True, text=True, timeout=600)
    assert local.returncode == 0, local.stderr
    remote = subprocess.run([*RUN, *args, "--cluster", head, "--out-dir", tmp_path / "client"], capture_output=True,
                            text=True, timeout=600)
    assert remote.returncode == 0, remote.stderr
    lines = (tmp_path / "local" / "sweep.csv").read_text().splitlines()
    assert len(lines) == 3 and lines == (tmp_path / "client" / "sweep.csv").read_text().splitlines()


def test_a_sweep_on_the_cluster_refuses_files_the_nodes_cannot_read(tmp_path):
    from PIL import Image, ImageDraw

    png = tmp_path / "ring.png"  # a good track, but a file on this machine only
    image = Image.new("L", (1000, 1000), 255)
    ImageDraw.Draw(image).ellipse((100, 100, 900, 900), outline=0, width=19)
    image.save(png)
    r = subprocess.run([*RUN, "sweep", "motion.mu=0.5:0.9:2", "--track", str(png), "--metres-per-pixel", "0.001",
                        "--cluster", "auto", "--out-dir", tmp_path / "s"], capture_output=True, text=True, timeout=300)
    assert r.returncode == 2 and r.stderr.count("\n") == 1, r.stderr
    assert "is an image" in r.stderr and not (tmp_path / "s").exists()


def _task_pids() -> list[int]:
    """Ray workers running a design (Ray titles a busy worker's process ``ray::_task``)."""
    out = subprocess.run(["ps", "-eo", "pid=,args="], capture_output=True, text=True).stdout
    return [int(line.split()[0]) for line in out.splitlines() if "ray::_task" in line and "grep" not in line]


def test_a_killed_worker_is_retried_and_counted_once(head):
    import ray

    designs = grid(DESIGNS)
    expected = study(designs, BASE, laps=2, max_iter=2, workers=1)
    killed: list[int] = []

    def killer():
        deadline = time.monotonic() + 120
        while not killed and time.monotonic() < deadline:
            pids = _task_pids()
            if pids:
                time.sleep(1.0)  # well inside the design's work
                os.kill(pids[0], signal.SIGKILL)
                killed.append(pids[0])
            time.sleep(0.05)

    t = threading.Thread(target=killer, daemon=True)
    t.start()
    seen = []
    try:
        got = study_on_ray(designs, BASE, 2, 2, "auto", on_done=seen.append)
    finally:
        ray.shutdown()
    t.join(timeout=5)
    assert killed, "no design task was seen running"
    assert len(seen) == len(designs)  # each design reported once
    for e, g in zip(expected, got):
        assert (g.design, g.ok, g.gains, g.lap_times_s, g.mean_cross_track_m) == \
            (e.design, e.ok, e.gains, e.lap_times_s, e.mean_cross_track_m)


@pytest.mark.parametrize("address, why", [("ray://127.0.0.1:1", "no Ray cluster there"),
                                          ("ray://127.0.0.1:port", "not a ray://HOST:PORT address"),
                                          ("ray://:10001", "no host in it")])
def test_no_cluster_is_one_line_exit_2(tmp_path, address, why):
    """Nothing listens at port 1 (refused before Ray Client's own ~30 s of retries); the others are not addresses."""
    r = subprocess.run([*RUN, "design", *SMALL, "--cluster", address, "--out-dir", tmp_path / "d"],
                       capture_output=True, text=True, timeout=180)
    assert r.returncode == 2 and r.stderr.strip().startswith(f"error: --cluster {address}: {why}"), r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and not (tmp_path / "d").exists()
