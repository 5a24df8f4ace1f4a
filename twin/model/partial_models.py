"""Declarations of the partial models that the foundation provides: CAD, environment, motion, DC motor.

Defaults come from the code that realises each model (``RobotDesign``, the Pololu motor datasheet,
``PhysicsOptions``), so there is one source for every nominal value.
"""

from __future__ import annotations

import dataclasses

from mjcf.design import DESIGN_UNITS, RobotDesign
from mjcf.track import LINE_WIDTH_M
from mjcf.world import TYRE_SOLREF, PhysicsOptions
from line_sensor.geometry import MAX_SENSORS, SensorArray
from line_sensor.reflectance import SensorModel
from motors import POLOLU_MP_6V_30_1
from twin.model.control import DEFAULTS as CONTROL_DEFAULTS
from twin.model.power import SOURCE_OHM
from twin.model.timing import Timing
from twin.model.space import ChangeCost, ModelSpace, Parameter, PartialModel, Port

R, F, C = ChangeCost.REBUILD, ChangeCost.MODEL_FIELD, ChangeCost.CONTROLLER

_CAD_DOC = {
    "L": ("half the wheel separation (Eq. 2)", 0.02, 0.2),
    "R": ("wheel radius", 0.005, 0.1),
    "S": ("centre of rotation to sensor array", 0.01, 0.3),
    "m_c": ("chassis mass, all but the wheels", 1e-3, 10.0),
    "m_w": ("mass of one wheel", 1e-4, 1.0),
    "d": ("chassis centre of gravity ahead of the axle", 0.0, 0.1),
    "wheel_width": ("tyre width", 0.002, 0.05),
    "chassis_thickness": ("chassis puck height", 0.002, 0.05),
    "caster_radius": ("ball caster radius", 0.001, 0.05),
    "sensor_height": ("sensor array height above the floor", 0.0005, 0.03),
    "sensor_bar_width": ("sensor bar length across the heading", 0.01, 0.3),
}


def cad_model() -> PartialModel:
    design = RobotDesign()
    params = tuple(
        Parameter(f.name, DESIGN_UNITS[f.name], getattr(design, f.name), lo, hi, R, doc, strictly_positive=f.name != "d")
        for f in dataclasses.fields(RobotDesign)
        for doc, lo, hi in [_CAD_DOC[f.name]]
    )
    return PartialModel(
        "cad",
        "design parameters → URDF with meshes, masses and inertias",
        outputs=(Port("robot_description", "URDF", "links, joints, meshes, inertials"),),
        parameters=params,
        realised_by="mjcf.cad (trimesh, yourdfpy)",
    )


def environment_model() -> PartialModel:
    return PartialModel(
        "environment",
        "track definition → textured floor and centre line",
        inputs=(Port("track_definition", "-", "built-in name or PNG of a dark line"),),
        outputs=(
            Port("floor_texture", "-", "grey-level image at a known scale"),
            Port("centre_line", "m", "closed polyline, arc length, start pose"),
        ),
        parameters=(
            Parameter("line_width", "m", LINE_WIDTH_M, 0.005, 0.05, R, "line width of built-in tracks", True),
            Parameter("texture_resolution", "m", 0.001, 0.0002, 0.001, R, "floor texture pixel pitch", True),
        ),
        realised_by="mjcf.track, mjcf.track_image",
    )


def motion_model() -> PartialModel:
    phys = PhysicsOptions()
    return PartialModel(
        "motion",
        "wheel torques → pose, v, ω (Eqs. 1–5) under contacts",
        inputs=(
            Port("robot_description", "URDF"),
            Port("floor_texture", "-"),
            Port("wheel_torque", "N·m", "left, right"),
        ),
        outputs=(
            Port("pose", "m, rad", "x, y, yaw of the centre of rotation"),
            Port("body_velocity", "m/s, rad/s", "v and ω (Eqs. 1–2)"),
            Port("wheel_speed", "rad/s", "left, right"),
        ),
        parameters=(
            Parameter("mu", "-", phys.tyre_mu, 0.05, 2.0, F, "tyre–floor friction coefficient", True),
            Parameter("floor_mu", "-", phys.floor_mu, 0.05, 2.0, F, "floor friction for contacts without a tyre or caster", True),
            Parameter("caster_mu", "-", phys.caster_mu, 0.0, 0.5, F, "ball casters' rolling resistance per unit "
                      "normal load (0: rolling freely; mjcf.world.CASTER_MU 0.08: a plastic ball in its socket)"),
            # the tyre contact needs at least two steps per time constant (PhysicsOptions checks the same)
            Parameter("timestep", "s", phys.timestep, 1e-5, TYRE_SOLREF[0] / 2, F, "physics step", True),
            Parameter("impratio", "-", phys.impratio, 1.0, 100.0, F, "friction/normal impedance ratio", True),
        ),
        realised_by="MuJoCo physics (mjcf.world)",
    )


