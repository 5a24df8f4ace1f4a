"""The variables of the twin's FMUs: names, units, causality, start values, and where the C finds each value.

One table per export, in value-reference order (a variable's value reference is its row): the modelDescription.xml
(:mod:`twin.fmi.description`) and the C table compiled into the FMU (:mod:`twin.fmi.build`) are both written from
it, so they cannot disagree. Parameters are the model-space addresses whose change costs a model field or only the
controller (``motion.*``, ``motor.*``, ``sensor.*`` but count and pitch, ``control.*``): the plant leaves out the
gains, which belong to whatever controls it. Names follow FMI's structured convention (``pose.x``,
``sensor.raw[1]``); units are Modelica's spelling of the model space's SI units.
"""

from __future__ import annotations

import dataclasses

from line_sensor.geometry import MAX_SENSORS
from twin.core import native as core
from twin.core.digital_twin import DigitalTwin
from twin.core.outcomes import LAP_STATUS
from twin.errors import TwinError
from twin.model.space import ChangeCost

PLANT, CLOSED_LOOP = "plant", "closed-loop"
KINDS = (PLANT, CLOSED_LOOP)
KIND_CODE = {PLANT: 1, CLOSED_LOOP: 2}  # enum lf_fmu_kind
# enum lf_fmu_source and enum lf_fmu_lap_value (twin/csrc/fmi/fmu_twin.h)
TIME, INPUT, RECORD, LAP, PARAM, SEED = range(6)
LAP_VALUES = ("status", "completed", "time", "distance", "xte_max", "xte_mean", "energy")
# the gains: tunable between steps (closed loop); the plant has none of them
GAINS = ("control.v_max", "control.kb", "control.kp", "control.ki", "control.kd", "control.accel_max",
         "control.integral_limit")
LAP_TIMEOUT_MAX_S = 3600.0  # as lap --lap-timeout
SEED_MAX = {2: 2**31 - 1, 3: 2**64 - 1}  # FMI 2 has 32-bit Integers, FMI 3 a UInt64

# model space unit → (Modelica unit name, SI base-unit exponents, factor); "-" is dimensionless (no unit)
UNITS = {
    "m": ("m", {"m": 1}, 1.0), "s": ("s", {"s": 1}, 1.0), "rad": ("rad", {"rad": 1}, 1.0),
    "m/s": ("m/s", {"m": 1, "s": -1}, 1.0), "rad/s": ("rad/s", {"rad": 1, "s": -1}, 1.0),
    "V": ("V", {"kg": 1, "m": 2, "s": -3, "A": -1}, 1.0), "J": ("J", {"kg": 1, "m": 2, "s": -2}, 1.0),
    "Ω": ("Ohm", {"kg": 1, "m": 2, "s": -3, "A": -2}, 1.0), "H": ("H", {"kg": 1, "m": 2, "s": -2, "A": -2}, 1.0),
    "N·m": ("N.m", {"kg": 1, "m": 2, "s": -2}, 1.0), "N·m/A": ("N.m/A", {"kg": 1, "m": 2, "s": -2, "A": -1}, 1.0),
    "N·m·s/rad": ("N.m.s/rad", {"kg": 1, "m": 2, "s": -1, "rad": -1}, 1.0),
    "kg·m²": ("kg.m2", {"kg": 1, "m": 2}, 1.0), "µs": ("us", {"s": 1}, 1e-6),
    "m/s/rad": ("m/(s.rad)", {"m": 1, "s": -1, "rad": -1}, 1.0), "1/s": ("1/s", {"s": -1}, 1.0),
    "1/s²": ("1/s2", {"s": -2}, 1.0), "m/s²": ("m/s2", {"m": 1, "s": -2}, 1.0),
    "rad·s": ("rad.s", {"rad": 1, "s": 1}, 1.0),
}


@dataclasses.dataclass(frozen=True)
class Variable:
    """One FMU variable. ``type``: Real, Integer, Boolean or UInt64 (FMI 3's Float64, Int32, Boolean, UInt64);
    ``unit``: a key of :data:`UNITS` or None; ``source``/``index``: where the C reads it (fmu_twin.h)."""

    name: str
    type: str
    causality: str
    variability: str
    description: str
    source: int
    index: int = 0
    unit: str | None = None
    start: float | int | bool | None = None
    lower: float | None = None
    upper: float | None = None
    lower_open: bool = False
    address: str | None = None  # a parameter's model-space address

    @property
    def fmi_unit(self) -> str | None:
        return UNITS[self.unit][0] if self.unit else None


def _record(name: str, column: str | int, unit: str | None, description: str, type_: str = "Real") -> Variable:
    index = column if isinstance(column, int) else core.RECORD_FIELDS.index(column)
    variability = "continuous" if type_ == "Real" else "discrete"
    return Variable(name, type_, "output", variability, description, RECORD, index, unit)


def _lap(name: str, which: str, unit: str | None, description: str, type_: str = "Real") -> Variable:
    return Variable(name, type_, "output", "discrete", description, LAP, LAP_VALUES.index(which), unit)


