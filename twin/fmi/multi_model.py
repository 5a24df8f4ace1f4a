"""An INTO-CPS multi-model run against the twin (``lap --multi-model FILE.mm.json --stand-in FILE.json``).

A multi-model (``*.mm.json``, as the INTO-CPS application writes it) names its FMUs (``"fmus": {"{key}":
"file.fmu"}``), connects their instances' variables (``"connections": {"{key}.instance.output": ["{key}.instance.
input", …]}``) and sets parameters (``"parameters": {"{key}.instance.name": value}``). The stand-in file names the
instances the twin replaces (a body, sensor blocks) and, for each variable of theirs that the rest of the
multi-model reads or drives, the twin port it is, as a ``--map`` relation (:mod:`twin.fmi.mapping`):
``"servo_right_input": "-1*wheel_duty_right"``. What remains must be one FMU instance (the controller): it runs in
the twin's loop as ``--controller-fmu`` does, with the multi-model's parameters and its connections to the replaced
instances as its mapping, stepped at the fixed step of a ``*.coe.json`` beside the multi-model if there is one.

The FMU files are found beside the multi-model or in the ``FMUs`` folder of the INTO-CPS project holding it (the
first folder above it that has one). Refused in one line (TwinError): a file that is not such JSON, an unknown FMU
key or instance, an FMU file that cannot be found, a connection to a variable the FMU does not have, a parameter of
the wrong type, a cycle of algebraic connections (outputs that depend at once on inputs connected, round the
cycle, to themselves), and what the twin cannot stand in for (a variable of a replaced instance the stand-in file
does not map, a connection between two instances the twin does not replace, more than one remaining instance).
Parameters of replaced instances (a sensor's position, the body's masses) are not the twin's: :attr:`notes` names
them.
"""

from __future__ import annotations

import dataclasses
import glob
import json
import os
import re

from lf_common.errors import LineFollowerError
from lf_common.files import input_file
from twin.errors import TwinError
from twin.fmi.mapping import Link, parse_map
from twin.fmi.parameters import resolve_params

NAME = re.compile(r"(\{[^{}]+\})\.([^.]+)\.(.+)")  # {key}.instance.variable


@dataclasses.dataclass
class MultiModelRun:
    """What the twin runs for a multi-model: the controller FMU, its mapping and parameters, its step, and notes."""

    fmu: str
    instance: str  # "{key}.instance"
    mapping: dict[str, Link]
    parameters: dict[str, str]
    step_s: float | None
    notes: list[str]


def _read_json(path: str, flag: str) -> dict:
    try:
        input_file(path, "file")
    except LineFollowerError as e:
        raise TwinError(f"{flag} {e}") from None
    try:
        with open(path, encoding="utf-8") as f:
            doc = json.load(f)
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise TwinError(f"{flag} {path}: not JSON ({' '.join(str(e).split())[:160]})") from None
    if not isinstance(doc, dict):
        raise TwinError(f"{flag} {path}: not a JSON object")
    return doc


def _split(mm: str, name: str) -> tuple[str, str]:
    """("{key}.instance", variable) of a multi-model name."""
    m = NAME.fullmatch(name) if isinstance(name, str) else None
    if m is None:
        raise TwinError(f"--multi-model {mm}: {name!r} is not {{FMU}}.instance.variable")
    return f"{m[1]}.{m[2]}", m[3]


def find_fmu(mm: str, file: str) -> str | None:
    """The FMU file beside the multi-model, else in the FMUs folder of the first folder above it that has one."""
    here = os.path.dirname(os.path.abspath(mm))
    if os.path.isfile(os.path.join(here, file)):
        return os.path.join(here, file)
    folder = here
    while True:
        if os.path.isdir(os.path.join(folder, "FMUs")):
            candidate = os.path.join(folder, "FMUs", file)
            return candidate if os.path.isfile(candidate) else None
        parent = os.path.dirname(folder)
        if parent == folder:
            return None
        folder = parent


def coe_step(mm: str) -> tuple[float | None, str | None]:
    """(the fixed step [s] of the one ``*.coe.json`` beside the multi-model, or None; a note, or None)."""
    found = sorted(glob.glob(os.path.join(os.path.dirname(os.path.abspath(mm)), "*coe.json")))
    if not found:
        return None, None
    doc = _read_json(found[0], "--multi-model")
    algorithm = doc.get("algorithm") or {}
    size = algorithm.get("size")
    if algorithm.get("type") != "fixed-step" or not isinstance(size, (int, float)) or not 0 < size <= 1.0:
        return None, f"{found[0]}: not a fixed step in (0, 1] s; the controller runs at its own step"
    return float(size), None


def _stand_in(path: str) -> dict[str, dict[str, Link]]:
    """{"{key}.instance": {variable: Link}} of the stand-in file."""
    doc = _read_json(path, "--stand-in")
    instances = doc.get("instances")
    if not isinstance(instances, dict) or not instances:
        raise TwinError(f"--stand-in {path}: no \"instances\" object naming the instances the twin replaces")
    out = {}
    for instance, entry in instances.items():
        variables = entry.get("variables") if isinstance(entry, dict) else None
        if not isinstance(variables, dict) or not all(isinstance(v, str) for v in variables.values()):
            raise TwinError(f"--stand-in {path}: instance {instance!r} has no \"variables\" object of "
                            "variable: relation strings")
        try:
            out[instance] = parse_map([f"{name}={relation}" for name, relation in variables.items()])
        except TwinError as e:
            raise TwinError(f"--stand-in {path}: instance {instance}: {e}") from None
    return out


