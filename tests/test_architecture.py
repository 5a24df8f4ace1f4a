"""The floor plan holds: rooms (a package, or a package's first subpackage) import one way, the CLI layer sits on
top and starts without the libraries, nothing imports another package's private names (tests and benchmarks
included) or imports by string, each room names its public API, and no module outgrows one concept (450 lines,
Python or C)."""

from __future__ import annotations

import ast
import importlib
import json
import os
import subprocess
import sys

import pytest

pytestmark = pytest.mark.quick

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
PACKAGES = ("lf_common", "mjcf", "motors", "line_sensor", "twin", "tuner")
SHIMS = ("twin.run", "tuner.__main__", "mjcf.__main__")  # entry points: they import the CLI layer by design
MAX_LINES = 450
MAX_FLAT = {"twin": 8, "tuner": 5}  # modules left beside a package's rooms (its face)
# lower rooms never import higher ones (the house plan's one-way data flow)
BELOW = {"lf_common": set(), "motors": {"lf_common"}, "line_sensor": {"lf_common"},
         "mjcf": {"lf_common", "motors", "line_sensor"}}


def _imports(path: str, module: str) -> list[tuple[str, str | None]]:
    """(imported module, imported name) for every import of one file, at any depth; ("importlib", None) for an
    import by string."""
    out = []
    for node in ast.walk(ast.parse(open(path, encoding="utf-8").read())):
        if isinstance(node, ast.Import):
            out += [(a.name, None) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = module.split(".")
                if path.endswith("__init__.py"):
                    parts = parts + ["__init__"]
                base = ".".join(parts[: len(parts) - node.level] + ([node.module] if node.module else []))
            out += [(base, a.name) for a in node.names]
        elif isinstance(node, ast.Call) and getattr(node.func, "attr", getattr(node.func, "id", "")) in (
                "import_module", "__import__"):
            out.append(("importlib", None))
    return out


def _modules() -> dict[str, str]:
    modules = {}
    for pkg in PACKAGES:
        for here, _, files in os.walk(os.path.join(ROOT, pkg)):
            for f in files:
                if f.endswith(".py"):
                    rel = os.path.relpath(os.path.join(here, f), ROOT)[:-3].replace(os.sep, ".").removesuffix(".__init__")
                    modules[rel] = os.path.join(here, f)
    return modules


def _graph(modules: dict[str, str]) -> tuple[dict[str, set[str]], list[str]]:
    graph = {m: set() for m in modules}
    problems = []
    for m, path in modules.items():
        for mod, name in _imports(path, m):
            top = mod.split(".")[0]
            if top == "importlib":
                problems.append(f"{m}: imports by string")
            if top in PACKAGES and top != m.split(".")[0] and name and name.startswith("_") and not name.startswith("__"):
                problems.append(f"{m}: imports private {mod}.{name}")
            target = f"{mod}.{name}" if name and f"{mod}.{name}" in modules else mod
            if target in modules and target != m:
                graph[m].add(target)
    return graph, problems


def room(module: str) -> str:
    """A module's room: its package, plus its first subpackage if it sits in one (``twin.core``, ``tuner.align``)."""
    parts = module.split(".")
    if len(parts) > 1 and os.path.isdir(os.path.join(ROOT, *parts[:2])):
        return ".".join(parts[:2])
    return parts[0]


def _cycles(graph: dict[str, set[str]]) -> list[str]:
    state: dict[str, int] = {}
    found = []

    def visit(m, stack):
        state[m] = 1
        for d in sorted(graph.get(m, ())):
            if state.get(d) == 1:
                found.append(" -> ".join(stack[stack.index(d):] + [d]))
            elif d not in state:
                visit(d, stack + [d])
        state[m] = 2

    for m in sorted(graph):
        if m not in state:
            visit(m, [m])
    return found


def test_no_cycles_between_modules_or_rooms_and_no_string_or_private_imports():
    modules = _modules()
    graph, problems = _graph(modules)
    problems += [f"cycle: {c}" for c in _cycles(graph)]
    rooms: dict[str, set[str]] = {}
    for m, deps in graph.items():
        if m in SHIMS:
            continue
        rooms.setdefault(room(m), set()).update(room(d) for d in deps if room(d) != room(m))
    problems += [f"cycle between rooms: {c}" for c in _cycles(rooms)]
    for low, allowed in BELOW.items():
        for r, deps in rooms.items():
            if room(r) == low or r.split(".")[0] == low:
                above = {d.split(".")[0] for d in deps} - allowed - {low}
                if above:
                    problems.append(f"{r} imports higher packages {sorted(above)}")
    assert not problems, problems


def test_the_cli_layer_is_on_top():
    graph, _ = _graph(_modules())
    for m, deps in graph.items():
        if not m.startswith("twin.cli") and m not in SHIMS:
            assert not any(d.startswith("twin.cli") for d in deps), f"{m} imports the CLI layer"


# what the command line must not load before a command does its work: each costs tens to hundreds of ms of CPU
HEAVY = ("mujoco", "numpy", "scipy", "trimesh", "yourdfpy", "rerun", "matplotlib", "sqlalchemy", "alembic", "fmpy",
         "SALib", "ray", "serial", "PIL", "networkx", "contourpy", "pandas", "pyarrow", "elftools", "xacro", "tqdm")

# in a fresh interpreter: import every module of the CLI layer and the entry points, show every command's --help and
# refuse a bad flag of each; print the exit codes and which heavy libraries got loaded
STARTUP = """
import argparse, contextlib, importlib, io, json, pkgutil, sys
import twin.cli
for info in pkgutil.iter_modules(twin.cli.__path__):
    importlib.import_module("twin.cli." + info.name)
import twin.run, tuner.__main__, mjcf.__main__  # (their __main__ guards keep them from running)
from twin.cli import main, robot, tune
commands = [n for a in main.parser()._actions if isinstance(a, argparse._SubParsersAction) for n in a.choices]
runs = [(main.main, [c, "--help"], 0) for c in commands] + [(main.main, [c, "--no-such-flag"], 2) for c in commands]
runs += [(main.main, ["--help"], 0), (main.main, ["lap", "--seed", "abc"], 2), (tune.main, ["--help"], 0),
         (tune.main, ["--seed", "abc"], 2), (robot.main, ["convert", "--help"], 0), (robot.main, ["generate", "-x"], 2)]
with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
    codes = [(argv, entry(argv), want) for entry, argv, want in runs]
loaded = sorted({m.split(".")[0] for m in sys.modules} & set(sys.argv[1].split(",")))
print(json.dumps({"commands": commands, "codes": codes, "loaded": loaded}))
"""


def test_the_command_line_starts_without_the_libraries():
    """``--help`` and a refused flag take an instant: the CLI layer loads MuJoCo, NumPy, SciPy, rerun, … only when a
    command does its work (inside ``twin.cli.startup.loading``), never at import or while it builds its parsers."""
    r = subprocess.run([sys.executable, "-c", STARTUP, ",".join(HEAVY)], capture_output=True, text=True, timeout=120,
                       cwd=ROOT)
    assert r.returncode == 0, r.stderr[-3000:]
    found = json.loads(r.stdout)
    assert len(found["commands"]) >= 15 and "lap" in found["commands"], found["commands"]
    wrong = [(argv, code, want) for argv, code, want in found["codes"] if code != want]
    assert not wrong, f"exit codes (argv, got, wanted): {wrong}"
    assert not found["loaded"], f"the command line loads libraries before any command runs: {found['loaded']}"


def test_the_command_line_loads_the_libraries_inside_loading():
    """Where a command loads a library (any import in a function, but the standard library's and the CLI's own), it
    does so inside ``with loading():``, where Ctrl-C ends the process at once: a KeyboardInterrupt in the middle of
    an extension module's import can become an ImportError that the library swallows, and the Ctrl-C is lost."""
    unguarded = []
    for here, _, files in os.walk(os.path.join(ROOT, "twin", "cli")):
        for f in (f for f in files if f.endswith(".py")):
            path = os.path.join(here, f)
            _find_unguarded(ast.parse(open(path, encoding="utf-8").read()), False, False, os.path.relpath(path, ROOT),
                            unguarded)
    assert not unguarded, f"imports of libraries outside 'with loading():' in the CLI layer: {unguarded}"


def _find_unguarded(node: ast.AST, in_function: bool, guarded: bool, where: str, found: list[str]) -> None:
    if isinstance(node, (ast.Import, ast.ImportFrom)) and in_function and not guarded:
        names = [node.module or ""] if isinstance(node, ast.ImportFrom) else [a.name for a in node.names]
        if any(n.split(".")[0] not in sys.stdlib_module_names and not n.startswith("twin.cli") for n in names):
            found.append(f"{where}:{node.lineno}")
    in_function = in_function or isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef))
    guarded = guarded or (isinstance(node, ast.With) and any(
        isinstance(i.context_expr, ast.Call) and getattr(i.context_expr.func, "id", "") == "loading" for i in node.items))
    for child in ast.iter_child_nodes(node):
        _find_unguarded(child, in_function, guarded, where, found)


