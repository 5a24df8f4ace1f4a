"""The quick tier (``pytest -m quick``, about 2 minutes on 2 cores) touches every package.

``QUICK`` maps each package of the project, as found on disk, to quick tests that exercise it. Checked here, from
the sources alone (no test is run, nothing heavy is imported):

* the map names exactly the packages on disk (those ``pyproject.toml`` installs): a new package needs a quick test;
* each named test exists and carries the ``quick`` mark (on itself or on its whole module);
* each named test reaches the package: the names its body uses (following the module's own fixtures and helper
  functions) come from one of the package's own modules, or from a module that imports one of them (the command
  line's ``tune`` for the recordings in ``tuner``, say).
"""

from __future__ import annotations

import ast
import fnmatch
import functools
import os
import re

import pytest

pytestmark = pytest.mark.quick

TESTS = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(TESTS)

QUICK: dict[str, list[str]] = {
    "lf_common": ["test_files.py::test_a_failing_writer_leaves_neither_a_temporary_nor_a_changed_target",
                  "test_design.py::test_json_output_has_null_for_missing_figures"],
    "mjcf": ["test_cad.py::test_urdf_has_stated_masses_and_geometric_inertias",
             "test_urdf_to_mjcf.py::test_third_party_urdf_converts", "test_track.py::test_projection_on_a_circle_is_exact"],
    "motors": ["test_motors.py::test_free_air_voltage_step_matches_closed_form_within_1_percent"],
    "line_sensor": ["test_line_sensor.py::test_footprint_c_equals_python"],
    "twin": ["test_closed_loop.py::test_cli_lap_json_gains_and_recording"],  # twin.run, twin.errors
    "twin.core": ["test_closed_loop.py::test_default_gains_complete_the_default_lap",
                  "test_c_boundary.py::test_the_library_layout_is_the_mirror"],
    "twin.model": ["test_model_space.py::test_change_costs_follow_the_influences_relation",
                   "test_firmware.py::test_c_firmware_equals_python_reference"],
    "twin.telemetry": ["test_link.py::test_wire_round_trip_and_checksum", "test_telemetry.py::test_telemetry_round_trip"],
    "twin.pil": ["test_pil.py::test_an_mcu_attached_before_the_physics_stepped_reads_a_dark_floor",  # needs simavr
                 "test_pil.py::test_without_simavr_the_command_says_what_to_install"],
    "twin.pil.board": ["test_board_units.py::test_the_operator_waits_for_polling_with_the_motors_still_then_presses_what_the_lcd_asks",
                       # Pololu's own programs (../shared/pololu-examples): a failure under CI without them
                       "test_pololu_examples.py::test_led1_blinks_red_for_a_second_then_green_for_half_a_second",
                       "test_pololu_examples.py::test_simple_test_says_hello_plays_an_arpeggio_and_alternates_the_leds"],
    "twin.link": ["test_link.py::test_restart_ends_a_cut_off_line_and_a_second_reader_is_refused"],
    "twin.viz": ["test_closed_loop.py::test_cli_lap_json_gains_and_recording"],
    "twin.cli": ["test_cli.py::test_the_readme_flag_table_matches_help"],
    "tuner": ["test_tuner.py::test_cli_out_gains_load_into_a_lap"],  # tuner.recording, through tune --save
    "tuner.search": ["test_tuner.py::test_one_step_on_the_simulation_lowers_the_lap_time"],
    "tuner.align": ["test_align.py::test_unexplained_lap_time_is_reported_with_the_reachable_range"],
    "tuner.history": ["test_history.py::test_migrations_create_exactly_the_schema_and_a_foreign_database_is_left_alone"],
    "tuner.live": ["test_live_twin.py::test_implausible_wire_laps_are_reported_and_never_realigned"],
    "tuner.prognostics": ["test_prognostics.py::test_the_failure_model_is_the_normal_cdf_and_a_certain_wear_fails_on_the_lap_a_hand_counts"],
    "tuner.sensitivity": ["test_sensitivity.py::test_a_failed_lap_has_zero_completion_and_no_value_written_in"],
    "twin.fmi": ["test_fmu_controller.py::test_the_library_refuses_an_fmi_1_controller"],
    "tuner.studies": ["test_sweep.py::test_points_are_the_laps_run_one_by_one",
                      "test_design.py::test_pareto_front_and_trend_statements"],
}


