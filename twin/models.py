"""Declarations of the partial models that the foundation provides: CAD, environment, motion, DC motor.

Defaults come from the code that realises each model (``RobotDesign``, the Pololu motor datasheet,
``PhysicsOptions``), so there is one source for every nominal value.
"""

from __future__ import annotations

import dataclasses

from mjcf.design import DESIGN_UNITS, RobotDesign
from mjcf.track import LINE_WIDTH_M
from mjcf.world import TYRE_SOLREF, PhysicsOptions
from motors import POLOLU_MP_6V_30_1
from twin.model_space import ChangeCost, ModelSpace, Parameter, PartialModel, Port

R, F = ChangeCost.REBUILD, ChangeCost.MODEL_FIELD

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
            Parameter("floor_mu", "-", phys.floor_mu, 0.05, 2.0, F, "floor friction for non-tyre contacts", True),
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
        "voltage → torque (Eqs. 6–7), both drive motors",
        inputs=(Port("motor_voltage", "V", "left, right"), Port("wheel_speed", "rad/s")),
        outputs=(Port("wheel_torque", "N·m", "left, right"), Port("motor_current", "A", "left, right")),
        parameters=(
            Parameter("R_M", "Ω", m.R_M, 0.1, 1000.0, F, "winding resistance", True),
            Parameter("L_M", "H", m.L_M, 0.0, 0.1, F, "winding inductance (0 ↔ >0 rebuilds)"),
            Parameter("K", "N·m/A", m.K, 1e-5, 1.0, F, "torque = back-EMF constant", True),
            Parameter("b_M", "N·m·s/rad", m.b_M, 0.0, 1e-3, F, "viscous friction at the motor shaft"),
            Parameter("J_rotor", "kg·m²", m.J_rotor, 0.0, 1e-4, F, "rotor inertia"),
            Parameter("gear", "-", m.gear, 1.0, 1000.0, F, "gearbox ratio", True),
            Parameter("supply_voltage", "V", PhysicsOptions().supply_voltage, 0.5, 24.0, F, "battery voltage, the voltage limit", True),
        ),
        realised_by="MuJoCo 4 dcmotor actuator (motors.actuator)",
    )


INFLUENCES = (
    ("cad", "motion", "L, R, masses, inertias and d are parameters of Eqs. 4–5: the world is rebuilt"),
    ("environment", "motion", "the floor texture and its extent are part of the simulated world: rebuilt"),
    ("motor", "motion", "rotor inertia and gearbox losses add to the wheels' inertia and damping"),
)


def default_space() -> ModelSpace:
    """The model space with the foundation's partial models at their default values."""
    return ModelSpace([cad_model(), environment_model(), motion_model(), motor_model()], INFLUENCES)
