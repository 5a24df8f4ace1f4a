"""An INTO-CPS multi-model run against the twin (``lap --multi-model FILE.mm.json --stand-in FILE.json``).

A multi-model (``*.mm.json``, as the INTO-CPS application writes it) names its FMUs (``"fmus": {"{key}":
"file.fmu"}``), connects their instances' variables (``"connections": {"{key}.instance.output": ["{key}.instance.
input", …]}``) and sets parameters (``"parameters": {"{key}.instance.name": value}``). The stand-in file names the
instances the twin replaces (a body, sensor blocks) and, for each variable of theirs that the rest of the
multi-model reads or drives, the twin port it is, as a ``--map`` relation (:mod:`twin.fmi.mapping`):
``"servo_right_input": "-1*wheel_duty_right"``. A sensor block may say where it reads the floor (``"sensor":
{"left_m": …, "ahead_m": …}``, relations of its parameters, which the multi-model sets or its FMU starts with): the
twin's array then stands there (:func:`_place_array`) and the block's sensor port has no index. An instance may give
the outputs it has after its initialisation (``"at_start"``), which the controller reads at its first step, as a
master's initial exchange gives them. What remains must be one FMU instance (the controller): it runs in the twin's
loop as ``--controller-fmu`` does, with the multi-model's parameters and its connections to the replaced instances as
its mapping, stepped at the fixed step of its co-simulation configuration (:func:`coe_step`).

The FMU files are found beside the multi-model or in the ``FMUs`` folder of the INTO-CPS project holding it (the
first folder above it that has one). Refused in one line (TwinError): a file that is not such JSON, an unknown FMU
key or instance, an FMU file that cannot be found, a connection to a variable the FMU does not have, a parameter of
the wrong type, a cycle of algebraic connections (outputs that depend at once on inputs connected, round the
cycle, to themselves), and what the twin cannot stand in for (a variable of a replaced instance the stand-in file
does not map, a connection between two instances the twin does not replace, more than one remaining instance,
sensors that are not a row the twin's array can take). Other parameters of replaced instances (the body's masses)
are not the twin's: :attr:`MultiModelRun.notes` names them.
"""

from __future__ import annotations

import dataclasses
import glob
import functools
import json
import math
import os
import re

import numpy as np

from lf_common.errors import LineFollowerError
from lf_common.files import input_file
from line_sensor.geometry import MAX_SENSORS
from twin.errors import TwinError
from twin.fmi.mapping import Link, parse_map
from twin.fmi.parameters import resolve_params

NAME = re.compile(r"(\{[^{}]+\})\.([^.]+)\.(.+)")  # {key}.instance.variable
PLACE_TOLERANCE_M = 1e-4  # sensors this close to a row of the twin's array stand in as it


@dataclasses.dataclass
class MultiModelRun:
    """What the twin runs for a multi-model: the controller FMU, its mapping and parameters, its step, and notes."""

    fmu: str
    instance: str  # "{key}.instance"
    mapping: dict[str, Link]
    parameters: dict[str, str]
    step_s: float | None
    notes: list[str]
    values: dict[str, float] = dataclasses.field(default_factory=dict)  # the twin's array where the sensors are


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


def _names_it(doc: dict, mm: str) -> bool:
    """The coe file's ``multimodel_path`` (relative to the INTO-CPS project) is this multi-model's path's tail."""
    named = doc.get("multimodel_path")
    if not isinstance(named, str) or not named.strip():
        return False
    tail = os.path.normpath(named.replace("\\", "/")).split(os.sep)
    return os.path.normpath(os.path.abspath(mm)).split(os.sep)[-len(tail):] == tail


def _fixed_step(doc: dict) -> float | None:
    algorithm = doc.get("algorithm") if isinstance(doc.get("algorithm"), dict) else {}
    size = algorithm.get("size")
    if algorithm.get("type") != "fixed-step" or isinstance(size, bool) or not isinstance(size, (int, float)):
        return None
    return float(size) if 0 < size <= 1.0 else None


