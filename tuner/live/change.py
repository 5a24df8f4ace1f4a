"""A change of gains on its way through ``live --act`` (:mod:`tuner.live.act`): what was decided, where it stands
(``status``: what the robot runs; ``stored``: what it boots on), the STORE that keeps it, and how its laps are
judged against the prediction and the laps before."""

from __future__ import annotations

import dataclasses

import numpy as np


@dataclasses.dataclass
class Change:
    seq: int
    kind: str  # retune or rollback
    gains: dict[str, float]
    previous: dict[str, float]
    previous_seq: int
    reason: str
    predicted_lap_time_s: float | None
    aligned: dict[str, float]
    decided_lap: int
    status: str = "decided"  # sent, acked, nak, silent, in_force, confirmed, rolled_back, superseded, withdrawn
    stored: str | None = None  # None (no STORE asked), pending, stored, not_stored: what the robot boots on
    deadline: float = 0.0
    first_lap: int | None = None
    before: list[dict] = dataclasses.field(default_factory=list)
    after: list[dict] = dataclasses.field(default_factory=list)


@dataclasses.dataclass
class Store:
    """A STORE on its way: its sequence number, the confirmed change whose gains it keeps, tries and the deadline
    of the last (None: not sent yet)."""

    seq: int
    change: Change
    tries: int = 0
    deadline: float | None = None


def _times(entries: list[dict]) -> tuple[int, float | None]:
    done = [e["robot_lap_time_s"] for e in entries if e["robot_lap_time_s"] is not None]
    return len(entries) - len(done), (float(np.mean(done)) if done else None)


def judge(change: Change, tolerance: float) -> tuple[bool, str]:
    """(worse than before, why): the laps with the new gains against the prediction and the laps before them."""
    fails_after, after = _times(change.after)
    fails_before, before = _times(change.before)
    if fails_after > fails_before:
        return True, f"{fails_after} of {len(change.after)} laps failed with them, {fails_before} before"
    if after is None:
        return False, "every lap failed, as before"
    p = change.predicted_lap_time_s
    off = f"{after:.3f} s against {p:.3f} s predicted" if p else f"{after:.3f} s"
    slower_than_predicted = p is not None and after > p * (1 + tolerance)
    if slower_than_predicted and before is not None and after > before * (1 + tolerance):
        return True, f"{off}, slower than the {before:.3f} s before"
    return False, off + (f", {before:.3f} s before" if before is not None else "")
