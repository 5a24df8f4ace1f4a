"""Learning model (Eqs. 12–13): gradients, steps, the paper's procedure, the CLI, bad input."""

from __future__ import annotations

import json

import numpy as np
import pytest

from twin.cli.tune import main as tuner_main
from tuner.search.gradient import DescentOptions, central_difference, descend, sequential
from tuner.search.objective import PENALTY_S, SLOW_SPEED, LapObjective, lap_cost
from twin.errors import TwinError
from tuner.search.space import SearchSpace, TunerError
from twin.core.closed_loop import run_laps
from twin.core.digital_twin import DigitalTwin
from twin.run import main as twin_main

pytestmark = pytest.mark.quick  # the whole module is in the quick tier (tests/test_tiers.py)

A = np.array([[3.0, 1.0, 0.0], [1.0, 2.0, 0.5], [0.0, 0.5, 1.0]])
C = np.array([0.3, 0.6, 0.45])


def quadratic(z: np.ndarray) -> np.ndarray:
    d = np.atleast_2d(z) - C
    return np.einsum("mi,ij,mj->m", d, A, d) + np.sin(3 * np.atleast_2d(z)[:, 0])


def quadratic_gradient(z: np.ndarray) -> np.ndarray:
    return 2 * A @ (z - C) + np.array([3 * np.cos(3 * z[0]), 0.0, 0.0])


def test_central_difference_matches_the_analytic_gradient():
    for z in (np.array([0.5, 0.5, 0.5]), np.array([0.1, 0.9, 0.3])):
        g, _, n = central_difference(quadratic, z, 1e-4)
        assert n == 6  # 2n points, one call
        np.testing.assert_allclose(g, quadratic_gradient(z), rtol=1e-6, atol=1e-7)  # O(h²) error: ~1e-8


def test_one_sided_difference_at_the_box_edge():
    z = np.array([1.0, 0.0, 0.5])
    g, _, _ = central_difference(quadratic, z, 1e-5)
    np.testing.assert_allclose(g, quadratic_gradient(z), rtol=1e-3, atol=1e-4)  # O(h) one-sided error


def test_descent_converges_on_a_smooth_function_and_keeps_bounds():
    calls = []
    f = lambda z: (calls.append(len(np.atleast_2d(z))), quadratic(z))[1]
    r = descend(f, np.array([0.95, 0.05, 0.95]), DescentOptions(xtol=1e-3, ftol=1e-6, max_iter=80))
    assert r.converged
    from scipy.optimize import minimize

    ref = minimize(lambda z: quadratic(z)[0], np.array([0.5, 0.5, 0.5]), bounds=[(0, 1)] * 3)
    assert r.cost == pytest.approx(ref.fun, abs=1e-3)
    assert np.all((r.z >= 0) & (r.z <= 1))
    assert all(c in (6 + 1, 6, 4) for c in calls)  # every evaluation is a whole batch: gradient or line search


def test_sequential_uses_exactly_one_plus_n_laps_per_iteration():
    calls = []
    f = lambda z: (calls.append(len(np.atleast_2d(z))), quadratic(z))[1]
    r = sequential(f, np.array([0.9, 0.1, 0.1]), DescentOptions(max_iter=12))
    assert all(c == 1 for c in calls)  # one lap at a time
    assert r.evaluations == len(calls) == (1 + 3) * len(r.iterations)
    assert r.cost < r.initial_cost


def test_lap_cost_penalises_failure_by_distance_left():
    from twin.core.lap import LapResult

    def lap(completed, t, d):
        return LapResult(completed, None if completed else "off_track", "", t if completed else None, t, d, 7.0,
                         0.0, 0.0, 0.0, (), (), {})

    assert lap_cost(lap(True, 9.0, 7.0)) == 9.0
    near, far = lap_cost(lap(False, 9.0, 6.9)), lap_cost(lap(False, 9.0, 1.0))
    assert near == pytest.approx(9.0 + PENALTY_S + 0.1 / SLOW_SPEED)
    assert far > near > 9.0 + PENALTY_S  # failing is worse than finishing; getting further is better


@pytest.fixture(scope="module")
def twin():
    return DigitalTwin()


def test_one_step_on_the_simulation_lowers_the_lap_time(twin):
    space = SearchSpace(twin.space)
    objective = LapObjective(twin, space, seed=0)
    z0 = space.to_unit(space.start(twin.space))
    r = descend(objective, z0, DescentOptions(max_iter=1))
    assert r.cost < r.initial_cost - 0.1  # at least 0.1 s faster after one step
    assert objective.laps == 2 * 5 + 1 + 4  # one gradient batch (with the start) and one line-search batch
    assert twin.space.get("control.kp") == 15.0  # the search never writes into the twin