def coe_step(mm: str, coe: str | None = None) -> tuple[float | None, str | None]:
    """(the fixed step [s] of the multi-model's co-simulation configuration, or None; a note, or None).

    ``coe`` names the file (``--coe``); else the ``*coe.json`` files beside the multi-model and in the folders
    right below it (the INTO-CPS application keeps an experiment's ``*.coe.json`` and each run's ``coe.json``
    there): those whose ``multimodel_path`` names this multi-model come first, then by path; the note says which
    was used and what else was found."""
    if coe is not None:
        doc = _read_json(coe, "--coe")
        step = _fixed_step(doc)
        if step is None:
            raise TwinError(f"--coe {coe}: no fixed step in (0, 1] s (\"algorithm\": {{\"type\": \"fixed-step\", "
                            "\"size\": …})")
        return step, f"the co-simulation step {step:g} s of {coe}"
    here = os.path.dirname(os.path.abspath(mm))
    found = sorted(glob.glob(os.path.join(here, "*coe.json")) + glob.glob(os.path.join(here, "*", "*coe.json")))
    if not found:
        return None, ("no *coe.json beside the multi-model or in a folder right below it: the controller runs at its "
                      "own step (or control.dt); give its co-simulation step with --coe")
    docs = {}
    for path in found:
        try:
            docs[path] = _read_json(path, "--multi-model")
        except TwinError:
            docs[path] = {}  # an unreadable run record is passed over, and named in the note
    steps = {f: _fixed_step(docs[f]) for f in found}
    ranked = sorted(found, key=lambda f: (not _names_it(docs[f], mm), f.count(os.sep), f))
    usable = [f for f in ranked if steps[f] is not None]
    rel = lambda f: os.path.relpath(f, here)  # noqa: E731
    others = ", ".join(f"{rel(f)} ({'step %g s' % steps[f] if steps[f] else 'no fixed step'})"
                       for f in ranked if not usable or f != usable[0])
    if not usable:
        return None, f"no fixed step in (0, 1] s in its coe files ({others}); the controller runs at its own step"
    chosen = usable[0]
    why = "names this multi-model" if _names_it(docs[chosen], mm) else "found first"
    return steps[chosen], (f"the co-simulation step {steps[chosen]:g} s of {rel(chosen)} ({why}; choose another with "
                           "--coe)" + (f"; also found: {others}" if others else ""))


@dataclasses.dataclass
class StandIn:
    """One replaced instance: its variables as twin ports; where it reads the floor if it is a sensor (``left_m``,
    ``ahead_m`` as relations of its parameters); the outputs it gives after its initialisation, if stated."""

    links: dict[str, Link]
    place: dict[str, Link] | None
    at_start: dict[str, float]


SENSOR_PORT = re.compile(r"sensor\.(calibrated|raw|white_8bit)(\[\d+\])?")
PLACE = ("left_m", "ahead_m")
PLACED = ("sensor.count", "sensor.pitch", "cad.S")  # the twin's addresses a placed array sets


def _stand_in(path: str) -> dict[str, StandIn]:
    """{"{key}.instance": StandIn} of the stand-in file."""
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
        where = f"--stand-in {path}: instance {instance}"
        try:
            links = parse_map([f"{name}={relation}" for name, relation in variables.items()])
        except TwinError as e:
            raise TwinError(f"{where}: {e}") from None
        place = entry.get("sensor")
        if place is not None:
            if not isinstance(place, dict) or set(place) != set(PLACE) or not all(isinstance(v, str) for v in
                                                                                   place.values()):
                raise TwinError(f"{where}: \"sensor\" must give left_m and ahead_m as relations of its parameters, "
                                "e.g. {\"left_m\": \"-1*lf_position_x\", \"ahead_m\": \"lf_position_y\"}")
            try:
                place = parse_map([f"{k}={place[k]}" for k in PLACE])
            except TwinError as e:
                raise TwinError(f"{where}: \"sensor\": {e}") from None
        for name, link in links.items():
            m = SENSOR_PORT.fullmatch(link.port)
            if m and bool(m[2]) == (place is not None):
                raise TwinError(f"{where}: {name}={link.expression}: " + (
                    "a sensor placed by its parameters (\"sensor\") reads its own port: write it without an index, "
                    f"e.g. sensor.{m[1]}" if place is not None else
                    f"give the sensor's index (sensor.{m[1]}[i]) or place the instance with \"sensor\""))
        at_start = entry.get("at_start", {})
        if not isinstance(at_start, dict) or any(n not in links for n in at_start) or not all(
                isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in at_start.values()):
            raise TwinError(f"{where}: \"at_start\" must give numbers for variables it maps, e.g. "
                            "{\"lf_1_sensor_reading\": 1}")
        out[instance] = StandIn(links, place, {n: float(v) for n, v in at_start.items()})
    return out


