"""World assembly: a converted robot, its DC motors and a textured track floor in one MjSpec.

The floor is a finite plane exactly the size of the track texture, whose PNG is referenced by file
(``spec.to_xml()`` cannot write a texture given as a buffer). The tyres get contact priority over the
floor so that the tyre–floor friction μ is the tyres' own (MuJoCo otherwise takes the larger of the two).

A cylinder tyre touches MuJoCo's plane at both rims, L ± w/2 from the centre; in a turn the rims
scrub against each other and ω falls 2–15 % below Eq. 2 (more with more grip). Real rubber tyres are
crowned and carry their load near the mid-plane, so a cylinder tyre is simulated as an ellipsoid of the
same radius and half-width (one contact at the mid-plane), with a stiffer contact (``TYRE_SOLREF``) so
that its compression does not shrink the rolling radius. Measured on the default robot: v and ω then
match Eqs. 1–2 within 0.2 % for μ from 0.9 to 2.
"""

from __future__ import annotations

import dataclasses
import math
import os
import shutil

import mujoco
import numpy as np
from PIL import Image

from lf_common.files import MJCF_MARKER, atomic_file, check_output_dir, check_output_file, first_line_is_ours, output_dir
from mjcf.errors import MjcfError, check_positive_fields
from mjcf.robot_config import RobotConfig
from mjcf.track import FloorTexture, Pose2D
from mjcf.urdf_to_mjcf import RobotInfo, convert
from line_sensor.geometry import SensorArray
from motors import MotorConstants
from motors.actuator import add_gearmotor

FLOOR = "floor"
MOTORS = ("left_motor", "right_motor")
AXLE_SITE = "axle_centre"
SENSOR_SITE = "sensor_array"
LINE_SENSOR = "line_sensor_{}"  # site of reflectance sensor i (0 = leftmost); its z axis points at the floor
TYRE_SOLREF = (0.005, 1.0)  # [s, -] contact time constant and damping ratio; needs timestep <= 2.5 ms
# A ball caster's rolling resistance as a coefficient of its normal load (-): the ball rolls on the floor and slides
# in its socket, where friction mu_s at the ball's radius needs a force mu_s N at the floor (the same lever arm), so
# the coefficient is the socket's sliding friction. The 3pi's caster is a 1/2" plastic ball in a plastic socket
# (Pololu item 957); Pololu publishes no figure for it. The value is the low end of the published range for slide
# bearings, 0.08-0.1 (NORD Drivesystems' rolling-resistance calculator, "coefficient of friction for support
# bearings"; the rolling lever arm of a polymer ball on a hard floor, 0.08 mm over its 6.35 mm radius, adds 0.013,
# inside that range). A caster with a ball in bearings (a ball-transfer unit) is nearer 0.005.
CASTER_MU = 0.08
# The default robot's casters resist rolling as a plastic ball does (issue 33); `--set motion.caster_mu=0` gives the
# frictionless caster the twin had before. The calibration turn is planned with it (control.cal_sweep).
CASTER_MU_DEFAULT = CASTER_MU
START_KEY = "start"


@dataclasses.dataclass(frozen=True)
class PhysicsOptions:
    """Simulation settings.

    Attributes:
      timestep: physics step in [s].
      tyre_mu: tyre–floor sliding friction μ [-] (``motion.mu``).
      floor_mu: the floor's own friction [-]; governs only contacts without a tyre or a caster.
      caster_mu: the ball casters' rolling resistance per unit of their normal load [-] (``motion.caster_mu``): a
        Coulomb force at the caster's contact against its motion in any direction (CASTER_MU).
      supply_voltage: battery voltage in [V]; the motor voltage control is clamped to ±this.
      impratio: frictional-to-normal impedance ratio; >1 reduces MuJoCo's soft-contact creep.
    """

    timestep: float = 0.001
    tyre_mu: float = 0.9
    floor_mu: float = 0.6
    caster_mu: float = CASTER_MU_DEFAULT
    supply_voltage: float = 6.0
    impratio: float = 10.0

    def __post_init__(self) -> None:
        check_positive_fields(self, "physics", may_be_zero=("caster_mu",))
        if self.timestep > TYRE_SOLREF[0] / 2:
            raise MjcfError(f"physics.timestep: {self.timestep:g} s is too coarse for the tyre contacts (max {TYRE_SOLREF[0] / 2:g} s)")


