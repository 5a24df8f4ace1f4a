"""Shared fixtures: a cache folder per test session, the root logger restored after each test, a third-party-style
URDF package, the processor in the loop's tools (``pil_ready``), and the gains ``tune`` answers today
(``plain_gains``, ``robust_gains``: tuned once a session by tests/reference_gains.py, which the benchmarks call too, so
tests that need tuned gains never hold a copy that the tuner has moved away from)."""

from __future__ import annotations

import logging
import os
import signal
import textwrap

import numpy as np
import pytest
import trimesh


# A shell without job control starts a background command (`.ci/run &`, nohup in a script) with SIGINT ignored, and
# a child inherits that: the twin's processes would never see the Ctrl-C the tests send them (a hung controller then
# ran out its 5 s limit and exited 2 instead of 130). A handler, unlike "ignored", is reset to the default on exec.
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)


# Under CI (.ci/run sets CI=1 and installs every tool and library the suite uses) a skip would hide a test that never
# ran, so it fails instead, with the skip's own reason naming the missing piece. The only skips CI allows are the
# opt-in ones listed here, each with why it is not part of CI.
SKIPS_CI_ALLOWS = {
    "LIBPOLOLU_AVR": "building more programs from a libpololu-avr source tree is opt-in: the 27 built examples in "
                     "../shared/pololu-examples run in CI (tests/test_pololu_examples.py)",
}


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    report = (yield).get_result()
    if not (os.environ.get("CI") and report.skipped and not hasattr(report, "wasxfail")):
        return
    reason = report.longrepr[2] if isinstance(report.longrepr, tuple) else str(report.longrepr)
    if not any(key in reason for key in SKIPS_CI_ALLOWS):
        report.outcome = "failed"
        report.longrepr = f"skipped under CI, where every test must run: {reason}"


