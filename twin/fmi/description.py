"""modelDescription.xml of the twin's FMUs, FMI 2.0 or 3.0 Co-Simulation, from the variable table (laid out as the
Modelica Reference FMUs lay theirs out: an independent ``time``, outputs listed again as initial unknowns, log
categories for status messages).

Every used unit is declared with its SI base units; parameters carry start, min and max; outputs are calculated
(no start) and listed in the model structure as outputs and initial unknowns. The plant's outputs do not depend
on its inputs at the same instant (``dependencies=""``): voltages act through the motors' dynamics, so a master
may close a loop around it without an algebraic loop.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from typing import Sequence

from lf_common.files import GENERATOR
from lf_common import VERSION
from twin.fmi.variables import UNITS, Variable

FMI3_TYPES = {"Real": "Float64", "Integer": "Int32", "Boolean": "Boolean", "UInt64": "UInt64"}
LOG_CATEGORIES = (("logEvents", "what the FMU does (with logging on)"),
                  ("logStatusWarning", "the lap ended early, and why"),
                  ("logStatusError", "calls and values the FMU refuses"))


def _value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    return repr(v) if isinstance(v, float) else str(v)


def _units(root: ET.Element, variables: Sequence[Variable]) -> None:
    used = sorted({v.unit for v in variables if v.unit}, key=lambda u: UNITS[u][0])
    if not used:
        return
    defs = ET.SubElement(root, "UnitDefinitions")
    for unit in used:
        name, base, factor = UNITS[unit]
        u = ET.SubElement(defs, "Unit", name=name)
        attrs = {k: str(e) for k, e in base.items()}
        if factor != 1.0:
            attrs["factor"] = repr(factor)
        ET.SubElement(u, "BaseUnit", attrs)


def _common(root: ET.Element, variables: Sequence[Variable], stop_time: float, step: float) -> None:
    _units(root, variables)
    cats = ET.SubElement(root, "LogCategories")
    for name, text in LOG_CATEGORIES:
        ET.SubElement(cats, "Category", name=name, description=text)
    ET.SubElement(root, "DefaultExperiment", startTime="0", stopTime=_value(float(stop_time)),
                  stepSize=_value(float(step)))


def _attributes(v: Variable) -> dict[str, str]:
    """Type-specific attributes: unit, start, min, max."""
    a = {}
    if v.unit:
        a["unit"] = v.fmi_unit
    if v.start is not None:
        a["start"] = _value(bool(v.start) if v.type == "Boolean" else v.start)
    if v.lower is not None:
        a["min"] = _value(v.lower)
    if v.upper is not None:
        a["max"] = _value(v.upper)
    return a


def _head(v: Variable, vr: int) -> dict[str, str]:
    a = {"name": v.name, "valueReference": str(vr), "description": v.description, "causality": v.causality,
         "variability": v.variability}
    if v.causality == "parameter":
        a["initial"] = "exact"
    return a


# what differs between the two standards' root and Co-Simulation elements (the rest is common)
ROOT = {2: ("guid", {"fmiVersion": "2.0", "numberOfEventIndicators": "0"}),
        3: ("instantiationToken", {"fmiVersion": "3.0"})}
CO_SIMULATION = {
    2: {"canNotUseMemoryManagementFunctions": "true", "canBeInstantiatedOnlyOncePerProcess": "false",
        "canGetAndSetFMUstate": "false", "canSerializeFMUstate": "false"},
    3: {"canGetAndSetFMUState": "false", "canSerializeFMUState": "false", "providesAdjointDerivatives": "false",
        "hasEventMode": "false"},
}


def _variables_and_structure(root: ET.Element, variables: Sequence[Variable], fmi_version: int,
                             dependency_free: bool) -> None:
    outputs = [i for i, v in enumerate(variables) if v.causality == "output"]
    free = {"dependencies": ""} if dependency_free else {}
    mv = ET.SubElement(root, "ModelVariables")
    for vr, v in enumerate(variables):
        if fmi_version == 2:
            sv = ET.SubElement(mv, "ScalarVariable", _head(v, vr))
            ET.SubElement(sv, "Integer" if v.type == "UInt64" else v.type, _attributes(v))
        else:
            ET.SubElement(mv, FMI3_TYPES[v.type], {**_head(v, vr), **_attributes(v)})
    ms = ET.SubElement(root, "ModelStructure")
    if fmi_version == 2:  # unknowns by their 1-based index among the variables
        outs, init = ET.SubElement(ms, "Outputs"), ET.SubElement(ms, "InitialUnknowns")
        for i in outputs:
            ET.SubElement(outs, "Unknown", {"index": str(i + 1), **free})
            ET.SubElement(init, "Unknown", index=str(i + 1))
    else:  # by value reference
        for i in outputs:
            ET.SubElement(ms, "Output", {"valueReference": str(i), **free})
        for i in outputs:
            ET.SubElement(ms, "InitialUnknown", valueReference=str(i))


def model_description(variables: Sequence[Variable], fmi_version: int, model_identifier: str, token: str,
                      description: str, stop_time: float, step: float, dependency_free: bool) -> bytes:
    """The XML document. ``dependency_free``: outputs do not depend directly on inputs (the plant)."""
    token_name, version = ROOT[fmi_version]
    root = ET.Element("fmiModelDescription", {**version, "modelName": model_identifier, token_name: token,
                                              "description": description, "generationTool": f"{GENERATOR} {VERSION}",
                                              "variableNamingConvention": "structured"})
    ET.SubElement(root, "CoSimulation", {"modelIdentifier": model_identifier,
                                         "canHandleVariableCommunicationStepSize": "true",
                                         "providesDirectionalDerivative": "false", **CO_SIMULATION[fmi_version]})
    _common(root, variables, stop_time, step)
    _variables_and_structure(root, variables, fmi_version, dependency_free)
    ET.indent(root, space="  ")
    return b'<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="utf-8", xml_declaration=False) + b"\n"
