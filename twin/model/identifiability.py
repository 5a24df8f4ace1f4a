"""Parameters whose effect the simulation cannot represent at the values it runs, so no lap can tell their value
(issue 33, item 4). ``align`` refuses to align such a parameter, ``diagnose`` and ``graph --learn`` leave it out,
each saying why, instead of reporting it as "negligible".

The one case today: the winding inductance. Its effect is a lag L_M/R_M of the winding voltage (≈ 56 µs for the
default motor, :mod:`motors.actuator`), which a physics step of 1 ms cannot represent; with a step below the lag
(``motion.timestep``) it is resolved, and the parameter is offered again.
"""

from __future__ import annotations

from typing import Mapping


def unresolved(values: Mapping[str, float], address: str) -> str | None:
    """Why no lap can tell ``address``'s value at ``values`` (every address), or None if a lap can."""
    if address == "motor.L_M":
        lag_s, step_s = values["motor.L_M"] / values["motor.R_M"], values["motion.timestep"]
        if lag_s < step_s:
            return (f"motor.L_M: not identifiable from a lap: its effect, a lag L_M/R_M = {lag_s * 1e6:.0f} µs of the "
                    f"winding voltage, lies below the {step_s * 1e3:g} ms physics step (motion.timestep), which cannot "
                    "represent it")
    return None