def write_texture_png(texture: FloorTexture, path: str) -> None:
    """Write the floor texture as an RGB PNG (DPI metadata carries its scale), atomically."""
    rgb = np.repeat(texture.grey[:, :, None], 3, axis=2)
    dpi = 0.0254 / texture.metres_per_pixel
    tmp = f"{path}.{os.getpid()}.tmp.png"
    Image.fromarray(rgb).save(tmp, dpi=(dpi, dpi), compress_level=6)
    os.replace(tmp, path)


def build_world(
    urdf_path: str,
    texture: FloorTexture,
    texture_png: str,
    start: Pose2D,
    motor: MotorConstants,
    physics: PhysicsOptions = PhysicsOptions(),
    config: RobotConfig = RobotConfig(),
    sensors: SensorArray = SensorArray(),
) -> tuple[mujoco.MjSpec, RobotInfo]:
    """The whole world as an MjSpec; compile it with ``spec.compile()``.

    Args:
      urdf_path: the robot.
      texture: the floor texture (its size and placement in the world).
      texture_png: the same texture as a PNG file (see :func:`write_texture_png`).
      start: robot start pose; stored as keyframe ``start``.
      motor: constants of both drive motors.
      physics: timestep, friction and supply voltage.
      config: names of wheels, caster and sensor mount in the URDF.
      sensors: the reflectance array: one site per sensor across the sensor mount's y axis, its z axis
        pointing at the floor. The controller casts its ray (``mj_ray``) when it reads the sensor, at its own
        period, rather than a rangefinder sensor on every physics step.
    """
    spec = mujoco.MjSpec()
    spec.modelname = "line_follower_world"
    spec.compiler.degree = False
    spec.option.timestep = physics.timestep
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    spec.option.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
    spec.option.impratio = physics.impratio

    w, h = texture.size_m
    tex = spec.add_texture(name="track", type=mujoco.mjtTexture.mjTEXTURE_2D, file=os.path.abspath(texture_png))
    del tex
    mat = spec.add_material(name="track")
    mat.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = "track"
    mat.texrepeat = [1.0, 1.0]
    mat.texuniform = False
    floor = spec.worldbody.add_geom(
        name=FLOOR,
        type=mujoco.mjtGeom.mjGEOM_PLANE,
        size=[w / 2, h / 2, 0.05],
        pos=[texture.origin_xy[0] + w / 2, texture.origin_xy[1] + h / 2, 0.0],
        material="track",
    )
    floor.friction = [physics.floor_mu, 0.005, 0.0001]
    spec.worldbody.add_light(pos=[texture.origin_xy[0] + w / 2, texture.origin_xy[1] + h / 2, 3.0], dir=[0, 0, -1])

    spec, info = convert(urdf_path, config, spec=spec)
    root = spec.body(info.root_body)
    root.pos = [start.x, start.y, info.ground_height]
    root.quat = [math.cos(start.yaw / 2), 0.0, 0.0, math.sin(start.yaw / 2)]
    root.add_site(name=AXLE_SITE, pos=list(info.axle_centre), size=[0.003, 0, 0], group=4)
    # the array: a frame at the mount whose z axis (each site's ray) points at the floor and whose y runs across
    mount = spec.body(info.sensor_body).add_frame(pos=list(info.sensor_pos), quat=list(info.sensor_quat))
    mount.add_site(name=SENSOR_SITE, size=[0.003, 0, 0], group=4)
    for i, y in enumerate(sensors.lateral_offsets()):
        # turned half a turn about x, +y of the frame is -y of the robot: sensor 0 (leftmost) at -y here
        mount.add_site(name=LINE_SENSOR.format(i), pos=[0.0, -float(y), 0.0], size=[0.001, 0, 0], group=4)
    for g in info.tyre_geoms:
        geom = spec.geom(g)
        geom.priority = 1  # this geom's friction governs its contacts
        geom.friction = [physics.tyre_mu, 0.005, 0.0001]
        geom.condim = 3
        geom.solref = list(TYRE_SOLREF)
        if geom.type == mujoco.mjtGeom.mjGEOM_CYLINDER:  # crowned tyre: see the module docstring
            geom.type = mujoco.mjtGeom.mjGEOM_ELLIPSOID
            geom.size = [geom.size[0], geom.size[0], geom.size[1]]
    for g in info.caster_geoms:  # priority (set by convert): its own friction governs, whatever the floor's; condim 3
        geom = spec.geom(g)  # even at 0, so that motion.caster_mu can change in the compiled model
        geom.condim = 3
        geom.friction = [physics.caster_mu, 0.0, 0.0]
    for name, joint, direction in zip(MOTORS, info.wheel_joints, info.wheel_directions):
        add_gearmotor(spec, name, joint, motor, direction=direction, max_voltage=physics.supply_voltage)
    model = _compile(spec, urdf_path)
    key = spec.add_key(name=START_KEY)
    key.qpos = model.qpos0.copy()  # the root's free joint starts at its body pose: the start pose
    return spec, info