def _outputs(kind: str, count: int) -> list[Variable]:
    out = [
        _record("pose.x", "x_m", "m", "x of the centre of rotation (the axle's midpoint) in the world frame"),
        _record("pose.y", "y_m", "m", "y of the centre of rotation (the axle's midpoint) in the world frame"),
        _record("pose.theta", "yaw_rad", "rad", "heading of the robot, counter-clockwise from the world's x axis, "
                "in (-pi, pi]"),
        _record("wheel_speed_left", "wheel_left_radps", "rad/s", "left wheel's angular speed (encoder)"),
        _record("wheel_speed_right", "wheel_right_radps", "rad/s", "right wheel's angular speed (encoder)"),
        _record("line_position", "position", None, "readLine: weighted line position over the calibrated readings, "
                f"0 (sensor 1) to {(count - 1) * 1000} (sensor {count}); when lost, the end last seen"),
        _record("line_angle", "e_rad", "rad", "Eq. 9: bearing of the line from the centre of rotation, > 0 to the left"),
        _record("line_seen", "line_seen", None, "a calibrated reading is above 200 (the line is under the array)",
                "Boolean"),
        _record("cross_track_error", "offset_m", "m", "signed distance of the centre of rotation from the track's "
                "centre line, > 0 to the left"),
        _record("energy", "energy_j", "J", "electrical energy drawn by both motors since the start time"),
    ]
    if kind == CLOSED_LOOP:
        out += [_record("voltage_left", "u_left_v", "V", "left motor voltage the firmware commands (PWM duty x supply)"),
                _record("voltage_right", "u_right_v", "V", "right motor voltage the firmware commands (PWM duty x supply)")]
    out += [_record(f"sensor.raw[{i + 1}]", core.RAW_COLUMN + i, "µs", f"sensor {i + 1}'s raw QTR-RC reading "
                    "(discharge time)") for i in range(count)]
    out += [_record(f"sensor.calibrated[{i + 1}]", core.CALIBRATED_COLUMN + i, None, f"sensor {i + 1}'s calibrated "
                    "reading (Eq. 8), 0 (white) to 1000 (black)") for i in range(count)]
    out += [
        _lap("lap_status", "status", None, ", ".join(f"{i} {name.replace('_', ' ')}" for i, name in
                                                      enumerate(LAP_STATUS)), "Integer"),
        _lap("lap_completed", "completed", None, "the lap is completed", "Boolean"),
        _lap("lap_time", "time", "s", "lap time, interpolated at the crossing of the start line; 0 until completed"),
        _lap("lap_distance", "distance", "m", "progress along the centre line since the start"),
        _lap("cross_track_error_max", "xte_max", "m", "largest |cross_track_error| of the lap so far"),
        _lap("cross_track_error_mean", "xte_mean", "m", "mean |cross_track_error| of the lap so far"),
        _lap("lap_energy", "energy", "J", "energy drawn during the lap; 0 until the lap has ended"),
    ]
    return out


def _parameters(twin: DigitalTwin, kind: str) -> list[Variable]:
    out = []
    for address in twin.space.addresses:
        p = twin.space.parameter(address)
        if p.cost is ChangeCost.REBUILD or (kind == PLANT and address in GAINS):
            continue
        if p.unit != "-" and p.unit not in UNITS:
            raise TwinError(f"{address}: unit {p.unit} has no FMI declaration (twin.fmi.variables.UNITS)")
        open_ = p.strictly_positive and p.lower <= 0
        value = twin.space.get(address)
        out.append(Variable(
            address, "Integer" if p.integer else "Real", "parameter",
            "tunable" if kind == CLOSED_LOOP and address in GAINS else "fixed",
            f"{p.description} [{p.cost.value}]", PARAM, len(out), None if p.unit == "-" else p.unit,
            int(value) if p.integer else value, max(p.lower, 0.0) if open_ else p.lower, p.upper, open_, address))
    return out


def fmu_variables(twin: DigitalTwin, kind: str, fmi_version: int, seed: int, lap_timeout_s: float) -> list[Variable]:
    """The FMU's variables in value-reference order (row k has value reference k). ``twin``: built, with the
    values the FMU starts from."""
    if kind not in KINDS:
        raise TwinError(f"--kind {kind!r}: choose plant or closed-loop")
    if not 0 <= seed <= SEED_MAX[fmi_version]:
        raise TwinError(f"seed: {seed} does not fit FMI {fmi_version}'s seed variable (0 … {SEED_MAX[fmi_version]})")
    count = int(twin.space.get("sensor.count"))
    if not 1 <= count <= MAX_SENSORS:
        raise TwinError(f"sensor.count: {count} is outside 1 … {MAX_SENSORS}")
    out = [Variable("time", "Real", "independent", "continuous", "simulation time", TIME, unit="s")]
    if kind == PLANT:
        out += [Variable(f"voltage_{side}", "Real", "input", "continuous", f"{side} motor voltage, clipped to "
                         "+-motor.supply_voltage", INPUT, i, "V", 0.0) for i, side in enumerate(("left", "right"))]
    out += _outputs(kind, count)
    params = _parameters(twin, kind)
    n = len(params)
    params.append(Variable("lap_timeout", "Real", "parameter", "fixed", "a lap not done after this much simulated "
                           "time ends as timeout (lap_status 4)", PARAM, n, "s", lap_timeout_s, 0.0,
                           LAP_TIMEOUT_MAX_S, True, "lap_timeout"))
    params.append(Variable("seed", "UInt64" if fmi_version == 3 else "Integer", "parameter", "fixed",
                           "sensor-noise seed (the same seed gives the same run, bit for bit, as lap --seed)", SEED,
                           0, None, int(seed), 0, SEED_MAX[fmi_version]))
    return out + params


def c_name(address: str) -> str:
    """A parameter's name in fmu_twin.h's enum lf_fmu_param_what."""
    return "LF_P_" + "".join(c if c.isalnum() else "_" for c in address).upper()
