"""What a set of gains was tuned for: the robot (its description, or the generated robot's CAD values), its motor and
the track. ``tune -o`` and ``design`` record it in the gains files they write; a command that loads a gains file
compares it with the twin it runs (:func:`mismatch`), so gains tuned for one robot are not silently raced on another.
"""

from __future__ import annotations

import math
import os
from typing import Mapping

# the motor's own constants (the battery, motor.supply_voltage, is a condition the gains must survive, not the motor)
MOTOR = ("motor.R_M", "motor.K", "motor.L_M", "motor.b_M", "motor.J_rotor", "motor.gear", "motor.efficiency",
         "motor.friction")
REL_TOL = 1e-6  # values read back from JSON are the same to far better than this


def tuned_for(twin) -> dict:
    """The record of what ``twin`` (a :class:`twin.core.digital_twin.DigitalTwin`) is: robot, CAD values that apply
    to it, motor constants and track (a built-in name, or an image's absolute path)."""
    values = twin.space.values
    cad = {a: v for a, v in values.items() if a.startswith("cad.") and (twin.robot_urdf is None or a == "cad.S")}
    track = twin.track_source
    if os.path.isfile(track):
        track = os.path.abspath(track)
    return {"robot": twin.robot_urdf or "generated", "cad": cad, "motor": {a: values[a] for a in MOTOR},
            "track": track}


def _same(a, b) -> bool:
    if isinstance(a, (int, float)) and isinstance(b, (int, float)) and not isinstance(a, bool):
        return math.isclose(a, b, rel_tol=REL_TOL, abs_tol=1e-12)
    return a == b


def differences(recorded: Mapping, current: Mapping) -> list[str]:
    """What differs between two records, as short phrases (robot, motor, track); [] when they agree. A record
    written by another version may lack parts: those are not compared."""
    out = []
    if "robot" in recorded and recorded["robot"] != current["robot"]:
        out.append(f"robot {recorded['robot']} (this run: {current['robot']})")
    elif isinstance(recorded.get("cad"), Mapping):
        changed = [a for a, v in recorded["cad"].items() if a in current["cad"] and not _same(v, current["cad"][a])]
        if changed:
            out.append("robot with " + ", ".join(f"{a}={recorded['cad'][a]:g} (this run: {current['cad'][a]:g})"
                                                  for a in changed[:3]) + (", …" if len(changed) > 3 else ""))
    if isinstance(recorded.get("motor"), Mapping):
        changed = [a for a, v in recorded["motor"].items() if a in current["motor"] and not _same(v, current["motor"][a])]
        if changed:
            out.append("motor with " + ", ".join(f"{a}={recorded['motor'][a]:.4g} (this run: {current['motor'][a]:.4g})"
                                                 for a in changed[:3]) + (", …" if len(changed) > 3 else ""))
    if "track" in recorded and recorded["track"] != current["track"]:
        out.append(f"track {recorded['track']} (this run: {current['track']})")
    return out


def mismatch(recorded: Mapping | None, twin, source: str) -> str | None:
    """One line saying that the gains in ``source`` were tuned for something else than ``twin``, or None."""
    if not isinstance(recorded, Mapping):
        return None  # hand-written, or written before gains files recorded their robot
    diff = differences(recorded, tuned_for(twin))
    if not diff:
        return None
    return f"the gains in {source} were tuned for another {'; '.join(diff)}: re-tune them for this one"