def test_the_values_the_flags_quote_are_the_libraries_own():
    """twin.cli.library_values copies what the flags' help and choices quote, so that building the parsers loads no
    library; each copy must equal its source."""
    from tuner.align.diagnose import DEFAULT_CANDIDATES
    from tuner.align.lap_time import ACCEPT, TOLERANCE
    from tuner.live import ActOptions
    from tuner.search.envelope import ROBUST_AXES, ROBUST_RISK, ROBUST_SEEDS
    from tuner.sensitivity.laps import MAX_SOBOL, SAMPLES, TRAJECTORIES
    from tuner.studies.design import DEFAULT_GRID
    from twin.cli import library_values as lib
    from twin.fmi import CLOSED_LOOP, KINDS, PLANT
    from twin.link.reader import FSYNC_INTERVAL_S, RETRY_S
    from twin.link.robot_end import COMMAND_MODES
    from twin.model.motor_setup import MOTOR_MODEL
    from twin.model.robots import ROBOTS
    from twin.pil.firmware import BOARD
    from twin.pil.lap import TELEMETRY_EVERY

    act = ActOptions()
    pairs = {
        "ROBOT_NAMES": (lib.ROBOT_NAMES, tuple(ROBOTS)), "MOTOR_MODEL": (lib.MOTOR_MODEL, MOTOR_MODEL),
        "ALIGN_TOLERANCE": (lib.ALIGN_TOLERANCE, TOLERANCE), "ALIGN_ACCEPT": (lib.ALIGN_ACCEPT, ACCEPT),
        "DIAGNOSE_CANDIDATES": (lib.DIAGNOSE_CANDIDATES, DEFAULT_CANDIDATES), "DESIGN_GRID": (lib.DESIGN_GRID, DEFAULT_GRID),
        "ROBUST_AXES": (lib.ROBUST_AXES, ROBUST_AXES), "ROBUST_SEEDS": (lib.ROBUST_SEEDS, ROBUST_SEEDS),
        "ROBUST_RISK": (lib.ROBUST_RISK, ROBUST_RISK), "SENSITIVITY_SAMPLES": (lib.SENSITIVITY_SAMPLES, SAMPLES),
        "SENSITIVITY_TRAJECTORIES": (lib.SENSITIVITY_TRAJECTORIES, TRAJECTORIES),
        "SENSITIVITY_MAX_SOBOL": (lib.SENSITIVITY_MAX_SOBOL, MAX_SOBOL),
        "ACT_EVERY_LAPS": (lib.ACT_EVERY_LAPS, act.every_laps), "ACT_CONFIRM_LAPS": (lib.ACT_CONFIRM_LAPS, act.confirm_laps),
        "ACT_ACK_TIMEOUT_S": (lib.ACT_ACK_TIMEOUT_S, act.ack_timeout_s), "ACT_STORE_TRIES": (lib.ACT_STORE_TRIES, act.store_tries),
        "LINK_FSYNC_INTERVAL_S": (lib.LINK_FSYNC_INTERVAL_S, FSYNC_INTERVAL_S), "LINK_RETRY_S": (lib.LINK_RETRY_S, RETRY_S),
        "COMMAND_MODES": (lib.COMMAND_MODES, COMMAND_MODES), "FIRMWARE_BOARD": (lib.FIRMWARE_BOARD, BOARD),
        "TELEMETRY_EVERY": (lib.TELEMETRY_EVERY, TELEMETRY_EVERY), "FMU_PLANT": (lib.FMU_PLANT, PLANT),
        "FMU_CLOSED_LOOP": (lib.FMU_CLOSED_LOOP, CLOSED_LOOP), "FMU_KINDS": (lib.FMU_KINDS, KINDS),
    }
    copied = {n for n in vars(lib) if n.isupper()}
    assert copied == set(pairs), f"checked here but not in library_values, or the reverse: {copied ^ set(pairs)}"
    differ = {name: (here, there) for name, (here, there) in pairs.items() if here != there}
    assert not differ, f"twin.cli.library_values differs from the library (here, there): {differ}"