def _place_array(mm: str, places: dict[str, tuple[float, float]]) -> tuple[dict, dict[str, int]]:
    """({address: value} placing the twin's array where the multi-model's sensors are, {instance: sensor index from
    1, leftmost first}), or one TwinError line: the twin's array is an evenly spaced row across the heading, centred
    on it, of 2 to 16 sensors."""
    order = sorted(places, key=lambda i: -places[i][0])
    left = np.array([places[i][0] for i in order])
    ahead = np.array([places[i][1] for i in order])
    shown = ", ".join(f"{i} ({places[i][0] * 1000:+.1f} mm left, {places[i][1] * 1000:.1f} mm ahead)" for i in order)
    spacing = -np.diff(left)
    fits = (2 <= len(order) <= MAX_SENSORS and np.ptp(ahead) <= PLACE_TOLERANCE_M
            and abs(left.mean()) <= PLACE_TOLERANCE_M and (spacing > 0).all() and np.ptp(spacing) <= PLACE_TOLERANCE_M)
    if not fits:
        raise TwinError(f"--multi-model {mm}: cannot be stood in for: the twin's line array is a row of 2 to "
                        f"{MAX_SENSORS} sensors, evenly spaced across the heading and centred on it, at one distance "
                        f"ahead (within {PLACE_TOLERANCE_M * 1000:g} mm); its sensors are at: {shown}")
    values = dict(zip(PLACED, (len(order), float(spacing.mean()), float(ahead.mean()))))
    return values, {instance: k + 1 for k, instance in enumerate(order)}


def _parameter_value(mm: str, fmus: dict, instance: str, name: str, settings: dict) -> float:
    """A replaced instance's parameter: as the multi-model sets it, else its FMU's start value."""
    if (instance, name) in settings:
        value = settings[(instance, name)]
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise TwinError(f"--multi-model {mm}: parameter {instance}.{name} = {value!r}: not a number")
        return float(value)
    file = find_fmu(mm, fmus[instance.split(".")[0]])
    if file is None:
        raise TwinError(f"--multi-model {mm}: {instance}.{name} places a sensor, but the multi-model does not set it "
                        f"and its FMU {fmus[instance.split('.')[0]]} is not found to read its start value")
    try:
        starts = _start_values(file)
    except ValueError as e:  # the archive or its XML
        raise TwinError(f"--multi-model {mm}: {file}: its modelDescription.xml cannot be read ({e})") from None
    try:
        return float(starts[name])
    except (KeyError, TypeError, ValueError):  # no such variable, no start value, or not a number
        raise TwinError(f"--multi-model {mm}: {instance}.{name} places a sensor, but the multi-model does not set it "
                        f"and {os.path.basename(file)} has no such variable with a numeric start value") from None


@functools.lru_cache(maxsize=16)
def _start_values(file: str) -> dict[str, str | None]:
    """{variable: its start value} of an FMU's modelDescription, read once per file (the sensors' places read
    several); ValueError if it cannot be read."""
    from fmpy import read_model_description

    try:
        md = read_model_description(file, validate=False)
    except Exception as e:  # fmpy raises plain exceptions for broken archives and XML
        raise ValueError(" ".join(str(e).split())[:160]) from None
    return {v.name: v.start for v in md.modelVariables}


