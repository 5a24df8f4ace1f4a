"""Where gradient descent starts: the twin's own gains, unless they fail.

A new robot (a description of its own, a heavier payload) often fails its first lap with gains tuned for another
one. Failed laps cost their failure time plus penalties (:func:`tuner.search.objective.lap_cost`), a surface with flat
plateaus where the gradient says little, and descent from there stalls. So when the start fails, a small grid of
starts is judged in one batch (speed low to moderate, steering gain from soft to stiff, the other searched
parameters where they were) and descent starts from the cheapest, if it is cheaper than the start.
"""

from __future__ import annotations

import itertools

import numpy as np

from tuner.search.objective import LapObjective

# fractions of each range: a cautious to moderate top speed, and steering from soft to stiff
SPEED_GRID = (0.1, 0.25, 0.45)
STEER_GRID = (0.1, 0.25, 0.45, 0.7)
SPEED, STEER = "control.v_max", "control.kp"


def rescue_start(objective: LapObjective, z0: np.ndarray) -> tuple[np.ndarray, str | None]:
    """The point to start from (in the unit box), and a note when it is not ``z0``."""
    cost0 = float(objective(z0[None, :])[0])
    start = objective.at(z0)
    if start is None or all(r.completed for r in start.laps):
        return z0, None
    addresses = objective.space.addresses
    axes = [(addresses.index(a), grid) for a, grid in ((SPEED, SPEED_GRID), (STEER, STEER_GRID)) if a in addresses]
    if not axes:
        return z0, None
    grid = []
    for values in itertools.product(*(g for _, g in axes)):
        z = z0.copy()
        for (i, _), v in zip(axes, values):
            z[i] = v
        grid.append(z)
    costs = objective(np.array(grid))
    best = int(np.argmin(costs))
    failures = sorted({r.failure for r in start.laps if not r.completed})
    if costs[best] >= cost0:
        return z0, (f"the starting values fail ({', '.join(failures)}); none of {len(grid)} other starts did better, "
                    "so descent starts there")
    x = objective.space.from_unit(grid[best])
    chosen = ", ".join(f"{a}={x[i]:.4g}" for a in (SPEED, STEER) if a in addresses for i in [addresses.index(a)])
    return grid[best], (f"the starting values fail ({', '.join(failures)}); descent starts from the best of "
                        f"{len(grid)} starts judged in one batch: {chosen}")