def test_tests_and_benchmarks_use_public_names_only():
    problems = []
    for extra in ("tests", "benchmarks", "docs"):
        for here, _, files in os.walk(os.path.join(ROOT, extra)):
            for f in (f for f in files if f.endswith(".py")):
                path = os.path.join(here, f)
                for mod, name in _imports(path, "tests.x"):
                    if mod.split(".")[0] in PACKAGES and name and name.startswith("_") and not name.startswith("__"):
                        problems.append(f"{os.path.relpath(path, ROOT)}: imports private {mod}.{name}")
    assert not problems, problems


def test_each_room_names_its_public_api():
    for pkg in ("twin", "tuner"):
        subs = [d for d in sorted(os.listdir(os.path.join(ROOT, pkg)))
                if os.path.isfile(os.path.join(ROOT, pkg, d, "__init__.py"))]
        assert len(subs) >= 4, f"{pkg} has only {len(subs)} rooms"
        flat = [f for f in os.listdir(os.path.join(ROOT, pkg)) if f.endswith(".py") and f != "__init__.py"]
        assert len(flat) <= MAX_FLAT[pkg], f"{pkg} keeps {len(flat)} flat modules: {sorted(flat)}"
        for sub in subs:
            if sub == "cli":
                continue  # commands, not a library: its face is python -m twin.run
            mod = importlib.import_module(f"{pkg}.{sub}")
            assert mod.__doc__, f"{pkg}.{sub} has no docstring saying what it holds"
            names = getattr(mod, "__all__", None)
            assert names, f"{pkg}.{sub} names no public API (__all__)"
            for name in names:
                assert hasattr(mod, name), f"{pkg}.{sub}.__all__ names {name}, which it does not have"
            for f in os.listdir(os.path.join(ROOT, pkg, sub)):  # an exported function must not hide its module
                leaf = f.removesuffix(".py")
                if f.endswith(".py") and leaf != "__init__" and hasattr(mod, leaf):
                    assert isinstance(getattr(mod, leaf), type(os)), f"{pkg}.{sub}.{leaf} is not the module {leaf}"


def test_no_module_outgrows_one_concept():
    long = []
    for top in (*PACKAGES, "tests", "benchmarks", "docs"):
        for here, _, files in os.walk(os.path.join(ROOT, top)):
            for f in files:
                if f.endswith((".py", ".c", ".h")):
                    path = os.path.join(here, f)
                    with open(path, encoding="utf-8") as fh:
                        n = sum(1 for _ in fh)
                    if n > MAX_LINES:
                        long.append(f"{os.path.relpath(path, ROOT)}: {n} lines")
    assert not long, long