# The suite runs in two processes (pytest -n 2 --dist worksteal, pytest-xdist), each taking the next test it holds
# and, when it holds none, half of what the other holds (worksteal; xdist's default left the tests queued behind a long
# one waiting while the other process idled). The tests that took 18 s or more in a full run start first, heaviest
# first (--durations, test and fixture time: ranked again from the run of 2026-12-02, those it did not list after
# them as before), so that the run does not end on one of them while the other process idles. Only the order
# changes; a test missing here runs in its place.
HEAVY_FIRST = tuple(f"tests/{name}" for name in (
    "test_case2.py::test_lap_time_and_diagnosis_intervals_cover_hidden_values_across_the_documented_ranges",
    "test_case2.py::test_telemetry_intervals_cover_hidden_values_across_the_documented_ranges",
    "test_viewer_web.py::test_the_web_viewer_shows_every_panel_without_errors",
    "test_benchmarks.py::test_benchmark_runs_in_quick_mode_and_prints_its_figures[bench_forecast.py",
    "test_case2.py::test_a_fit_stopped_on_the_ridge_says_so_and_states_no_interval_that_misses",
    "test_act.py::test_live_act_in_lockstep_keeps_its_robot_on_a_machine_busy_on_every_core",
    "test_case2.py::test_telemetry_recovers_grip_and_battery_with_intervals_that_cover_them",
    "test_benchmarks.py::test_benchmark_runs_in_quick_mode_and_prints_its_figures[bench_tuner.py",
    "test_benchmarks.py::test_benchmark_runs_in_quick_mode_and_prints_its_figures[bench_cluster.py",
    "test_benchmarks.py::test_benchmark_runs_in_quick_mode_and_prints_its_figures[bench_case_studies.py",
    "test_race_ahead.py::test_live_runs_ahead_the_races_history_reads",
    "test_case2.py::test_a_parameter_the_run_cannot_pin_is_named_with_the_evidence",
    "test_cluster.py::test_a_sweep_on_the_cluster_equals_the_local_one",
    "test_forecast_drift.py::test_the_stated_interval_holds_the_hidden_drifts_first_failure",
    "test_benchmarks.py::test_benchmark_runs_in_quick_mode_and_prints_its_figures[bench_startup.py",
    "test_telemetry.py::test_two_hidden_parameters_are_recovered_from_the_traces",
    "test_act.py::test_acting_keeps_a_drifting_robot_finishing_where_watching_sees_failures",
    "test_cli.py::test_every_command_prints_exactly_one_json_document",
    "test_case2.py::test_diagnosis_ranks_dirty_tyres_first_from_the_traces",
    "test_history.py::test_processes_creating_one_new_database_at_once_all_get_it",
    "test_case2.py::test_diagnosis_ranks_a_tired_battery_first_from_the_lap_time",
    "test_viewer_web.py::test_every_recording_is_valid_for_rerun",
    "test_case2.py::test_the_refined_scan_finds_a_value_inside_a_narrow_steep_band",
    "test_benchmarks.py::test_benchmark_runs_in_quick_mode_and_prints_its_figures[bench_timestep.py",
    "test_case2.py::test_lap_time_alignment_recovers_grip_on_another_seed",
    "test_telemetry.py::test_grip_the_run_never_tests_gets_no_interval_but_the_values_that_fit",
    "test_robust.py::test_robust_gains_finish_the_whole_envelope_on_held_out_seeds",
    "test_cluster.py::test_a_study_on_the_cluster_equals_the_local_one",
    "test_live_twin.py::test_whole_chain_through_a_pty_converges_across_a_restart",
    "test_act.py::test_a_store_the_robot_never_answers_is_reported_not_stored_everywhere",
    "test_benchmarks.py::test_benchmark_runs_in_quick_mode_and_prints_its_figures[bench_act.py",
    "test_robust.py::test_fewer_laps_give_the_same_robust_descent",
    "test_align.py::test_a_robot_in_the_steep_band_is_explained_with_the_default_range",
    "test_act.py::test_a_robot_in_lockstep_keeps_waiting_through_a_re_tune_longer_than_its_idle_timeout",
    "test_prognostics.py::test_the_stated_intervals_cover_the_truth_at_their_stated_rate",
    "test_forecast_drift.py::test_read_lap_by_lap_the_stated_interval_holds_hidden_drifts_first_failures_and_the_order_does_not_matter",
    "test_two_causes.py::test_both_causes_at_once_are_followed_as_the_exact_posterior_follows_them",
    "test_prognostics.py::test_a_part_renewed_mid_life_is_followed_as_the_exact_posterior_follows_it",
    "test_board.py::test_a_design_study_races_a_3pi_program_on_each_design_as_lap_does",
    "test_sensitivity.py::test_a_default_analysis_with_fewer_samples_is_not_kept_for_diagnose_and_align",
    "test_own_robot.py::test_your_robot_in_five_minutes",
    "test_history.py::test_lap_and_align_keep_their_runs_and_an_unreachable_database_is_one_line",
    "test_cluster.py::test_a_sweep_through_ray_client_equals_the_local_one_line_for_line",
    "test_pil.py::test_a_sweep_on_the_mcu_gives_each_point_the_lap_that_lap_gives",
    "test_board.py::test_a_sweep_runs_a_3pi_program_lap_by_lap_as_lap_does",
    "test_benchmarks.py::test_benchmark_runs_in_quick_mode_and_prints_its_figures[bench_learn.py",
    "test_align.py::test_flat_lap_time_is_not_identifiable",
    "test_design.py::test_a_categorical_study_ranks_motors_as_its_evidence_explains",
    "test_board.py::test_bad_programs_and_inputs_are_one_line_and_exit_2",
    "test_align.py::test_cli_align_json_and_recording",
    "test_cluster.py::test_a_killed_worker_is_retried_and_counted_once",
    "test_benchmarks.py::test_benchmark_runs_in_quick_mode_and_prints_its_figures[bench_timing.py",
    "test_benchmarks.py::test_benchmark_runs_in_quick_mode_and_prints_its_figures[bench_pil.py",
    "test_board.py::test_a_register_level_follower_laps_the_oval_deterministically",
    "test_benchmarks.py::test_benchmark_runs_in_quick_mode_and_prints_its_figures[bench_fmu.py",
    "test_act.py::test_a_robot_that_refuses_or_stays_silent_keeps_its_gains",
    "test_timing.py::test_the_defaults_are_what_the_mcu_measures",
    "test_forecast_drift.py::test_two_causes_at_once_grip_alone_does_not_explain_and_the_battery_that_does_forecasts_the_failure",
    "test_progress.py::test_diagnose_counts_its_candidates",
    "test_act.py::test_a_bad_tune_is_rolled_back",
    "test_board.py::test_a_maze_solver_of_our_own_reaches_the_finish_spot",
    "test_board.py::test_emulate_paces_a_program_that_sends_nothing_at_its_speed",
    "test_design.py::test_small_study_writes_charts_table_and_gains",
    "test_pil.py::test_a_design_study_races_its_tuned_gains_on_the_mcu",
    "test_failure_model.py::test_the_twins_failure_model_says_how_often_laps_fail_at_the_onset",
    "test_prognostics.py::test_lap_by_lap_features_give_intervals_that_cover_the_truth_at_their_stated_rate",
))


