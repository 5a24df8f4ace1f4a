"""How a simulation or a lap ends, one enumeration each, shared by the closed loop and the processor in the loop.

* :class:`Status`: what the C says of a simulation, ``enum lf_status`` (twin/csrc/sim/lf_status.h): the control
  callback's refusal (``lf_sim.error``) and the processor-in-the-loop lockstep's result. Each C library names its codes
  (``lf_status_names``) and :func:`twin.core.native.check_library` compares them with this enumeration when it loads.
* :class:`Outcome`: how a lap ended; ``LapResult.failure`` is its value (None when completed), as JSON writes it.
"""

from __future__ import annotations

import enum

from line_sensor.geometry import MAX_SENSORS


class Status(enum.IntEnum):
    """``enum lf_status``, each C name without its ``LF_`` prefix."""

    OK = 0
    ERR_LAYOUT = 1
    ERR_MODEL = 2
    ERR_CAPACITY = 3
    ERR_SENSORS = 4
    ERR_ID = 5
    ERR_CENTRE = 6
    ERR_STATE = 7
    ERR_RAY = 8
    ERR_FIRMWARE = 9
    STALLED = 10


def c_names() -> dict[str, int]:
    """{C name: value} of every :class:`Status` and lap status (:data:`LAP_STATUS`), as ``lf_status_names`` lists
    them."""
    return {**{f"LF_{s.name}": int(s) for s in Status},
            **{f"LF_LAP_{name.upper()}": i for i, name in enumerate(LAP_STATUS)}}


# why the callback refused a simulation (lf_sim.error), for the lap's detail
REFUSALS = {
    Status.ERR_LAYOUT: "its layout version is not this library's",
    Status.ERR_MODEL: "the model's sizes are not those it was written for",
    Status.ERR_CAPACITY: "its trace ring is empty or does not fit in the model's userdata",
    Status.ERR_SENSORS: f"its sensor count is outside 1..{MAX_SENSORS} or differs from the firmware's",
    Status.ERR_ID: "a site, body, texture, actuator or joint id is outside the model",
    Status.ERR_CENTRE: "its centre line does not lie inside the model's numeric data",
    Status.ERR_STATE: "its record counter is negative",
}


class Outcome(str, enum.Enum):
    """How a lap ended (the judge's rules: :mod:`twin.core.lap`)."""

    COMPLETED = "completed"
    OFF_TRACK = "off_track"
    LINE_LOST = "line_lost"
    TIMEOUT = "timeout"
    DIVERGED = "diverged"
    CALIBRATION = "calibration"
    REFUSED = "refused"  # the C refused the simulation (a program error, reported as a result)
    WRONG_WAY = "wrong_way"  # turned round: follows the line backwards
    FIRMWARE_STALLED = "firmware_stalled"  # the binary in the loop stopped (twin.pil.lap)
    POWER = "power"  # the motors' supply failed: a regulator that did not start or shut off (twin.model.power)
    STOPPED = "stopped"  # ended undecided by its caller, whom its outcome could no longer matter (run_laps' deadline_s, cut)


# ``enum lf_lap_status``: a lap the C judges (the FMU) is running (0) or ended with one of these outcomes (1 …)
LAP_STATUS: tuple[str, ...] = ("running", Outcome.COMPLETED.value, Outcome.OFF_TRACK.value, Outcome.LINE_LOST.value,
                               Outcome.TIMEOUT.value, Outcome.DIVERGED.value, Outcome.CALIBRATION.value,
                               Outcome.REFUSED.value, Outcome.WRONG_WAY.value)


def outcome_of(status: Status) -> Outcome:
    """The outcome of a lap the C ended with ``status`` (not OK): the watchdog's stall, or a refusal."""
    return Outcome.FIRMWARE_STALLED if status == Status.STALLED else Outcome.REFUSED
