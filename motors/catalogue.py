"""Named gearmotors with their datasheet figures, for ``--motor NAME`` and the choice of a motor for a robot
(:mod:`motors.choice`). Figures at the gearbox output, at the rated voltage; sources per entry.

Inductance and rotor inertia are not published for these motors: each entry uses the default motor's
assumptions (0.5 mH, 2e-9 kg·m², typical of 10 mm-class brushed motors), as :data:`POLOLU_MP_6V_30_1` does.
"""

from __future__ import annotations

from motors.datasheet import POLOLU_MP_6V_30_1, Datasheet

CATALOGUE: dict[str, Datasheet] = {
    "pololu-mp-6v-30": POLOLU_MP_6V_30_1,
}


def names() -> list[str]:
    return sorted(CATALOGUE)
