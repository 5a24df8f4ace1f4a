"""Parameter files: model-space values as JSON, written by the tuner and the aligners, read by every command
that builds a twin.

Two kinds, one format (an object of addresses and numbers, provenance beside it):

* a **gains file** holds ``control.*`` addresses only, under ``"gains"``: ``{"gains": {"control.kp": 20}}``.
  ``--gains FILE`` reads it (a bare object of addresses is accepted too, and keys may omit ``control.``);
* a **parameter file** holds any addresses, under ``"parameters"``: ``{"parameters": {"motion.mu": 0.62}}``.
  ``--params FILE`` reads it, and a gains file too.

A gains file written by ``tune -o`` or ``design`` also records what it was tuned for (``"tuned_for"``: robot, motor,
track; :mod:`twin.core.identity`), so a command that loads it can say when it runs another robot.

Files are read with a size limit (1 MB) and every value is checked by the model space.
"""

from __future__ import annotations

import math

from lf_common.files import parse_json, read_text, write_json
from twin.errors import TwinError
from twin.model.space import ModelSpace

MAX_BYTES = 2**20
_JSON_KINDS = {list: "an array", str: "a string", int: "a number", float: "a number", bool: "true or false",
               type(None): "null"}


def _values(path: str, doc, kind: str) -> dict:
    """The address → value object inside a document of either kind."""
    if isinstance(doc, dict):
        for key in ("gains", "parameters"):
            if key in doc:
                if not isinstance(doc[key], dict):
                    raise TwinError(f"{path}: \"{key}\" must be an object of addresses and numbers, not "
                                    f"{_JSON_KINDS.get(type(doc[key]), 'that')}")
                if kind == "gains" and key == "parameters":
                    raise TwinError(f"{path}: a parameter file (any addresses), not a gains file (control.* only)")
                return doc[key]
    if kind == "gains" and isinstance(doc, dict) and "generator" not in doc:
        return doc  # a hand-written bare object of gains
    raise TwinError(f"{path}: expected an object of addresses and numbers under \"{kind}\", e.g. "
                    + ('{"gains": {"control.kp": 20}}' if kind == "gains" else '{"parameters": {"motion.mu": 0.6}}'))


def load_values(path: str, space: ModelSpace, kind: str = "parameters") -> dict[str, float]:
    """Read and check a gains file (``kind="gains"``: control.* only) or a parameter file; {address: value}."""
    doc = parse_json(read_text(path, MAX_BYTES, f"{kind} file"), path)
    values = _values(path, doc, kind)
    if not values:
        raise TwinError(f"{path}: holds no {kind}")
    out = {}
    for key, value in values.items():
        address = key if "." in key or kind != "gains" else f"control.{key}"
        if kind == "gains" and not address.startswith("control."):
            raise TwinError(f"{path}: {key}: a gains file holds control.* parameters only (other addresses go in a parameter file)")
        try:
            parameter = space.parameter(address)
        except TwinError as e:
            raise TwinError(f"{path}: {e}") from None
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise TwinError(f"{path}: {address}: not a number: {str(value)[:40]!r}")
        out[address] = parameter.check(f"{path}: {address}", value)
    return out


def tuned_for_record(path: str) -> dict | None:
    """The ``"tuned_for"`` record a gains file carries (what its gains were tuned for), or None."""
    doc = parse_json(read_text(path, MAX_BYTES, "gains file"), path)
    record = doc.get("tuned_for") if isinstance(doc, dict) else None
    return record if isinstance(record, dict) else None


def load_gains(path: str, space: ModelSpace) -> dict[str, float]:
    """A gains file's ``control.*`` values, checked."""
    return load_values(path, space, "gains")


def save_values(path: str, values: dict[str, float], **provenance) -> str:
    """Write values atomically as a gains file when they are all ``control.*``, else as a parameter file;
    replaces only a file this program wrote. Returns the path."""
    for address, value in values.items():
        if not math.isfinite(value):
            raise TwinError(f"{address}: refusing to write a non-finite value ({value!r})")
    kind = "gains" if all(a.startswith("control.") for a in values) else "parameters"
    return write_json(path, {kind: values, **provenance}, f"{kind} file")
