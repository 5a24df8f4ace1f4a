"""A controller FMU's parameters set by the twin (``--controller-param NAME=VALUE``), checked against its
modelDescription: the name must be a parameter of the FMU, the value of its type and within its declared min and
max. The values are set after the FMU is instantiated, before its initialisation (as a co-simulation master sets a
multi-model's parameters), so an FMU that ignores its own start values still gets them."""

from __future__ import annotations

import math

from twin.errors import TwinError

REALS = ("Real", "Float64", "Float32")
INTEGERS = ("Integer", "Enumeration", "Int8", "Int16", "Int32", "Int64", "UInt8", "UInt16", "UInt32", "UInt64")
BOOLEANS = {"true": True, "1": True, "false": False, "0": False}


def parse_params(items: list[str] | None) -> dict[str, str]:
    """``["forwardSpeed=0.4", ...]`` → {"forwardSpeed": "0.4"} (the values are typed against the FMU later)."""
    out: dict[str, str] = {}
    for item in items or ():
        name, sep, value = item.partition("=")
        if not sep or not name.strip() or not value.strip():
            raise TwinError(f"--controller-param {item!r}: expected NAME=VALUE, e.g. forwardSpeed=0.4")
        if name.strip() in out:
            raise TwinError(f"--controller-param {item!r}: {name.strip()} is set twice")
        out[name.strip()] = value.strip()
    return out


def _typed(variable, text: str):
    """The value of ``text`` in the variable's type, or None if it is not one."""
    kind = variable.type
    try:
        if kind in REALS:
            value = float(text)
            return value if math.isfinite(value) else None
        if kind in INTEGERS:
            return int(text, 10)
    except ValueError:
        return None
    if kind == "Boolean":
        return BOOLEANS.get(text.lower())
    if kind == "String":
        return text
    return None


def resolve_params(path: str, md, given: dict[str, str],
                   source: str = "--controller-param ") -> list[tuple[str, object]]:
    """[(name, typed value)] for the FMU's parameters, or one TwinError line naming the parameter (after ``source``:
    where it was given) and the fault."""
    variables = {v.name: v for v in md.modelVariables}
    params = [n for n, v in variables.items() if v.causality == "parameter"]
    out = []
    for name, text in given.items():
        v = variables.get(name)
        if v is None or v.causality != "parameter":
            what = f"no parameter {name!r}" if v is None else f"{name} is of causality {v.causality}, not a parameter"
            raise TwinError(f"{source}{name}={text}: {path}: {what} (its parameters: "
                            f"{', '.join(params) or 'none'})")
        value = _typed(v, text)
        if value is None:
            raise TwinError(f"{source}{name}={text}: {name} is of type {v.type}; {text!r} is not a "
                            f"{'finite ' if v.type in REALS else ''}{v.type} value")
        lo, hi = (getattr(v, k, None) for k in ("min", "max"))
        if isinstance(value, (int, float)) and not isinstance(value, bool) and (
                (lo not in (None, "") and value < float(lo)) or (hi not in (None, "") and value > float(hi))):
            raise TwinError(f"{source}{name}={text}: outside its range [{lo or '-inf'}, {hi or 'inf'}]")
        out.append((name, value))
    return out