def motor_model() -> PartialModel:
    m = POLOLU_MP_6V_30_1.constants()
    return PartialModel(
        "motor",
        "voltage → torque (Eqs. 6–7 with gearbox efficiency and dry friction), both drive motors",
        inputs=(Port("motor_voltage", "V", "left, right"), Port("wheel_speed", "rad/s")),
        outputs=(Port("wheel_torque", "N·m", "left, right"), Port("motor_current", "A", "left, right")),
        parameters=(
            Parameter("R_M", "Ω", m.R_M, 0.1, 1000.0, F, "winding resistance", True),
            Parameter("L_M", "H", m.L_M, 0.0, 0.1, F, "winding inductance: a lag L_M/R_M of the winding voltage (≈ 56 µs, "
                      "below the 1 ms step, so not identifiable from a lap; not published, assumed); 0 ↔ >0 rebuilds"),
            Parameter("K", "N·m/A", m.K, 1e-5, 1.0, F, "torque = back-EMF constant", True),
            Parameter("b_M", "N·m·s/rad", m.b_M, 0.0, 1e-3, F, "viscous friction at the motor shaft (datasheet fit: the viscous half of the no-load friction)"),
            Parameter("J_rotor", "kg·m²", m.J_rotor, 0.0, 1e-4, F, "rotor inertia"),
            Parameter("gear", "-", m.gear, 1.0, 1000.0, F, "gearbox ratio", True),
            Parameter("efficiency", "-", m.efficiency, 0.0, 1.0, F,
                      "gearbox efficiency η: the output torque is G·η·(K·i − τ0); fitted to the stall torque", True),
            Parameter("friction", "N·m", m.friction, 0.0, 0.01, F,
                      "dry (Coulomb) friction torque τ0 at the motor shaft (brushes, bearings, gearbox drag); "
                      "datasheet fit: half of the no-load current's torque K·I_0"),
            Parameter("supply_voltage", "V", PhysicsOptions().supply_voltage, 0.5, 24.0, F,
                      "the battery's open-circuit voltage (the motors' supply without a regulator: power.*)", True),
        ),
        realised_by="MuJoCo 4 general actuator (fixed gain, affine bias) + the wheel joint's frictionloss (motors.actuator)",
    )


def sensor_model() -> PartialModel:
    array, resp = SensorArray(), SensorModel()
    return PartialModel(
        "sensor",
        "pose over the textured track → raw RC readings s_i,raw (raycasts, footprint, response, noise)",
        inputs=(Port("pose", "m, rad"), Port("floor_texture", "-")),
        outputs=(Port("sensor_readings", "µs", "raw QTR-RC discharge time per sensor"),),
        parameters=(
            Parameter("count", "-", array.count, 2, MAX_SENSORS, R, "reflectance sensors in the array (QTR-8: 8)", True, integer=True),
            Parameter("pitch", "m", array.pitch, 0.002, 0.03, R, "sensor spacing (QTR-8: 9.525 mm)", True),
            Parameter("aperture", "m", resp.aperture_m, 1e-4, 0.01, C, "footprint radius at zero height", True),
            Parameter("half_angle", "rad", resp.half_angle_rad, 0.01, 1.2, C, "footprint growth with height", True),
            Parameter("falloff_height", "m", resp.falloff_height_m, 5e-4, 0.05, C, "height at which returned light halves", True),
            Parameter("t_unit", "µs", resp.t_unit_us, 1.0, 2000.0, C, "discharge time of a perfect reflector at 0 mm", True),
            Parameter("timeout", "µs", resp.timeout_us, 100.0, 65535.0, C, "RC read timeout (Pololu default 2500 µs)", True),
            Parameter("noise", "-", resp.noise_rel, 0.0, 0.5, C, "relative photocurrent noise (std)"),
        ),
        realised_by="MuJoCo rangefinders + twin/csrc/sim/sensor_physics.c (reference: line_sensor.reflectance)",
    )


def control_model() -> PartialModel:
    d = CONTROL_DEFAULTS
    return PartialModel(
        "control",
        "raw readings → e (Eqs. 8–9) → v, ω (Eqs. 10–11) → motor voltages, every Δt (firmware in C)",
        inputs=(Port("sensor_readings", "µs"),),
        outputs=(Port("motor_command", "V", "left, right: PWM duty × supply voltage, as the firmware writes it"),
                 Port("line_angle", "rad", "e")),
        parameters=(
            Parameter("v_max", "m/s", d["v_max"], 0.0, 3.0, C, "Eq. 10: top forward speed"),
            Parameter("kb", "m/s/rad", d["k_b"], 0.0, 10.0, C, "Eq. 10: slow-down per unit |e|"),
            Parameter("kp", "1/s", d["k_p"], 0.0, 200.0, C, "Eq. 11: proportional gain"),
            Parameter("ki", "1/s²", d["k_i"], 0.0, 500.0, C, "Eq. 11: integral gain"),
            Parameter("kd", "-", d["k_d"], 0.0, 10.0, C, "Eq. 11: derivative gain"),
            Parameter("dt", "s", d["dt"], 1e-4, 0.05, C, "control period Δt (a whole number of physics steps)", True),
            Parameter("accel_max", "m/s²", d["accel_max"], 0.01, 100.0, C, "forward-speed ramp limit", True),
            Parameter("full_speed", "rad/s", POLOLU_MP_6V_30_1.constants().no_load_speed_wheel(PhysicsOptions().supply_voltage),
                      1.0, 1000.0, C, "wheel speed the firmware expects at full PWM (datasheet no-load speed)", True),
            Parameter("integral_limit", "rad·s", d["integral_limit"], 0.0, 10.0, C, "anti-windup bound on ∫e dt"),
            Parameter("cal_duty", "-", d["cal_duty"], 0.01, 1.0, C, "PWM duty of the calibration turn", True),
            Parameter("cal_sweep", "rad", d["cal_sweep"], 0.1, 3.0, C, "nominal calibration sweep each way", True),
            Parameter("cal_sweeps", "-", d["cal_sweeps"], 1, 10, C, "calibration sweeps", True, integer=True),
        ),
        realised_by="twin/csrc/firmware (C, also built for the ATmega328P; reference: twin.model.control)",
    )


