"""The one exception the `mjcf` room raises for bad input, and the field check its configs share."""

import dataclasses
import math

from lf_common.errors import LineFollowerError


class MjcfError(LineFollowerError, ValueError):
    """Bad input to the CAD, track or URDF → MJCF models; the message names the input and the fault."""


def check_positive_fields(config, prefix: str, may_be_zero: tuple[str, ...] = ()) -> None:
    """Every field of a frozen dataclass must be a finite number > 0 (>= 0 for ``may_be_zero``).

    Raises:
      MjcfError: naming the field as ``prefix.name``.
    """
    for f in dataclasses.fields(config):
        v = getattr(config, f.name)
        if not isinstance(v, (int, float)) or not math.isfinite(v):
            raise MjcfError(f"{prefix}.{f.name}: must be a finite number, got {v!r}")
        if v < 0 or (v == 0 and f.name not in may_be_zero):
            op = ">=" if f.name in may_be_zero else ">"
            raise MjcfError(f"{prefix}.{f.name}: must be {op} 0, got {v:g}")
