"""JSON output of the tuner's commands: JSON has no NaN or infinity, so missing figures become null."""

from __future__ import annotations

import math


def json_safe(obj):
    """A copy of nested dicts, lists and tuples with every non-finite float replaced by None."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: json_safe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [json_safe(v) for v in obj]
    return obj