def timing_model() -> PartialModel:
    t = Timing()
    return PartialModel(
        "timing",
        "when the motors take the duties a control tick decides: release, the read (physics), compute",
        inputs=(Port("motor_command", "V"), Port("sensor_readings", "µs"), Port("bus_voltage", "V")),
        outputs=(Port("motor_voltage", "V", "left, right: the commands as the motors see them, a reaction time after "
                      "each tick, at the PWM's whole counts"),),
        parameters=(
            Parameter("release", "µs", t.release_us, 0.0, 5000.0, C, "control tick to the QTR-RC lines' release "
                      "(measured on the emulated ATmega328P)"),
            Parameter("compute", "µs", t.compute_us, 0.0, 50000.0, C, "end of the sensor read to the PWM write: "
                      "the firmware's compute time on its general path, the line seen off centre, and an external "
                      "controller's (measured on the emulated ATmega328P)"),
            Parameter("compute_centred", "µs", t.compute_centred_us, 0.0, 50000.0, C, "the compute time when the "
                      "line reads exactly at the centre, e = 0 (measured on the emulated ATmega328P)"),
            Parameter("compute_lost", "µs", t.compute_lost_us, 0.0, 50000.0, C, "the compute time when the line is "
                      "lost (measured on the emulated ATmega328P)"),
            Parameter("compute_calibrate", "µs", t.compute_calibrate_us, 0.0, 50000.0, C, "the compute time of a "
                      "calibration tick, after its ten reads (measured on the emulated ATmega328P)"),
            Parameter("pwm_counts", "-", t.pwm_counts, 0, 65536, C, "motor PWM period in timer counts: duties are "
                      "whole counts, full drive one count short (3pi: 256); 0: any duty", integer=True),
        ),
        realised_by="twin/csrc/sim/mujoco_glue.c (decide, drive; reference: twin.model.timing)",
    )


def power_model() -> PartialModel:
    return PartialModel(
        "power",
        "battery → the motor driver's supply: the cells' internal resistance, or a boost regulator (twin.model.power)",
        inputs=(Port("motor_command", "V", "left, right: the duties, as voltages at the nominal supply"),
                Port("motor_current", "A", "left, right")),
        outputs=(Port("bus_voltage", "V", "the H-bridges' supply under load; 0 once a regulator shut off"),),
        parameters=(
            Parameter("source_resistance", "Ω", SOURCE_OHM, 0.0, 100.0, F, "between the cells and the H-bridges: "
                      "4 × 30 mΩ, Panasonic HHR70AAAJ (AAA NiMH) at 1 kHz, charged; more as they discharge"),
            Parameter("regulator_voltage", "V", 0.0, 0.0, 48.0, F, "boost regulator output for the motors (the "
                      "3pi: 9.25 V); 0: the motors run from the battery"),
            Parameter("regulator_min_input", "V", 0.0, 0.0, 48.0, F, "the regulator's lowest battery voltage; "
                      "below it shuts off for the rest of the run (the 3pi: 3.5 V)"),
        ),
        realised_by="twin/csrc/sim/mujoco_glue.c (lf_bus_voltage; reference: twin.model.power)",
    )


INFLUENCES = (
    ("cad", "motion", "L, R, masses, inertias and d are parameters of Eqs. 4–5: the world is rebuilt"),
    ("environment", "motion", "the floor texture and its extent are part of the simulated world: rebuilt"),
    ("motor", "motion", "rotor inertia and gearbox losses add to the wheels' inertia and damping"),
    ("cad", "sensor", "S and the sensor height place the rays; R and L set the firmware's wheel geometry"),
    ("motor", "control", "no-load speed at the supply voltage maps wheel speed to PWM duty"),
)


def default_space() -> ModelSpace:
    """The model space with every partial model at its default values."""
    return ModelSpace(
        [cad_model(), environment_model(), motion_model(), motor_model(), sensor_model(), control_model(), timing_model(),
         power_model()],
        INFLUENCES
    )
