"""A drive motor for a robot the twin did not design: from the catalogue when one fits, else sized to the robot.

A line follower accelerates and turns for most of its lap, so a motor fits when, at half its stall torque (where a
DC motor gives its most power), the two wheels can still push the robot at ``MIN_PUSH_G`` (0.5 g):
2 · ½ τ_stall / R ≥ 0.5 · m · g; and when its no-load speed on these wheels is a line follower's
(≤ ``MAX_TOP_SPEED``, 2.5 m/s: faster, a reflectance array at its usual look-ahead cannot see a bend coming).
Of the motors that fit, the one whose top speed is nearest ``TARGET_TOP_SPEED`` wins (then the least stall
current): the 3pi-class speed that the default gains, the calibration turn and the tuner's reference bounds were
made for; a faster motor is the user's call (``--motor``). The default robot's own motor has
2 · ½ · 0.032 / 0.016 = 2.0 N for 0.21 kg (about 1 g, a margin of 2) at 1.21 m/s: it picks itself.

When none fits (a robot of kilograms on micro gearmotors), a motor is sized for the robot instead, with the
default motor's character: the stall torque that gives the default robot's margin (τ_stall = m·g·R per motor),
a top speed of ``SIZED_TOP_SPEED`` (1 m/s), the default motor's ratio of peak mechanical power to stall
electrical power (τ_stall·Ω_0 / (U·I_stall)), its motor-shaft no-load speed (which sets the gear) and its
electrical time constant, and its rotor's share of the robot's inertia. This is an estimate for a first lap, not a datasheet: say so, and fit the real motor.
"""

from __future__ import annotations

import dataclasses

from motors.datasheet import POLOLU_MP_6V_30_1, Datasheet

G = 9.80665  # [m/s²]
MIN_PUSH_G = 0.5  # [g] at half stall torque
MAX_TOP_SPEED = 2.5  # [m/s]
SIZED_TOP_SPEED = 1.0  # [m/s]
TARGET_TOP_SPEED = 1.206  # [m/s] the default robot's: 720 rpm × 16 mm
REF_MASS, REF_WHEEL = 0.21, 0.016  # [kg], [m]: the default robot the reference motor drives


@dataclasses.dataclass(frozen=True)
class MotorChoice:
    name: str  # catalogue name, or "sized"
    datasheet: Datasheet
    reason: str


def push_g(d: Datasheet, mass_kg: float, wheel_radius_m: float, voltage: float) -> float:
    """What two of these motors at half stall torque push the robot at, in g."""
    stall = d.stall_torque * voltage / d.voltage  # stall torque scales with voltage
    return 2 * 0.5 * stall / wheel_radius_m / (mass_kg * G)


def top_speed(d: Datasheet, wheel_radius_m: float, voltage: float) -> float:
    """No-load ground speed on these wheels [m/s] (no-load speed scales with voltage)."""
    return d.no_load_speed * voltage / d.voltage * wheel_radius_m


def choose(catalogue: dict[str, Datasheet], mass_kg: float, wheel_radius_m: float, voltage: float) -> MotorChoice:
    """The catalogue motor that fits (see the module docstring), else one sized for the robot."""
    fits = [(abs(top_speed(d, wheel_radius_m, voltage) - TARGET_TOP_SPEED), d.stall_current, name.startswith("3pi"), name)
            for name, d in catalogue.items()
            if push_g(d, mass_kg, wheel_radius_m, voltage) >= MIN_PUSH_G
            and top_speed(d, wheel_radius_m, voltage) <= MAX_TOP_SPEED]
    if fits:
        name = min(fits)[-1]  # (an edition's alias only where no motor name ties with it)
        d = catalogue[name]
        return MotorChoice(name, d, f"the catalogue motor nearest {TARGET_TOP_SPEED:g} m/s that fits {mass_kg:.3g} kg on {wheel_radius_m * 1000:.3g} mm "
                           f"wheels: pushes {push_g(d, mass_kg, wheel_radius_m, voltage):.2f} g at half stall torque, "
                           f"top speed {top_speed(d, wheel_radius_m, voltage):.2f} m/s at {voltage:g} V")
    d = sized(mass_kg, wheel_radius_m, voltage)
    return MotorChoice("sized", d, f"no catalogue motor fits {mass_kg:.3g} kg on {wheel_radius_m * 1000:.3g} mm wheels "
                       f"(≥ {MIN_PUSH_G:g} g at half stall torque, ≤ {MAX_TOP_SPEED:g} m/s); a motor sized for it: "
                       f"{d.stall_torque:.3g} N·m stall at the wheel, {d.stall_current:.3g} A, top speed "
                       f"{SIZED_TOP_SPEED:g} m/s at {voltage:g} V (an estimate: fit your motor's datasheet with --set motor.*)")


def sized(mass_kg: float, wheel_radius_m: float, voltage: float) -> Datasheet:
    ref = POLOLU_MP_6V_30_1
    merit = ref.stall_torque * ref.no_load_speed / (ref.voltage * ref.stall_current)
    shaft_speed = ref.no_load_speed * ref.gear  # [rad/s] at the motor, at the reference voltage
    stall = mass_kg * G * wheel_radius_m
    omega = SIZED_TOP_SPEED / wheel_radius_m
    current = stall * omega / (merit * voltage)
    tau_e = ref.inductance / (ref.voltage / ref.stall_current)  # [s]
    return Datasheet(
        voltage=voltage, stall_torque=stall, stall_current=current, no_load_speed=omega,
        no_load_current=ref.no_load_current * current / ref.stall_current, gear=max(1.0, shaft_speed / omega),
        inductance=tau_e * voltage / current,
        # the rotor's share of the robot's inertia (reflected through the gear: J·G² against m·R²) is the default's
        rotor_inertia=ref.rotor_inertia * ref.gear**2 * (mass_kg * wheel_radius_m**2) / (REF_MASS * REF_WHEEL**2)
        / max(1.0, shaft_speed / omega) ** 2,
        source=f"sized for {mass_kg:.3g} kg on {wheel_radius_m * 1000:.3g} mm wheels (motors.choice)",
    )