def pytest_collection_modifyitems(config, items):
    def rank(item) -> int:  # heaviest first, in the order listed; the rest (stable sort) as collected
        return next((k for k, name in enumerate(HEAVY_FIRST) if item.nodeid.startswith(name)), len(HEAVY_FIRST))
    items.sort(key=rank)
    # worksteal hands the first half of the list to one process and the second half to the other, and a process out
    # of tests steals from the end of the other's: so each half starts with every other heavy test (a half that held
    # them all would run them one after another while the other stole only light ones)
    heavy = [i for i in items if rank(i) < len(HEAVY_FIRST)]
    light = items[len(heavy):]
    first = heavy[0::2] + light[:max(0, len(items) // 2 - len(heavy[0::2]))]
    second = heavy[1::2] + light[len(first) - len(heavy[0::2]):]
    items[:] = first + second


def _run_folder(tmp_path_factory):
    """The run's own temporary folder, the same for both pytest processes (pytest -n 2)."""
    root = tmp_path_factory.getbasetemp()
    return root.parent if os.environ.get("PYTEST_XDIST_WORKER") else root  # each process's base folder sits in it


@pytest.fixture(scope="session")
def run_folder(tmp_path_factory):
    """The run's own folder, the same for both pytest processes: where what one makes for both is kept (under a
    lock, as ``one_ray_head`` and ``_cache_dir`` do)."""
    return _run_folder(tmp_path_factory)


@pytest.fixture
def one_ray_head(tmp_path_factory):
    """The machine's Ray lock, held for the test: a test that starts a Ray head waits for the other pytest process's
    (pytest -n 2) to finish, since 'ray stop --force' stops every head on the machine and 'auto' joins whichever is
    there. (pytest-xdist's own xdist_group does not group under pytest 9: tried with xdist 3.8.) Function-scoped:
    a lock held across tests could wait on a process that waits for it."""
    import fcntl

    with open(_run_folder(tmp_path_factory) / "ray.lock", "a") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        yield


@pytest.fixture(autouse=True, scope="session")
def _cache_dir(tmp_path_factory):
    """One cache and one folder of reference gains (reference_gains.tuned_gains) for the whole run, both pytest
    processes: a robot, a track or a race of the twin built by one is read by the other (cache entries are published
    whole, lf_common.cache.cached_folder, so two processes building one entry is safe) instead of built twice."""
    root = _run_folder(tmp_path_factory)
    (root / "twin-cache").mkdir(exist_ok=True)
    os.environ["TWIN_CACHE_DIR"] = str(root / "twin-cache")
    os.environ[GAINS_DIR] = str(root / "reference-gains")


@pytest.fixture(scope="session")
def pil_ready():
    """avr-gcc and simavr's glue with the robot's firmware built, or a skip (a failure in CI, which installs both)."""
    from twin.errors import TwinError
    from twin.pil import firmware as fw

    try:
        from twin.pil.mcu import glue

        glue()
        fw.build("robot")
    except TwinError as e:
        if os.environ.get("CI"):
            pytest.fail(f"CI installs gcc-avr, simavr and libsimavr-dev: {e}")
        pytest.skip(str(e))


GAINS_DIR = "LF_REFERENCE_GAINS_DIR"  # where reference_gains keeps its answers (default: the cache folder's)


@pytest.fixture(scope="session")
def plain_gains() -> dict:
    """``tune``'s answer (a few seconds; tests/reference_gains.py, shared with the benchmarks)."""
    from reference_gains import tuned_gains

    return tuned_gains()


@pytest.fixture(scope="session")
def robust_gains() -> dict:
    """``tune --robust``'s answer (about 30 s of CPU on the first machine; tuned once per code: reference_gains)."""
    from reference_gains import tuned_gains

    return tuned_gains("--robust")


@pytest.fixture(autouse=True)
def _keep_logging():
    """Commands run in-process point the root logger at the captured stderr of their test: undo that."""
    root = logging.getLogger()
    handlers, level = root.handlers[:], root.level
    yield
    root.handlers[:], root.level = handlers, level


THIRD_PARTY_URDF = """\
<?xml version="1.0"?>
<!-- ROS-style robot: root base_footprint without mass, wheels turned by rpy with axis 0 0 1,
     package:// meshes, a caster link without <inertial>. -->
<robot name="tb_like">
  <link name="base_footprint"/>
  <joint name="base_joint" type="fixed">
    <parent link="base_footprint"/><child link="base_link"/>
    <origin xyz="0 0 0.033" rpy="0 0 0"/>
  </joint>
  <link name="base_link">
    <visual><origin xyz="0 0 0.02"/><geometry><mesh filename="package://tb_like/meshes/body.stl"/></geometry>
      <material name="grey"><color rgba="0.6 0.6 0.6 1"/></material></visual>
    <collision><origin xyz="0 0 0.02"/><geometry><mesh filename="package://tb_like/meshes/body.stl"/></geometry></collision>
    <inertial><origin xyz="0.01 0 0.02"/><mass value="0.8"/>
      <inertia ixx="0.002" ixy="0" ixz="0" iyy="0.002" iyz="0" izz="0.003"/></inertial>
  </link>
  <joint name="wheel_left_joint" type="continuous">
    <parent link="base_link"/><child link="wheel_left_link"/>
    <origin xyz="0 0.08 0" rpy="-1.5707963267948966 0 0"/><axis xyz="0 0 1"/>
  </joint>
  <link name="wheel_left_link">
    <visual><geometry><mesh filename="package://tb_like/meshes/wheel.stl"/></geometry></visual>
    <collision><geometry><cylinder radius="0.033" length="0.018"/></geometry></collision>
    <inertial><mass value="0.03"/><inertia ixx="1e-5" ixy="0" ixz="0" iyy="1e-5" iyz="0" izz="1.7e-5"/></inertial>
  </link>
  <joint name="wheel_right_joint" type="continuous">
    <parent link="base_link"/><child link="wheel_right_link"/>
    <origin xyz="0 -0.08 0" rpy="1.5707963267948966 0 0"/><axis xyz="0 0 1"/>
  </joint>
  <link name="wheel_right_link">
    <visual><geometry><mesh filename="package://tb_like/meshes/wheel.stl"/></geometry></visual>
    <collision><geometry><cylinder radius="0.033" length="0.018"/></geometry></collision>
    <inertial><mass value="0.03"/><inertia ixx="1e-5" ixy="0" ixz="0" iyy="1e-5" iyz="0" izz="1.7e-5"/></inertial>
  </link>
  <joint name="caster_joint" type="fixed">
    <parent link="base_link"/><child link="caster_link"/>
    <origin xyz="0.07 0 -0.023"/>
  </joint>
  <link name="caster_link">
    <collision><geometry><sphere radius="0.01"/></geometry></collision>
  </link>
  <joint name="caster_back_joint" type="fixed">
    <parent link="base_link"/><child link="caster_back_link"/>
    <origin xyz="-0.07 0 -0.022"/>
  </joint>
  <link name="caster_back_link">
    <collision><geometry><sphere radius="0.01"/></geometry></collision>
    <inertial><mass value="0.005"/><inertia ixx="2e-7" ixy="0" ixz="0" iyy="2e-7" iyz="0" izz="2e-7"/></inertial>
  </link>
  <joint name="sensor_joint" type="fixed">
    <parent link="base_link"/><child link="line_sensor_link"/>
    <origin xyz="0.09 0 -0.028"/>
  </joint>
  <link name="line_sensor_link"/>
</robot>
"""


def write_third_party(root) -> str:
    """Write ``tb_like/urdf/robot.urdf`` and ``tb_like/meshes/*.stl`` under root; returns the URDF path."""
    pkg = root / "tb_like"
    (pkg / "urdf").mkdir(parents=True)
    (pkg / "meshes").mkdir()
    trimesh.creation.box([0.16, 0.12, 0.03]).export(pkg / "meshes" / "body.stl")
    trimesh.creation.cylinder(radius=0.033, height=0.018).export(pkg / "meshes" / "wheel.stl")
    urdf = pkg / "urdf" / "robot.urdf"
    urdf.write_text(THIRD_PARTY_URDF)
    return str(urdf)


@pytest.fixture
def third_party_urdf(tmp_path) -> str:
    return write_third_party(tmp_path)


def minimal_urdf(extra: str = "", wheels: int = 2) -> str:
    """A tiny diff-drive URDF with primitives only, for error cases."""
    wheel = """
  <joint name="w{i}" type="continuous"><parent link="base"/><child link="wl{i}"/>
    <origin xyz="0 {y} 0" rpy="-1.5708 0 0"/><axis xyz="0 0 1"/></joint>
  <link name="wl{i}"><collision><geometry><cylinder radius="0.02" length="0.01"/></geometry></collision>
    <inertial><mass value="0.01"/><inertia ixx="1e-6" ixy="0" ixz="0" iyy="1e-6" iyz="0" izz="2e-6"/></inertial></link>"""
    body = "".join(wheel.format(i=i, y=0.05 if i == 0 else -0.05) for i in range(wheels))
    return textwrap.dedent(f"""\
        <robot name="mini">
          <link name="base"><inertial><mass value="0.3"/><inertia ixx="1e-4" ixy="0" ixz="0" iyy="1e-4" iyz="0" izz="1e-4"/></inertial>
            <collision><origin xyz="0.05 0 -0.015"/><geometry><sphere radius="0.005"/></geometry></collision></link>
          {body}{extra}
        </robot>""")


def yaw_of(quat: np.ndarray) -> float:
    w, x, y, z = quat
    return float(np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z)))