def test_bad_search_input_is_refused(twin):
    with pytest.raises(TunerError, match="inverted"):
        SearchSpace(twin.space, ["control.kp"], {"control.kp": (60.0, 1.0)})
    with pytest.raises(TunerError, match="rebuilds"):
        SearchSpace(twin.space, ["cad.L"])
    with pytest.raises(TwinError, match="unknown parameter address"):
        SearchSpace(twin.space, ["control.kq"])
    with pytest.raises(TunerError, match="must be a finite number"):
        SearchSpace(twin.space, ["control.kp"], {"control.kp": (float("nan"), 5.0)})
    space = SearchSpace(twin.space, ["control.kp"], {"control.kp": (20.0, 40.0)})
    with pytest.raises(TunerError, match="start value 15 is outside its bounds"):
        space.start(twin.space)


@pytest.mark.parametrize("args, needle", [
    (["--bounds", "control.kp=60,1"], "inverted"),
    (["--set", "control.kp=nan"], "must be finite"),
    (["--param", "control.kq"], "unknown parameter address"),
    (["--bounds", "control.kp=20,40"], "outside its bounds"),
    (["--bounds", "control.kp=1"], "expected LOWER,UPPER"),
])
def test_cli_bad_input_is_one_line_and_exit_2(args, needle, capsys):
    assert tuner_main([*args, "-q"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: ") and needle in err[0]


def test_cli_out_gains_load_into_a_lap(tmp_path, capsys):
    out, rrd = tmp_path / "gains.json", tmp_path / "tune.rrd"
    code = tuner_main(["--param", "control.v_max", "--param", "control.kp", "--track", "oval", "--max-iter", "2",
                       "--out", str(out), "--save", str(rrd), "--json", "-q"])
    assert code == 0
    summary = json.loads(capsys.readouterr().out)
    assert 1 <= summary["iterations"] <= 2 and summary["completed"]
    assert set(summary["gains"]) == {"control.v_max", "control.kp"}
    # the start is the default gains' lap, and the tuned gains' lap is faster: both re-run through the library
    oval = DigitalTwin(track="oval")
    start, tuned = run_laps(oval, [{}, summary["gains"]], seed=0, keep_traces=False)
    assert summary["initial_lap_time_s"] == start.lap_time_s
    assert summary["final_lap_time_s"] == tuned.lap_time_s < start.lap_time_s
    assert summary["gains"] != {"control.v_max": 0.6, "control.kp": 15.0}  # it moved from the start
    # and the gains file loads into a lap of the command line: the same lap, bit for bit
    assert twin_main(["lap", "--track", "oval", "--gains", str(out), "--json"]) == 0
    lap = json.loads(capsys.readouterr().out)
    assert lap["lap_time_s"] == summary["final_lap_time_s"]
    assert b"tuning/lap_time" in rrd.read_bytes()


def test_bounds_hit_are_the_values_on_a_bound():
    space = SearchSpace(DigitalTwin(track="circle").space, ["control.v_max", "control.kp"],
                        {"control.v_max": (0.3, 1.5), "control.kp": (5.0, 25.0)})
    assert space.bounds_hit(np.array([1.5, 12.0])) == [("control.v_max", "upper", 1.5)]
    assert space.bounds_hit(np.array([0.3, 25.0])) == [("control.v_max", "lower", 0.3), ("control.kp", "upper", 25.0)]
    assert space.bounds_hit(np.array([1.49, 5.01])) == []  # 0.8 % and 0.05 % of the range inside: not on a bound


def test_plain_tune_names_the_bound_it_hit_and_no_envelope(capsys):
    """Issue 36: plain tune reported "completed over the envelope's corners" with no envelope, and did not say that
    v_max ended on its upper bound. Top speed capped at its start value: a faster lap can only push it up, so one
    iteration ends on that bound."""
    assert tuner_main(["--param", "control.v_max", "--bounds", "control.v_max=0.3,0.6", "--track", "circle",
                       "--max-iter", "1", "--held-out", "2", "-q"]) == 0
    out = capsys.readouterr().out
    assert "bound hit: control.v_max ended on its upper bound (0.6 m/s)" in out, out
    assert "envelope" not in out, out
    assert "held-out seeds" in out and "/2 laps completed" in out, out