def _json_text(value) -> str:
    """A multi-model's parameter value as ``--controller-param`` text (typed against the FMU later)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    return value if isinstance(value, str) else repr(value)


def read_multi_model(mm: str, stand_in: str) -> MultiModelRun:
    """The run the twin makes of ``mm`` with the stand-in file ``stand_in``, or one TwinError line."""
    doc = _read_json(mm, "--multi-model")
    fmus, connections = doc.get("fmus"), doc.get("connections", {})
    parameters = doc.get("parameters", {})
    if not isinstance(fmus, dict) or not fmus or not isinstance(connections, dict) or not isinstance(parameters, dict):
        raise TwinError(f"--multi-model {mm}: not an INTO-CPS multi-model (\"fmus\", \"connections\" and "
                        "\"parameters\" objects)")
    replaced = _stand_in(stand_in)
    pairs = []  # (from, to) as ("{key}.instance", variable)
    for source, targets in connections.items():
        if not isinstance(targets, list):
            raise TwinError(f"--multi-model {mm}: connection {source}: not a list of inputs")
        pairs += [(_split(mm, source), _split(mm, t)) for t in targets]
    settings = [(_split(mm, name), value) for name, value in parameters.items()]
    instances = {i for pair in pairs for i, _ in pair} | {i for (i, _), _ in settings}
    for instance in sorted(instances):
        key = instance.split(".")[0]
        if key not in fmus:
            raise TwinError(f"--multi-model {mm}: unknown FMU {key} (in {instance}; its FMUs: {', '.join(fmus)})")
    for instance in replaced:
        if instance not in instances:
            raise TwinError(f"--stand-in {stand_in}: the multi-model has no instance {instance} "
                            f"(it has: {', '.join(sorted(instances))})")
    remaining = sorted(instances - set(replaced))
    if len(remaining) != 1:
        raise TwinError(f"--multi-model {mm}: cannot be stood in for: {len(remaining)} instances remain besides "
                        f"the twin ({', '.join(remaining) or 'none'}); the twin runs one controller FMU")
    (controller,) = remaining
    file = find_fmu(mm, fmus[controller.split(".")[0]])
    if file is None:
        raise TwinError(f"--multi-model {mm}: FMU {fmus[controller.split('.')[0]]} ({controller}) is neither beside "
                        "it nor in the FMUs folder of an INTO-CPS project above it")
    from twin.fmi.controller import read_controller

    md = read_controller(file)
    variables = {v.name: v for v in md.modelVariables}
    mapping: dict[str, Link] = {}
    for (a, va), (b, vb) in pairs:
        for instance, name, other in ((a, va, b), (b, vb, a)):
            if instance == controller and name not in variables:
                raise TwinError(f"--multi-model {mm}: connection {a}.{va} -> {b}.{vb}: {controller} "
                                f"({os.path.basename(file)}) has no variable {name!r}")
            if instance in replaced and other == controller and name not in replaced[instance]:
                raise TwinError(f"--multi-model {mm}: cannot be stood in for: {instance}.{name} (connected to "
                                f"{controller}) is not in the stand-in file {stand_in}")
    _check_cycle(mm, controller, md, pairs)
    for (a, va), (b, vb) in pairs:
        if a == b == controller:
            raise TwinError(f"--multi-model {mm}: cannot be stood in for: the connection {a}.{va} -> {b}.{vb} "
                            "(the twin connects the controller only to the ports it stands in for)")
        if a == controller and b in replaced:  # the controller drives a twin port
            link = replaced[b][vb]
            mapping[va] = Link(va, link.port, link.scale, link.offset, link.scaled)
        elif b == controller and a in replaced:  # a twin port feeds the controller
            link = replaced[a][va]
            mapping[vb] = Link(vb, link.port, link.scale, link.offset, link.scaled)
    notes, given = [], {}
    for (instance, name), value in settings:
        if instance == controller:
            given[name] = _json_text(value)
    resolve_params(file, md, given, f"--multi-model {mm}: parameter {controller}.")  # its line names the file
    ignored = [f"{i}.{n} = {v}" for (i, n), v in settings if i != controller]
    if ignored:
        notes.append(f"the twin uses its own robot and sensors; not used: {', '.join(ignored)}")
    step, note = coe_step(mm)
    notes += [note] if note else []
    return MultiModelRun(file, controller, mapping, given, step, notes)


def _check_cycle(mm: str, controller: str, md, pairs) -> None:
    """Refuse connections from the controller to itself that close an algebraic loop: an output connected to an
    input that it depends on at once (no ``dependencies`` attribute: on every input, as FMI 2 reads it)."""
    inputs = {v.name for v in md.modelVariables if v.causality == "input"}
    depends = {u.variable.name: (inputs if u.dependencies is None else {d.name for d in u.dependencies})
               for u in md.outputs}
    edges = {}
    for (a, va), (b, vb) in pairs:
        if a == controller and b == controller:
            edges.setdefault(va, set()).add(vb)
    for out, ins in edges.items():
        seen, todo = set(), list(ins)
        while todo:
            i = todo.pop()
            if i in seen:
                continue
            seen.add(i)
            for o, targets in edges.items():
                if i in depends.get(o, inputs):
                    if o == out:
                        raise TwinError(f"--multi-model {mm}: a cycle of algebraic connections: {controller}.{out} "
                                        f"feeds {controller}.{i}, on which it depends at once")
                    todo += targets
