"""What a person reads: the forecast in one sentence, and the advice, both from the same distribution of the
remaining life (:class:`tuner.prognostics.monte_carlo.RemainingLife`). Too little evidence gives no number."""

from __future__ import annotations

import math

from tuner.prognostics.monte_carlo import RemainingLife

RETUNE_WITHIN = 10  # [laps]
RETUNE_RISK = 0.10  # re-tune now when at least this share of the futures fail within RETUNE_WITHIN laps
SHAPE_SHARE = 0.2  # the evidence has not told a straight line from a curve while each holds this share of futures …
SHAPE_APART = 1.5  # … and their medians lie this far apart (the larger over the smaller)


def _laps(x: float) -> str:
    return f"{x:.0f}"


def life_sentence(life: RemainingLife) -> str:
    """'the gains in force stop finishing in about N laps (90 % between A and B)'."""
    median, lo, hi = life.quantile(0.5), life.quantile(0.05), life.quantile(0.95)
    if math.isinf(median):
        return (f"the gains in force are not expected to stop finishing within {life.horizon} laps (in fewer than "
                f"half the futures; 5 % fail within {_laps(lo)} laps)" if math.isfinite(lo) else
                f"the gains in force are not expected to stop finishing within {life.horizon} laps")
    upper = f"more than {life.horizon}" if math.isinf(hi) else _laps(hi)
    return f"the gains in force stop finishing in about {_laps(median)} laps (90 % between {_laps(lo)} and {upper})"


def shape_sentence(life: RemainingLife) -> str | None:
    """When the futures fall in two humps, wear that keeps its pace and wear that speeds up, and the evidence has not
    chosen: 'the laps cannot tell yet whether the wear speeds up: …'. A median between two humps says little, so the
    person reads both (their shares and medians); None when one shape holds nearly all futures or both agree."""
    shapes = life.by_shape()
    if shapes is None or min(s["share"] for s in shapes.values()) < SHAPE_SHARE:
        return None
    med = {k: math.inf if s["median"] is None else s["median"] for k, s in shapes.items()}
    lo, hi = sorted(med.values())
    if hi < SHAPE_APART * max(lo, 1.0):
        return None

    def said(name: str) -> str:
        m = med[name]
        return f"more than {life.horizon}" if math.isinf(m) else f"about {_laps(m)}"

    return (f"the laps cannot tell yet whether the wear speeds up: at its pace, {said('straight')} laps "
            f"({shapes['straight']['share']:.0%} of the futures); speeding up, {said('speeding_up')} "
            f"({shapes['speeding_up']['share']:.0%})")


def retune_advice(life: RemainingLife, address: str, failing_value: float, also: dict | None = None) -> str | None:
    """Re-tune now when one future in ten fails within ``RETUNE_WITHIN`` laps: at the value where the gains fail
    (and the ``also`` values of other causes that wear with it)."""
    risk = life.within(RETUNE_WITHIN)
    if risk < RETUNE_RISK:
        return None
    sets = " ".join(f"--set {a}={v:.4g}" for a, v in {address: failing_value, **(also or {})}.items())
    return (f"re-tune now: {risk:.0%} of the futures fail within {RETUNE_WITHIN} laps (live --act does it, or tune "
            f"with {sets})")


def service_advice(life: RemainingLife, what: str, address: str, limit: float, dim: int = 0) -> str | None:
    """When the futures reach a part's service limit (``dim``: which part, with two causes at once)."""
    n = life.service_median(dim)
    if n is None:
        return None
    if n == 0:
        return f"{what} now ({address} is past {limit:g}, the worn end of the robust envelope)"
    return f"{what} in about {n:.0f} laps ({address} reaches {limit:g}, the worn end of the robust envelope)"