def packages_on_disk() -> set[str]:
    """Every package (a folder with ``__init__.py``) that pyproject.toml's package search includes."""
    with open(os.path.join(ROOT, "pyproject.toml"), encoding="utf-8") as f:  # (tomllib is Python 3.11+)
        table = re.search(r"^\[tool\.setuptools\.packages\.find\]\s*include\s*=\s*\[(.*?)\]", f.read(), re.M | re.S)
    patterns = re.findall(r'"([^"]+)"', table[1])
    found = set()
    for here, dirs, files in os.walk(ROOT):
        dirs[:] = [d for d in dirs if not d.startswith((".", "_")) and d not in ("build", "tests")]
        name = os.path.relpath(here, ROOT).replace(os.sep, ".")
        if "__init__.py" in files and any(fnmatch.fnmatchcase(name, p) for p in patterns):
            found.add(name)
    return found


def source_of(module: str) -> str | None:
    """The file of a project module or a test helper module, if there is one."""
    base = os.path.join(ROOT, *module.split("."))
    for path in (base + ".py", os.path.join(base, "__init__.py"), os.path.join(TESTS, module + ".py")):
        if os.path.isfile(path):
            return path
    return None


@functools.lru_cache(maxsize=None)
def parsed(path: str) -> ast.Module:
    with open(path, encoding="utf-8") as f:
        return ast.parse(f.read(), path)


def imported(node: ast.AST) -> dict[str, set[str]]:
    """Names bound by the imports inside ``node`` → the modules they come from (``from a import b``: ``a.b`` if
    that is a module, else ``a``)."""
    out: dict[str, set[str]] = {}
    for n in ast.walk(node):
        if isinstance(n, ast.Import):
            for a in n.names:
                out.setdefault(a.asname or a.name.split(".")[0], set()).add(a.name)
        elif isinstance(n, ast.ImportFrom) and n.module and not n.level:
            for a in n.names:
                sub = f"{n.module}.{a.name}"
                out.setdefault(a.asname or a.name, set()).add(sub if source_of(sub) else n.module)
    return out


def modules_used(path: str, test: str) -> set[str]:
    """The modules whose names the test function uses, following the module's own functions it names (fixtures
    and helpers), and the imports inside those functions."""
    tree = parsed(path)
    functions = {n.name: n for n in tree.body if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef))}
    top = imported(ast.Module([n for n in tree.body if isinstance(n, (ast.Import, ast.ImportFrom))], []))
    seen, todo, modules = set(), [test], set()
    while todo:
        name = todo.pop()
        if name in seen or name not in functions:
            continue
        seen.add(name)
        fn = functions[name]
        local = imported(fn)
        names = {n.id for n in ast.walk(fn) if isinstance(n, ast.Name)} | {a.arg for a in fn.args.args}
        for n in names | set(local):
            modules |= top.get(n, set()) | local.get(n, set())
            todo.append(n)
    return modules


def quick_marked(path: str, test: str) -> bool:
    tree = parsed(path)
    for n in tree.body:
        if isinstance(n, ast.Assign) and any(isinstance(t, ast.Name) and t.id == "pytestmark" for t in n.targets):
            if "pytest.mark.quick" in ast.unparse(n.value):
                return True
        if isinstance(n, ast.FunctionDef) and n.name == test:
            return any(ast.unparse(d) == "pytest.mark.quick" for d in n.decorator_list)
    return False


def own(module: str, package: str) -> bool:
    """Whether ``module`` is ``package`` itself or one of its modules outside its subpackages."""
    if module == package:
        return True
    if not module.startswith(package + "."):
        return False
    return source_of(module) is not None and "." not in module[len(package) + 1:]


def reaches(modules: set[str], package: str) -> bool:
    """One of ``modules``, or a module one of them imports, is one of the package's own."""
    for m in modules:
        if own(m, package):
            return True
        path = source_of(m)
        if path and any(own(x, package) for xs in imported(parsed(path)).values() for x in xs):
            return True
    return False


def test_the_map_names_every_package_on_disk():
    on_disk = packages_on_disk()
    assert {"lf_common", "twin.core", "tuner.studies"} <= on_disk  # the search itself works
    assert sorted(on_disk - set(QUICK)) == [], "a package without a quick test: add one to QUICK"
    assert sorted(set(QUICK) - on_disk) == [], "QUICK names a package that is gone"


