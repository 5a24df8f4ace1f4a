"""What a finished lap shows the forecast (tuner.history.twin_edge.FEATURES): the lap time, the line's mean |offset|
from the sensor array's centre and its mean signed offset (the side it runs on), read alike from the robot's
telemetry (tuner.history.ingest.cross_track, on the wire's lines) and from the twin's own trace
(tuner.history.twin_edge.lap_features); the history's columns that hold them; a forecast reads the features every
lap it reads carries; and the misfit's limit against its distribution's closed form."""

from __future__ import annotations

import numpy as np
import pytest

from tuner.history.forecast import COLUMNS, carried, misfit_limit, observations_of, one_cause_misfit
from tuner.history.ingest import cross_track
from tuner.history.twin_edge import FEATURES, lap_features, observation_model
from tuner.prognostics import LapObservation, ObservationModel
from twin.core.closed_loop import run_laps
from twin.core.digital_twin import DigitalTwin
from twin.link.emulator import lap_records
from twin.telemetry.laps import LapAssembler, line_sides_m
from twin.telemetry.wire import decode

from reference_gains import PLAIN_HELD

pytestmark = pytest.mark.quick
LAPS, SEED = 6, 300
G = {"control.kp": 20.0}  # the gains the laps below ran on


def test_the_robots_telemetry_and_the_twins_trace_read_a_lap_alike():
    """The emulated robot (the twin with hidden values) sends a sample every 2nd control tick, its times in
    milliseconds and its line positions as integers; the twin reads its own lap from every tick. The same laps (the
    same noise seeds) read both ways differ by less than a tenth of the laps' own scatter from one seed to the next,
    the scatter the observation model holds (and the lap time by the wire's millisecond)."""
    twin = DigitalTwin()
    twin.update({**PLAIN_HELD, "motion.mu": 0.8})
    pitch = float(twin.space.get("sensor.pitch"))
    assembler = LapAssembler()
    robot = [lap for _, line in lap_records(twin, SEED, 2, LAPS) if (lap := assembler.feed(decode(line.strip())))]
    read = np.array([(lap.lap_time_s, *cross_track(lap, pitch)[1:]) for lap in robot])
    own = np.array([lap_features(r, pitch) for r in run_laps(twin, [{}] * LAPS, seed=[SEED + k for k in range(LAPS)])])
    assert read.shape == own.shape == (LAPS, len(FEATURES))
    assert np.abs(read[:, 0] - own[:, 0]).max() <= 1e-3
    scatter = own.std(axis=0, ddof=1)
    assert np.all(scatter[1:] > 0) and np.all(np.abs(read - own)[:, 1:] < 0.1 * scatter[1:]), (read - own, scatter)


def test_the_lines_side_is_signed_towards_the_last_sensor():
    """An 8-sensor array (positions 0 … 7000) at a 10 mm pitch: the line under the last sensor lies 35 mm to that
    side of the centre, under the first 35 mm to the other."""
    assert line_sides_m(np.array([7000.0, 0.0, 3500.0, 4000.0]), 8, 0.01) == pytest.approx([0.035, -0.035, 0.0, 0.005])


