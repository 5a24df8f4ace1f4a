"""The floor plan holds: rooms (a package, or a package's first subpackage) import one way, the CLI layer sits on
top, nothing imports another package's private names (tests and benchmarks included) or imports by string, each
room names its public API, and no module outgrows one concept (450 lines, Python or C)."""

from __future__ import annotations

import ast
import importlib
import os

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
