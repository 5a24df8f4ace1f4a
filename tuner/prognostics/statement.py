"""What a person reads: the forecast in one sentence, and the advice, both from the same distribution of the
remaining life (:class:`tuner.prognostics.monte_carlo.RemainingLife`). Too little evidence gives no number."""

from __future__ import annotations

import math

from tuner.prognostics.monte_carlo import RemainingLife

RETUNE_WITHIN = 10  # [laps]
RETUNE_RISK = 0.10  # re-tune now when at least this share of the futures fail within RETUNE_WITHIN laps


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


def retune_advice(life: RemainingLife, address: str, failing_value: float) -> str | None:
    risk = life.within(RETUNE_WITHIN)
    if risk < RETUNE_RISK:
        return None
    return (f"re-tune now: {risk:.0%} of the futures fail within {RETUNE_WITHIN} laps (live --act does it, or tune "
            f"with --set {address}={failing_value:.4g})")


def service_advice(life: RemainingLife, what: str, address: str, limit: float) -> str | None:
    n = life.service_median()
    if n is None:
        return None
    if n == 0:
        return f"{what} now ({address} is past {limit:g}, the worn end of the robust envelope)"
    return f"{what} in about {n:.0f} laps ({address} reaches {limit:g}, the worn end of the robust envelope)"