def test_a_forecast_reads_the_features_every_lap_carries():
    """Each feature lives in the history's column COLUMNS names; a feature some finished lap lacks (laps stored
    before the line's side was, a robot without telemetry) is not read, and the observation model is cut to the
    rest, in their order."""
    assert set(COLUMNS) == set(FEATURES) and COLUMNS["lap_time_s"] == "lap_time_s"
    full = [{"n": k, "completed": True, "gains": G, "lap_time_s": 7.0 + k, "xte_mean_m": 0.004, "line_side_m": -0.001}
            for k in range(3)]
    unsided = {"n": 3, "completed": True, "gains": G, "lap_time_s": 7.5, "xte_mean_m": 0.004, "line_side_m": None}
    failed = {"n": 4, "completed": False, "gains": G, "lap_time_s": None, "xte_mean_m": None, "line_side_m": None}
    older = [*full, unsided, failed]
    bare = [{**r, "xte_mean_m": None, "line_side_m": None} for r in full]
    assert carried(full) == FEATURES and carried(older) == ("lap_time_s", "line_offset_m")
    assert carried(bare) == ("lap_time_s",) and carried([]) == ("lap_time_s",)
    read = observations_of(older, G, 4, carried(older))
    assert [o.features for o in read] == [(7.0 + k, 0.004) for k in range(3)] + [(7.5, 0.004)]
    model = ObservationModel(FEATURES, np.array([0.7, 0.8]), np.arange(6.0).reshape(2, 3),
                             np.arange(18.0).reshape(2, 3, 3))
    cut = model.subset(("lap_time_s", "line_side_m"))
    assert cut.names == ("lap_time_s", "line_side_m") and cut.means.tolist() == [[0, 2], [3, 5]]
    assert cut.covariances.tolist() == [[[0, 2], [6, 8]], [[9, 11], [15, 17]]]


@pytest.mark.quick
def test_the_misfits_limit_is_its_99_9_percent_point():
    """The best six of eight laps' mean misfit, each χ² with d − 1 degrees of freedom, at the filter's largest noise
    scale (3, squared), exceeds the limit in 0.1 % of windows. Three features (χ²(2): twice an exponential): the
    order statistics of eight exponentials are sums of independent ones (Rényi), so the best six's sum is
    Σ wⱼ·Eⱼ with wⱼ = 2·(7 − j)/(9 − j), j = 1…6, whose tail is the hypoexponential's closed form. Two features
    (χ²(1)): 2²⁰ windows drawn by scipy on a seed of their own. The limit is itself drawn (2¹⁹ windows): its tail
    within 15 % of 0.1 % (about 3.5 of its standard errors); the bound the check used before (χ²(6·2)/6, 49.4 for
    three features) gives 1.4·10⁻⁵."""
    from scipy.stats import chi2

    w = np.array([2 * (7 - j) / (9 - j) for j in range(1, 7)])

    def tail(total):
        return sum(np.prod([w[j] / (w[j] - w[k]) for k in range(6) if k != j]) * np.exp(-total / w[j])
                   for j in range(6))

    assert tail(6 * misfit_limit(3) / 9) == pytest.approx(1e-3, rel=0.15)
    assert tail(6 * 49.4 / 9) < 2e-5  # (the loose bound: what the test tells apart)
    laps = chi2.rvs(1, size=(1 << 20, 8), random_state=np.random.RandomState(7))
    best = np.sort(laps, axis=1)[:, :6].mean(axis=1)
    assert np.mean(best > misfit_limit(2) / 9) == pytest.approx(1e-3, rel=0.2)
    with pytest.raises(ValueError):
        misfit_limit(1)


@pytest.mark.quick
def test_two_odd_laps_are_not_a_second_cause_and_three_are():
    """Two features that move together along the parameter (lap time and offset both rise as it falls, unit
    scatter): eight laps on the curve explain it alone; one or two of them 20 σ off across the curve (glitches)
    still do, the two worst laps left out; three such laps do not (400/6 = 67 against 17.0)."""
    model = ObservationModel(("lap_time_s", "line_offset_m"), np.array([0.0, 1.0]),
                             np.array([[10.0, 10.0], [0.0, 0.0]]), np.repeat(np.eye(2)[None], 2, axis=0))
    on = [LapObservation(k, (10.0 - k, 10.0 - k)) for k in range(8)]
    off = 20 / np.sqrt(2)  # across the curve (+, −): 20 σ from its nearest point

    def odd(lap):
        return LapObservation(lap.lap, (lap.features[0] + off, lap.features[1] - off))

    assert one_cause_misfit(model, on, (0.0, 1.0)) == pytest.approx(0.0, abs=1e-3)
    one = on[:3] + [odd(on[3])] + on[4:]
    assert one_cause_misfit(model, one, (0.0, 1.0)) == pytest.approx(0.0, abs=1e-3)
    two = one[:5] + [odd(on[5])] + on[6:]
    assert one_cause_misfit(model, two, (0.0, 1.0)) == pytest.approx(0.0, abs=1e-3)
    three = two[:1] + [odd(on[1])] + two[2:]
    assert one_cause_misfit(model, three, (0.0, 1.0)) == pytest.approx(400 / 6, rel=1e-2)
    assert one_cause_misfit(model, three, (0.0, 1.0)) > misfit_limit(2)


