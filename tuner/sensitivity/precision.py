"""How sure an index is: an estimate outside [0, 1] clipped to it with a note (an index is a share, so the excess is
sampling error), and, when an interval is wider than ±:data:`PRECISION`, a ``too few samples`` note naming the
sample that would narrow it (95 % half-widths shrink as 1/√N)."""

from __future__ import annotations

import math

PRECISION = 0.1  # an index's interval half-width beyond which the sample is flagged as too small
TOO_FEW = "too few samples"


def clipped(o: str, name: str, values: dict[str, tuple[float, tuple[float, float]]], notes: list[str]) -> dict:
    """Each index and its interval clipped to [0, 1] (an estimate outside is sampling error); a note per output
    naming the raw values that were outside."""
    out, outside = {}, []
    for f, (v, (lo, hi)) in values.items():
        if math.isnan(v):  # not estimable from these runs: nothing to clip
            out[f] = (v, (lo, hi))
            continue
        if not (0.0 <= v <= 1.0 and 0.0 <= lo and hi <= 1.0):
            outside.append(f"{f} {v:.2f} [{lo:.2f}, {hi:.2f}]")
        out[f] = (min(max(v, 0.0), 1.0), (min(max(lo, 0.0), 1.0), min(max(hi, 0.0), 1.0)))
    if outside:
        notes.append(f"{o}: {name} estimated outside [0, 1], shown clipped to it (an index is a share, so the excess "
                     f"is sampling error): {'; '.join(outside)}")
    return out


def needed(current: int, half_width: float, power_of_two: bool = True) -> int:
    """The sample that narrows a 95 % half-width of ``half_width`` at ``current`` to :data:`PRECISION` (half-widths
    shrink as 1/√N); the next power of two when the sample must be one."""
    n = math.ceil(current * (half_width / PRECISION) ** 2)
    return 2 ** math.ceil(math.log2(n)) if power_of_two else n


def flag_precision(o: str, name: str, half: float, current: int, unit: str, notes: list[str],
                   power_of_two: bool = True) -> None:
    """A ``too few samples`` note when ``half`` (the widest 95 % half-width) exceeds :data:`PRECISION`."""
    if half > PRECISION:
        notes.append(f"{TOO_FEW}: {o}'s {name} intervals are up to ±{half:.2f} wide at {current} {unit}; ±{PRECISION:g} "
                     f"needs about {needed(current, half, power_of_two):,} {unit}")