@pytest.mark.parametrize("package", sorted(QUICK))
def test_each_package_has_a_quick_test_that_reaches_it(package):
    for entry in QUICK[package]:
        file, test = entry.split("::")
        path = os.path.join(TESTS, file)
        assert os.path.isfile(path), entry
        assert test in {n.name for n in parsed(path).body if isinstance(n, ast.FunctionDef)}, f"{entry}: no such test"
        assert quick_marked(path, test), f"{entry}: not marked quick"
        used = modules_used(path, test)
        assert reaches(used, package), f"{entry} does not reach {package} (it uses {sorted(used)})"


def test_the_marks_are_what_pytest_sees(request):
    """The static reading of the marks against pytest's own, for the tests of this session."""
    for item in request.session.items:
        file, _, name = item.nodeid.partition("::")
        entry = f"{os.path.basename(file)}::{name.split('[')[0]}"
        if any(entry in entries for entries in QUICK.values()):
            assert item.get_closest_marker("quick") is not None, entry


def test_the_checks_would_catch_a_gap():
    """The checks themselves: a test that uses no project module reaches nothing; an unmarked one is seen."""
    here = os.path.abspath(__file__)
    assert not reaches(modules_used(here, "test_the_map_names_every_package_on_disk"), "twin.core")
    assert quick_marked(here, "test_the_checks_would_catch_a_gap")  # (by the module's mark)
    assert not quick_marked(os.path.join(TESTS, "test_case2.py"), "test_diagnosis_ranks_a_tired_battery_first_from_the_lap_time")
    assert reaches({"twin.cli.tune"}, "tuner") and not reaches({"twin.cli.tune"}, "tuner.live")


def test_under_ci_a_skip_fails_unless_ci_allows_it(tmp_path):
    """conftest.py's rule, run on a throwaway suite beside a copy of it: under CI a skip (in the test or by a mark)
    fails with its reason; an opt-in skip CI allows and an expected failure stay as they are; outside CI all skip."""
    import shutil
    import subprocess
    import sys

    shutil.copy(os.path.join(TESTS, "conftest.py"), tmp_path)
    (tmp_path / "test_throwaway.py").write_text(
        "import pytest\n"
        "def test_missing(): pytest.skip('needs the frobnicator')\n"
        "@pytest.mark.skipif(True, reason='no compiler')\n"
        "def test_marked(): pass\n"
        "def test_opt_in(): pytest.skip('LIBPOLOLU_AVR is not set')\n"
        "@pytest.mark.xfail(reason='known')\n"
        "def test_known(): assert False\n")

    def outcomes(ci: bool, *flags: str) -> str:
        env = {k: v for k, v in os.environ.items() if k != "CI"} | ({"CI": "1"} if ci else {})
        r = subprocess.run([sys.executable, "-m", "pytest", "-q", "-rA", "-p", "no:cacheprovider", *flags, str(tmp_path)],
                           capture_output=True, text=True, env=env, cwd=tmp_path, timeout=120)
        return r.stdout

    for flags in ((), ("-n", "2", "--dist", "worksteal")):  # alone, and as the README runs the suite (pytest-xdist
        # sends the reports over)
        under_ci = outcomes(True, *flags)
        assert "FAILED test_throwaway.py::test_missing - skipped under CI" in under_ci and "frobnicator" in under_ci
        assert "ERROR test_throwaway.py::test_marked - skipped under CI" in under_ci and "no compiler" in under_ci
        assert "1 skipped, 1 xfailed" in under_ci, under_ci
    assert "3 skipped, 1 xfailed" in outcomes(False)


def test_the_heavy_tests_run_first_by_name():
    """conftest.HEAVY_FIRST (the order the two processes take the heaviest tests in) names tests that exist, so a
    renamed test is not silently left to end the run."""
    from conftest import HEAVY_FIRST

    for entry in HEAVY_FIRST:
        file, test = entry.removeprefix("tests/").split("::")
        path = os.path.join(TESTS, file)
        assert os.path.isfile(path), entry
        assert test.split("[")[0] in {n.name for n in parsed(path).body if isinstance(n, ast.FunctionDef)}, entry
