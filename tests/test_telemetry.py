"""Telemetry format and alignment to a recorded run: hidden parameters recovered, flat ones reported."""

from __future__ import annotations

import json

import pytest

from lf_common.errors import LineFollowerError
from twin.core.closed_loop import run_laps
from twin.core.digital_twin import DigitalTwin
from twin.run import main
from twin.telemetry.jsonl import lap_lines, read_telemetry, write_telemetry
from tuner.align.trace import align_telemetry

# deliberately arbitrary, not tuned: moderate gains that lap the oval well inside its limits (as bench_case_studies)
GAINS = {"control.v_max": 1.0, "control.kb": 0.3, "control.kp": 25.0, "control.kd": 0.5}


@pytest.fixture(scope="module")
def oval():
    t = DigitalTwin(track="oval")  # short: 4.9 m, a lap in ≈ 5.5 s
    t.update(GAINS)
    return t


@pytest.fixture(scope="module")
def recorded(oval, tmp_path_factory):
    """A 'robot' with hidden motor constants and its own noise seed."""
    hidden = {"motor.R_M": 10.0, "motor.K": oval.space.get("motor.K") * 1.08}
    lap = run_laps(oval, [hidden], seed=7)[0]
    path = tmp_path_factory.mktemp("tel") / "lap.jsonl"
    write_telemetry(str(path), lap_lines(lap, {"track": "oval", "sensors": 8, "dt_s": 0.005, "gains": GAINS}, 2))
    return str(path), hidden, lap


@pytest.mark.quick
def test_telemetry_round_trip(recorded):
    path, _, lap = recorded
    tel = read_telemetry(path)
    assert tel.header["format"] == "lf-telemetry" and tel.header["version"] == 1
    assert tel.lap_time_s == pytest.approx(lap.lap_time_s)
    assert len(tel.t) == len(lap.trace.records[::2]) and (tel.t[1:] > tel.t[:-1]).all()
    assert tel.wl[100] == pytest.approx(lap.trace.column("wheel_left_radps")[200], abs=1e-4)


def test_two_hidden_parameters_are_recovered_from_the_traces(oval, recorded):
    """K is recovered within 5 % and identified; R_M is reported as sure as the run makes it: with the motors'
    datasheet losses (issue 33) this run ties it to K (ρ ≈ −1: the closed loop hides the stall end of the torque
    line), so the fit may call it not identifiable, but every set it reports holds the hidden value."""
    path, hidden, _ = recorded
    r = align_telemetry(oval, read_telemetry(path), ["motor.R_M", "motor.K"])
    for p in r.parameters:
        assert p.consistent[0] <= hidden[p.address] <= p.consistent[1], p
        if p.identifiable and p.ci95 is not None:
            assert p.ci95[0] <= hidden[p.address] <= p.ci95[1], p
    k = r.parameters[1]
    assert k.identifiable and k.value == pytest.approx(hidden["motor.K"], rel=0.05), k
    assert r.rms_wheel_radps < 1.0  # the noise of a different seed is ≈ 0.7 rad/s
    assert oval.space.get("motor.R_M") != 10.0  # the twin itself is left as it was


def test_a_point_asked_again_is_not_raced_again_and_the_fit_is_the_same_bit_for_bit(oval, recorded, monkeypatch):
    """The fit asks its residual again for points it has raced (its solution, the refits' start, the scan's point at
    it); answered from what it raced, the fit is the one that races every point asked, to the bit, in fewer laps.
    The reference races every point of every call (the fit as it was before it kept them)."""
    from tuner.align import trace

    path, _, _ = recorded
    tel = read_telemetry(path)
    kept = align_telemetry(oval, tel, ["motor.R_M"], max_iter=3)

    def racing_every_point(self, X, seeds=None):
        return self.residuals_of(self.laps_for(X.reshape(len(self.addresses), -1), seeds))

    monkeypatch.setattr(trace._Residual, "__call__", racing_every_point)
    every = align_telemetry(oval, tel, ["motor.R_M"], max_iter=3)
    assert kept.parameters == every.parameters and kept.rms_wheel_radps == every.rms_wheel_radps
    assert kept.correlation == every.correlation and kept.iterations == every.iterations
    assert kept.laps < every.laps, (kept.laps, every.laps)


@pytest.mark.parametrize("body, needle", [
    ('{"type":"header","format":"lf-telemetry","version":1,"dt_s":0.005,"sensors":8}\n{"type":"sample","t":0}\n',
     ":2: field 'pos' must be a finite number"),
    ('{"type":"header","format":"lf-telemetry","version":1,"dt_s":0.005,"sensors":8}\n{"type":"sample",\n',
     ":2: not JSON"),
    ('{"type":"sample","t":0}\n', ":1: the first line must be the lf-telemetry header"),
    ('{"type":"header","format":"lf-telemetry","version":9,"dt_s":0.005,"sensors":8}\n', "version 9 is not supported"),
    ('{"type":"header","format":"lf-telemetry","version":1,"dt_s":0.005,"sensors":8}\n'
     '{"type":"sample","t":1,"pos":0,"seen":1,"wl":0,"wr":0}\n{"type":"sample","t":0.5,"pos":0,"seen":1,"wl":0,"wr":0}\n',
     ":3: sample time 0.5 s does not follow 1 s"),
])
def test_malformed_telemetry_names_the_line(tmp_path, body, needle, capsys):
    bad = tmp_path / "bad.jsonl"
    bad.write_text(body)
    with pytest.raises(LineFollowerError, match=needle.replace("(", r"\(")):
        read_telemetry(str(bad))
    assert main(["align", "--telemetry", str(bad)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(bad) in err[0]


def test_cli_record_writes_a_readable_run(tmp_path, capsys):
    out = tmp_path / "lap.jsonl"
    assert main(["record", "--track", "oval", "--set", "motion.mu=0.55", "--out", str(out)]) == 0
    tel = read_telemetry(str(out))
    assert tel.header["track"] == "oval" and tel.lap_time_s is not None
    assert json.loads(out.read_text().splitlines()[0])["gains"]["control.v_max"] == 0.6


def test_grip_the_run_never_tests_gets_no_interval_but_the_values_that_fit(tmp_path, capsys):
    """Default gains on the default track, robot seed 3, hidden μ 0.7: the robot never slips (with the caster's drag
    its run differs from one at μ 1.1 only in the tyres' micro-slip: wheel speeds in the 4th digit, laps 13.8141 s
    against 13.8147 s).
    μ gets no interval (null in the JSON), and the values that fit as well include the hidden value and reach the
    upper bound of μ's physical range, 2. (One run, of μ alone: an alignment of the default two, μ and R_M, was 2.5
    minutes of the suite's time; test_two_hidden_parameters_are_recovered_from_the_traces fits two.)"""
    path = tmp_path / "run.jsonl"
    assert main(["record", "--set", "motion.mu=0.7", "--seed", "3", "--out", str(path)]) == 0
    capsys.readouterr()
    assert main(["align", "--telemetry", str(path), "--param", "motion.mu", "--json"]) == 1  # exit 1: μ not identified
    (mu,) = [p for p in json.loads(capsys.readouterr().out)["parameters"] if p["address"] == "motion.mu"]
    assert mu["ci95"] is None and not mu["identifiable"], mu
    lo, hi = mu["consistent"]
    assert lo <= 0.7 <= hi and hi == 2.0, mu["consistent"]