def _json_text(value) -> str:
    """A multi-model's parameter value as ``--controller-param`` text (typed against the FMU later)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    return value if isinstance(value, str) else repr(value)


def read_multi_model(mm: str, stand_in: str, coe: str | None = None) -> MultiModelRun:
    """The run the twin makes of ``mm`` with the stand-in file ``stand_in`` (and the co-simulation configuration
    ``coe``, else the one found: :func:`coe_step`), or one TwinError line."""
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
    settings = dict((_split(mm, name), value) for name, value in parameters.items())
    instances = {i for pair in pairs for i, _ in pair} | {i for i, _ in settings}
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
    for (a, va), (b, vb) in pairs:
        for instance, name, other in ((a, va, b), (b, vb, a)):
            if instance == controller and name not in variables:
                raise TwinError(f"--multi-model {mm}: connection {a}.{va} -> {b}.{vb}: {controller} "
                                f"({os.path.basename(file)}) has no variable {name!r}")
            if instance in replaced and other == controller and name not in replaced[instance].links:
                raise TwinError(f"--multi-model {mm}: cannot be stood in for: {instance}.{name} (connected to "
                                f"{controller}) is not in the stand-in file {stand_in}")
    _check_cycle(mm, controller, md, pairs)
    notes, values, used = [], {}, set()
    placed = {i: r for i, r in replaced.items() if r.place is not None}
    index: dict[str, int] = {}
    if placed:
        where = {}
        for instance, r in placed.items():
            left, ahead = (link.to_fmu(_parameter_value(mm, fmus, instance, link.port, settings))
                           for link in (r.place["left_m"], r.place["ahead_m"]))
            used |= {(instance, r.place[k].port) for k in PLACE}
            where[instance] = (left, ahead)
        values, index = _place_array(mm, where)
        notes.append(f"the twin's line array stands where the multi-model's sensors are: {values['sensor.count']} "
                     f"sensors {values['sensor.pitch'] * 1000:.4g} mm apart, {values['cad.S'] * 1000:.4g} mm ahead "
                     f"(sensor.count={values['sensor.count']}, sensor.pitch={values['sensor.pitch']:.6g}, "
                     f"cad.S={values['cad.S']:.6g}; from the left: "
                     + ", ".join(f"sensor {k} {i}" for i, k in sorted(index.items(), key=lambda x: x[1])) + ")")
    mapping: dict[str, Link] = {}
    for (a, va), (b, vb) in pairs:
        if a == b == controller:
            raise TwinError(f"--multi-model {mm}: cannot be stood in for: the connection {a}.{va} -> {b}.{vb} "
                            "(the twin connects the controller only to the ports it stands in for)")
        for instance, name, theirs, direction in ((b, vb, va, a == controller), (a, va, vb, b == controller)):
            if instance in replaced and direction:
                r = replaced[instance]
                link = r.links[name]
                port = link.port + (f"[{index[instance]}]" if instance in index and SENSOR_PORT.fullmatch(link.port)
                                    else "")
                mapping[theirs] = dataclasses.replace(link, variable=theirs, port=port, at_start=r.at_start.get(name))
    given = {}
    for (instance, name), value in settings.items():
        if instance == controller:
            given[name] = _json_text(value)
    resolve_params(file, md, given, f"--multi-model {mm}: parameter {controller}.")  # its line names the file
    ignored = [f"{i}.{n} = {v}" for (i, n), v in settings.items() if i != controller and (i, n) not in used]
    if ignored:
        notes.append(f"the twin uses its own robot{'' if placed else ' and sensors'}; not used: {', '.join(ignored)}")
    step, note = coe_step(mm, coe)
    notes += [note] if note else []
    return MultiModelRun(file, controller, mapping, given, step, notes, values)


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