def _compile(spec: mujoco.MjSpec, what: str) -> mujoco.MjModel:
    try:
        return spec.compile()
    except ValueError as e:
        raise MjcfError(f"{what}: MuJoCo cannot compile the model ({str(e).splitlines()[0]})") from None


def compile_world(spec: mujoco.MjSpec, what: str = "world") -> mujoco.MjModel:
    """Compile, turning MuJoCo's compiler errors into one-line :class:`MjcfError`."""
    return _compile(spec, what)


def save_xml(spec: mujoco.MjSpec, out_path: str) -> str:
    """Write the spec as MJCF with its meshes and textures copied to ``<stem>_assets/`` beside it.

    Replaces only an MJCF file and an assets folder that this program wrote (``lf_common.files``); both are
    checked before anything is written, built under temporary names, and renamed into place (assets first).
    Returns the XML path.
    """
    full = check_output_file(out_path, first_line_is_ours, "MJCF file")
    stem = os.path.splitext(os.path.basename(full))[0]
    assets = f"{stem}_assets"
    check_output_dir(os.path.join(os.path.dirname(full), assets), "MJCF assets folder")
    copy = spec.copy()
    with atomic_file(out_path, first_line_is_ours, "MJCF file") as f:
        with output_dir(os.path.join(os.path.dirname(full), assets), "MJCF assets folder") as tmp_assets:
            copied: dict[str, str] = {}  # asset file name → source: two sources of one name get distinct names
            for item in list(copy.meshes) + list(copy.textures):
                if not item.file:
                    continue
                base = os.path.basename(item.file)
                while copied.get(base, item.file) != item.file:
                    base = f"_{base}"
                if base not in copied:
                    shutil.copyfile(item.file, os.path.join(tmp_assets, base))
                    copied[base] = item.file
                item.file = os.path.join(tmp_assets, base)
            try:
                xml = copy.to_xml()
            except Exception as e:  # MuJoCo raises plain errors for what it cannot write
                raise MjcfError(f"{out_path}: cannot write MJCF ({str(e).splitlines()[0]})") from None
            # to_xml reads the assets, so they pointed at the temporary folder; point them at the final one
            f.write(MJCF_MARKER + "\n" + xml.replace(f'"{tmp_assets}/', f'"{assets}/'))
    return full
