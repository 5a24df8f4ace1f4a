"""Robust tuning: an envelope of conditions × noise seeds, a risk measure over their laps, held-out seeds."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tuner.search.envelope import ROBUST_SEEDS, Envelope, Risk, held_out_seeds
from tuner.search.gradient import DescentOptions, descend
from tuner.search.objective import LapObjective, lap_cost
from tuner.search.space import SearchSpace
from twin.cli import tune
from twin.core.closed_loop import run_laps
from twin.core.digital_twin import DigitalTwin
from twin.errors import TwinError


@pytest.mark.quick
def test_risk_measures_by_hand():
    costs = np.array([[1.0, 2.0, 3.0, 10.0], [4.0, 4.0, 4.0, 4.0]])
    np.testing.assert_array_equal(Risk.parse("mean")(costs), [4.0, 4.0])
    np.testing.assert_array_equal(Risk.parse("worst")(costs), [10.0, 4.0])
    np.testing.assert_array_equal(Risk.parse("cvar:0.5")(costs), [6.5, 4.0])  # mean of the worst two
    np.testing.assert_array_equal(Risk.parse("cvar:0.25")(costs), [10.0, 4.0])
    np.testing.assert_array_equal(Risk.parse("cvar:1")(costs), Risk.parse("mean")(costs))
    for bad in ("median", "cvar:0", "cvar:1.5", "cvar:x", "worst:0.3"):
        with pytest.raises(TwinError, match="expected mean, worst or cvar"):
            Risk.parse(bad)


@pytest.mark.quick
def test_envelope_is_every_combination_and_held_out_seeds_are_new():
    e = Envelope.of({"motion.mu": (0.6, 0.75, 0.9), "motor.supply_voltage": (4.8, 6.0)}, [0, 1])
    assert len(e.scenarios) == 6 and len(e) == 12
    assert {(c["motion.mu"], c["motor.supply_voltage"]) for c in e.corners} == {(0.6, 4.8), (0.6, 6.0), (0.9, 4.8), (0.9, 6.0)}
    assert not set(held_out_seeds(e, 20)) & set(e.seeds) and len(set(held_out_seeds(e, 20))) == 20


@pytest.mark.quick
def test_robust_batched_laps_equal_the_same_laps_run_one_by_one():
    twin = DigitalTwin(track="oval")
    space = SearchSpace(twin.space, ["control.v_max", "control.kp"])
    envelope = Envelope.of({"motion.mu": (0.6, 0.9), "motor.supply_voltage": (4.8,)}, [0, 1])
    objective = LapObjective(twin, space, envelope=envelope, risk=Risk.parse("worst"))
    z = np.array([[0.3, 0.2], [0.6, 0.5]])
    costs = objective(z)
    assert objective.laps == 2 * 2 * 2  # points × scenarios × seeds, in one call
    for zi, c in zip(z, costs):
        gains = space.assignments(space.from_unit(zi))
        alone = [run_laps(twin, [{**gains, **sc}], seed=s, keep_traces=False)[0]
                 for sc in envelope.scenarios for s in envelope.seeds]
        assert [r.summary() for r in objective.at(zi).laps] == [r.summary() for r in alone]  # bit for bit
        assert c == max(lap_cost(r) for r in alone)


def test_fewer_laps_give_the_same_robust_descent():
    """The worst lap over μ 0.6 (near the grip limit) and 0.9 on two seeds: racing the line search's candidates,
    skipping a stencil's far-from-deciding laps and stopping decided laps take every step the laps-to-the-end search
    takes, to the same point and cost bit for bit, with fewer laps."""
    twin = DigitalTwin()
    space = SearchSpace(twin.space)
    envelope = Envelope.of({"motion.mu": (0.6, 0.9), "motor.supply_voltage": (6.0,)}, [0, 1])
    runs = []
    for stop_early in (True, False):
        objective = LapObjective(twin, space, envelope=envelope, risk=Risk.parse("worst"), stop_early=stop_early)
        r = descend(objective, space.to_unit(space.start(twin.space)), DescentOptions(max_iter=3))
        runs.append((r, objective))
    (fast, f), (full, g) = runs
    assert [(i.z.tobytes(), i.cost) for i in fast.iterations] == [(i.z.tobytes(), i.cost) for i in full.iterations]
    assert np.array_equal(f.best.x, g.best.x) and f.best.cost == g.best.cost
    assert [r.summary() for r in f.best.laps] == [r.summary() for r in g.best.laps]
    assert f.laps < g.laps


def test_robust_gains_finish_the_whole_envelope_on_held_out_seeds(capsys):
    code = tune.main(["--robust", "--track", "oval", "--max-iter", "3", "--held-out", "6", "--json", "-q"])
    assert code == 0
    s = json.loads(capsys.readouterr().out)
    assert s["risk"] == "worst" and len(s["envelope"]["scenarios"]) == 4 and len(s["envelope"]["seeds"]) == ROBUST_SEEDS
    assert len(s["per_iteration"]) == s["iterations"] and all(len(it["scenarios"]) == 4 for it in s["per_iteration"])
    held = s["held_out"]
    assert not set(range(held["seeds"][0], held["seeds"][1] + 1)) & set(s["envelope"]["seeds"])
    assert held["completion_rate"] == 1.0, held
    assert {c["scenario"] for c in held["corners"]} == set(s["envelope"]["scenarios"])


@pytest.mark.parametrize("args, needle", [
    (["--scenario", "motion.mu="], "expected ADDRESS=V1,V2"),
    (["--scenario", "motion.mu=nan"], "must be finite"),
    (["--scenario", "motion.muu=0.5"], "unknown parameter address"),
    (["--scenario", "cad.L=0.04,0.05"], "rebuilds"),
    (["--scenario", "motion.mu=0.01"], "outside"),
    (["--scenario", "control.kp=10,20"], "is searched"),
    (["--risk", "cvar:2"], "expected mean, worst or cvar"),
    (["--seeds", "0"], "outside"),
])
def test_robust_bad_input_is_one_line_and_exit_2(args, needle, capsys):
    assert tune.main([*args, "--track", "oval", "--max-iter", "1", "-q"]) == 2
    err = [e for e in capsys.readouterr().err.strip().splitlines() if not e.startswith("warning")]
    assert len(err) == 1 and err[0].startswith("error: ") and needle in err[0], err
