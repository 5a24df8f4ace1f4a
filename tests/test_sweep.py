"""Sensitivity sweeps: every grid point × seed in one batch, equal to laps run alone; outputs that agree."""

from __future__ import annotations

import csv
import json
import time

import numpy as np
import pytest

from twin.cli.main import main
from twin.core.closed_loop import run_laps
from twin.core.digital_twin import DigitalTwin
from twin.errors import TwinError
from tuner.studies.sweep import Axis, sweep


@pytest.mark.quick
def test_points_are_the_laps_run_one_by_one():
    twin = DigitalTwin(track="oval")
    points = sweep(twin, [Axis("motion.mu", 0.3, 0.9, 3)], seeds=[0, 4])
    assert [p.values["motion.mu"] for p in points] == pytest.approx([0.3, 0.6, 0.9], abs=1e-12)  # evenly spaced, by hand
    for p in points:
        alone = [run_laps(twin, [p.values], seed=s, keep_traces=False)[0] for s in (0, 4)]
        assert p.lap_times_s == tuple(r.lap_time_s for r in alone if r.completed)
        assert p.max_cross_track_m == max(r.max_cross_track_m for r in alone)


OVAL_LENGTH_M = 2 * 1.2 + 2 * np.pi * 0.4  # by hand: two 1.2 m straights, two half circles of 0.4 m
TOP_SPEED_MPS = 720 * 2 * np.pi / 60 * 0.016  # 720 rpm no-load (Pololu #2369 at 6 V) on 16 mm wheels: 1.206 m/s


def test_one_parameter_sweep_writes_agreeing_csv_json_and_a_chart(tmp_path, capsys):
    """v_max from 0 to 1.5 m/s on the oval. At 0 the robot never leaves the start line (Eq. 10: v ≤ v_max), so
    its laps end at the 60 s timeout; above 0 they complete, faster the higher v_max is, and never faster than
    the track length at min(v_max, the wheels' no-load speed)."""
    out = tmp_path / "sweep"
    assert main(["sweep", "control.v_max=0:1.5:4", "--track", "oval", "--seeds", "2", "--out-dir", str(out),
                 "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    rows = list(csv.DictReader(open(out / "sweep.csv")))
    saved = json.loads((out / "sweep.json").read_text())
    assert len(rows) == len(doc["points"]) == len(saved["points"]) == 4
    for row, point in zip(rows, saved["points"]):
        assert float(row["control.v_max"]) == point["control.v_max"]
        assert float(row["completion_rate"]) == point["completion_rate"]
    assert (out / "sweep.png").read_bytes()[:4] == b"\x89PNG"
    points = doc["points"]
    assert [p["control.v_max"] for p in points] == pytest.approx([0.0, 0.5, 1.0, 1.5], abs=1e-12)
    assert [p["completion_rate"] for p in points] == [0.0, 1.0, 1.0, 1.0]  # the flag flips where v_max > 0
    assert points[0]["failures"] == "timeout" and points[0]["median_lap_time_s"] is None
    times = [p["median_lap_time_s"] for p in points[1:]]
    assert times[0] > times[1] > times[2]  # faster as v_max rises
    for p in points[1:]:
        assert p["min_lap_time_s"] >= OVAL_LENGTH_M / min(p["control.v_max"], TOP_SPEED_MPS)
        assert p["min_lap_time_s"] <= p["median_lap_time_s"] <= p["max_lap_time_s"]


@pytest.mark.quick
def test_two_parameter_sweep_makes_a_heat_map(tmp_path, capsys):
    """Tyre grip × steering gain on the oval at v_max = 0.6 m/s: the 0.4 m bends need v²/r = 0.9 m/s², under a
    tenth of the grip μ·g for μ ≥ 0.4, so the tyres never slide and μ leaves the lap nearly unchanged: within 5e-4,
    because the tyres carry the ball caster's drag (motion.caster_mu) and MuJoCo's soft contacts creep a little more
    under a force at lower grip (measured 1.3e-4 at K_P 30; 1e-5 with a free caster, from the calibration turn's spin);
    a stiffer steering gain holds the line closer."""
    out = tmp_path / "map"
    assert main(["sweep", "motion.mu=0.4:0.9:2", "control.kp=10:30:2", "--track", "oval", "--seeds", "1",
                 "--out-dir", str(out), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert [(p["motion.mu"], p["control.kp"]) for p in doc["points"]] == [(0.4, 10), (0.4, 30), (0.9, 10), (0.9, 30)]
    assert (out / "sweep.png").stat().st_size > 10_000
    (lo_10, lo_30, hi_10, hi_30) = doc["points"]
    assert all(p["completion_rate"] == 1.0 for p in doc["points"])
    assert lo_10["median_lap_time_s"] == pytest.approx(hi_10["median_lap_time_s"], rel=5e-4)
    assert lo_30["median_lap_time_s"] == pytest.approx(hi_30["median_lap_time_s"], rel=5e-4)
    assert lo_30["max_cross_track_m"] < lo_10["max_cross_track_m"] and hi_30["max_cross_track_m"] < hi_10["max_cross_track_m"]
    for p in doc["points"]:
        assert p["median_lap_time_s"] >= OVAL_LENGTH_M / 0.6


@pytest.mark.parametrize("args, needle", [
    (["motion.mu=0.3:0.9:1"], "N must be at least 2"),
    (["motion.mu=0.9:0.3:4"], "must be below HI"),
    (["motion.mu=nan:0.9:4"], "must be finite"),
    (["motion.muu=0.3:0.9:4"], "unknown parameter address"),
    (["cad.L=0.03:0.05:3"], "rebuilds"),
    (["motion.mu=0.3-0.9"], "expected ADDRESS=LO:HI:N"),
    (["motion.mu=0.3:0.9:3", "motion.mu=0.3:0.9:3"], "the same parameter twice"),
    (["motion.mu=0.01:0.9:3"], "outside"),
])
def test_sweep_bad_input_is_one_line_and_exit_2(args, needle, capsys, tmp_path):
    assert main(["sweep", *args, "--track", "oval", "--out-dir", str(tmp_path / "s")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: ") and needle in err[0], err


@pytest.mark.parametrize("axes", [["motion.mu=0.5:1:1000000000"], ["motion.mu=0.5:1:10000000"],
                                  ["motion.mu=0.5:1:100000", "control.kp=10:30:100000"]])
def test_an_unbounded_sweep_is_refused_at_once(axes, capsys, tmp_path):
    """Counted before any grid is built: a billion points was killed for memory after 28 s without a word, and
    ten million were refused after 24 s."""
    t0 = time.monotonic()
    assert main(["sweep", *axes, "--out-dir", str(tmp_path / "s")]) == 2
    # counting is instant; 10 s (not 1 s) leaves a loaded 2-core machine room and still tells it from the 24 s before
    assert time.monotonic() - t0 < 10.0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: sweep: ") and "more than the 20,000" in err[0], err
