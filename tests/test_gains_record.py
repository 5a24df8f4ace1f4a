"""A gains file records what it was tuned for, and a command that loads it says when it runs something else
(issue 22.6: gains were silently applied to a different robot)."""

from __future__ import annotations

import json

import pytest

from twin.run import main


@pytest.fixture(scope="module")
def tuned(tmp_path_factory):
    """Gains tuned (one iteration is enough to write a file) for the default robot on the circle."""
    path = tmp_path_factory.mktemp("gains") / "gains.json"
    assert main(["tune", "--track", "circle", "--max-iter", "1", "-o", str(path), "-q"]) == 0
    return path


def _lap(capsys, *args):
    assert main(["lap", "--json", *args]) == 0
    return json.loads(capsys.readouterr().out)


def test_tune_records_the_robot_motor_and_track(tuned):
    record = json.loads(tuned.read_text())["tuned_for"]
    assert record["robot"] == "generated" and record["track"] == "circle"
    assert record["cad"]["cad.L"] == 0.0425 and record["motor"]["motor.gear"] == 29.86  # the default 3pi-class robot


@pytest.mark.parametrize("args, names", [
    (["--track", "circle"], None),  # the robot it was tuned for: no warning
    (["--track", "circle", "--set", "motor.supply_voltage=5"], None),  # a tired battery is a condition, not a robot
    (["--track", "oval"], "track circle (this run: oval)"),
    (["--track", "circle", "--set", "cad.L=0.05"], "cad.L=0.0425 (this run: 0.05)"),
    (["--track", "circle", "--motor", "pololu-hp-6v-30"], "motor with"),
])
def test_lap_warns_in_one_line_and_in_json(tuned, capsys, args, names):
    doc = _lap(capsys, "--gains", str(tuned), *args)
    if names is None:
        assert doc["gains_warning"] is None
    else:
        assert names in doc["gains_warning"] and str(tuned) in doc["gains_warning"]


def test_a_hand_written_gains_file_is_not_judged(tmp_path, capsys):
    gains = tmp_path / "mine.json"
    gains.write_text(json.dumps({"control.kp": 20}))
    assert _lap(capsys, "--gains", str(gains), "--track", "circle")["gains_warning"] is None


def test_sweep_warns_too(tuned, tmp_path, capsys):
    assert main(["sweep", "control.kd=0.2:0.3:2", "--seeds", "1", "--track", "oval", "--gains", str(tuned),
                 "--out-dir", str(tmp_path / "s"), "--json"]) == 0
    assert "track circle (this run: oval)" in json.loads(capsys.readouterr().out)["gains_warning"]