def test_a_history_from_before_the_side_keeps_its_laps_and_reads_them_without_it(tmp_path):
    """A database at the migration before the line's side (0003) with a lap in it: opened by this version it is
    upgraded (0004 adds ``line_side_m``), the lap is kept as it was, its side NULL, and a forecast reads its lap
    time and |offset| (carried) until the log is rebuilt."""
    import sqlalchemy as sa
    from alembic import command
    from alembic.config import Config

    from tuner.history import History, schema
    from tuner.history.store import MIGRATIONS, head

    url = f"sqlite:///{tmp_path / 'old.sqlite'}"
    engine = sa.create_engine(url)
    with engine.begin() as c:
        config = Config()  # the package's migrations, run on this connection as the history runs them
        config.set_main_option("script_location", MIGRATIONS)
        config.attributes["connection"] = c
        command.upgrade(config, "0003")
        c.exec_driver_sql("INSERT INTO lf_robots (id, name, kind) VALUES (1, 'bot', 'robot')")
        c.exec_driver_sql("INSERT INTO lf_runs (id, robot_id, command, source) VALUES (1, 1, 'live', 'log:x#log:bot')")
        c.exec_driver_sql("INSERT INTO lf_laps (run_id, robot_id, source, lap, completed, lap_time_s, xte_mean_m) "
                          "VALUES (1, 1, 'log:x#lap0', 0, 1, 7.25, 0.0041)")
        assert "line_side_m" not in {col["name"] for col in sa.inspect(c).get_columns("lf_laps")}
    engine.dispose()
    h = History(url)
    try:
        with h.engine.connect() as c:
            assert c.execute(sa.text(f"SELECT version_num FROM {schema.VERSION_TABLE}")).scalar() == head()
            rows = [dict(r._mapping) for r in c.execute(sa.select(schema.laps))]
    finally:
        h.close()
    assert [(r["lap_time_s"], r["xte_mean_m"], r["line_side_m"]) for r in rows] == [(7.25, 0.0041, None)]
    assert carried([{**rows[0], "completed": True}]) == ("lap_time_s", "line_offset_m")


@pytest.mark.quick
def test_a_part_that_slows_every_lap_is_read_to_its_edge_and_a_lap_that_lost_the_line_is_not():
    """A battery running down: each value raced 1.6 % slower than the one before, 20 values, 6.9 s to 9.4 s (36 %
    slower, regular all the way): the twin reads them all, and a robot's lap as slow as the last. A value where one
    lap took 1.3 times the value before it (it lost the line and found it again) ends the model there, and a lap
    1.3 times the slowest mean is not read."""
    rng = np.random.default_rng(3)
    values = 6.24 - 0.08 * np.arange(20)  # least worn first

    def laps(t):
        return [(False, (t * (1 + 1e-3 * rng.standard_normal()), 1e-3 + 1e-5 * rng.standard_normal(),
                         -5e-4 + 1e-5 * rng.standard_normal())) for _ in range(5)]

    times = 6.9 * 1.016 ** np.arange(20)
    rows = [(float(v), laps(t)) for v, t in zip(values, times)]
    model = observation_model(rows)
    assert len(model.values) == 20 and model.means[:, 0].max() == pytest.approx(times[-1], rel=2e-3)
    assert model.reads((times[-1],)) and not model.reads((1.3 * times[-1],))
    lost = [(v, list(ls)) for v, ls in rows]
    lost[12][1][0] = (False, (1.3 * times[11],) + lost[12][1][0][1][1:])
    assert len(observation_model(lost).values) == 12  # values 0-11: the value with the lost lap and all past it
