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


def test_points_are_the_laps_run_one_by_one():
    twin = DigitalTwin(track="oval")
    points = sweep(twin, [Axis("motion.mu", 0.3, 0.9, 3)], seeds=[0, 4])
    assert [p.values["motion.mu"] for p in points] == pytest.approx([0.3, 0.6, 0.9], abs=1e-12)  # evenly spaced, by hand
    for p in points:
        alone = [run_laps(twin, [p.values], seed=s, keep_traces=False)[0] for s in (0, 4)]
        assert p.lap_times_s == tuple(r.lap_time_s for r in alone if r.completed)
        assert p.max_cross_track_m == max(r.max_cross_track_m for r in alone)


def test_one_parameter_sweep_writes_agreeing_csv_json_and_a_chart(tmp_path, capsys):
    out = tmp_path / "sweep"
    assert main(["sweep", "control.v_max=0.5:1.5:4", "--track", "oval", "--seeds", "2", "--out-dir", str(out),
                 "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    rows = list(csv.DictReader(open(out / "sweep.csv")))
    saved = json.loads((out / "sweep.json").read_text())
    assert len(rows) == len(doc["points"]) == len(saved["points"]) == 4
    for row, point in zip(rows, saved["points"]):
        assert float(row["control.v_max"]) == point["control.v_max"]
        assert float(row["completion_rate"]) == point["completion_rate"]
    assert (out / "sweep.png").read_bytes()[:4] == b"\x89PNG"
    rates = [p["completion_rate"] for p in doc["points"]]
    assert rates[0] == 1.0  # the slowest gains finish the oval


def test_two_parameter_sweep_makes_a_heat_map(tmp_path, capsys):
    out = tmp_path / "map"
    assert main(["sweep", "motion.mu=0.4:0.9:2", "control.kp=10:30:2", "--track", "oval", "--seeds", "1",
                 "--out-dir", str(out), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert [(p["motion.mu"], p["control.kp"]) for p in doc["points"]] == [(0.4, 10), (0.4, 30), (0.9, 10), (0.9, 30)]
    assert (out / "sweep.png").stat().st_size > 10_000


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
    assert time.monotonic() - t0 < 1.0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: sweep: ") and "more than the 20,000" in err[0], err
