"""Gains files: the control parameters (Eq. 13's x and the rest of ``control.*``) as JSON.

Format: one object mapping addresses to numbers, e.g. ``{"control.v_max": 0.8, "control.kp": 20}``; a
``{"gains": {...}}`` wrapper (what the tuner writes, with its provenance beside) is accepted too. Keys may
omit the ``control.`` prefix. Only ``control.*`` addresses belong in a gains file.
"""

from __future__ import annotations

import json
import math
import os

from twin.errors import TwinError
from twin.model_space import ModelSpace


def load_gains(path: str, space: ModelSpace) -> dict[str, float]:
    """Read and check a gains file against the model space; returns {address: value}."""
    try:
        with open(path) as f:
            doc = json.load(f)
    except FileNotFoundError:
        raise TwinError(f"{path}: no such gains file") from None
    except (OSError, UnicodeDecodeError) as e:
        raise TwinError(f"{path}: cannot read ({getattr(e, 'strerror', None) or e})") from None
    except json.JSONDecodeError as e:
        raise TwinError(f"{path}: not JSON (line {e.lineno}, column {e.colno}: {e.msg})") from None
    if isinstance(doc, dict) and isinstance(doc.get("gains"), dict):
        doc = doc["gains"]
    if not isinstance(doc, dict) or not doc:
        raise TwinError(f"{path}: expected an object of control addresses and numbers, e.g. {{\"control.kp\": 20}}")
    out = {}
    for key, value in doc.items():
        address = key if "." in key else f"control.{key}"
        if not address.startswith("control."):
            raise TwinError(f"{path}: {key}: a gains file holds control.* parameters only")
        try:
            space.parameter(address)
        except TwinError as e:
            raise TwinError(f"{path}: {e}") from None
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise TwinError(f"{path}: {address}: not a number: {value!r}")
        out[address] = space.parameter(address).check(f"{path}: {address}", value)
    return out


def save_gains(path: str, gains: dict[str, float], **provenance) -> str:
    """Write ``{"gains": {...}, **provenance}`` atomically; returns the path."""
    for address, value in gains.items():
        if not math.isfinite(value):
            raise TwinError(f"{address}: refusing to write a non-finite gain ({value!r})")
    path = os.path.abspath(path)
    tmp = f"{path}.{os.getpid()}.tmp"
    try:
        with open(tmp, "w") as f:
            json.dump({"gains": gains, **provenance}, f, indent=2)
            f.write("\n")
        os.replace(tmp, path)
    except OSError as e:
        raise TwinError(f"{path}: cannot write gains ({e.strerror or e})") from None
    return path
