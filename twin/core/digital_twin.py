"""The twin: model-space values → a compiled MuJoCo world, rebuilt only when a change needs it.

A CAD or environment parameter rebuilds URDF, MJCF and model; a motion or motor parameter is written
into the compiled model's fields (so a ``mujoco.batch`` can hold different values per simulation).
Generated robots and rasterised tracks are cached on disk by content hash, verified on every use
(:mod:`lf_common.cache`); the compiled floor texture is then overwritten with the one the twin holds.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import logging
import math
import os
from typing import Mapping

import mujoco
import numpy as np

from lf_common.cache import cache_dir, cached_folder
from mjcf.cad import write_robot
from mjcf.design import RobotDesign
from mjcf.robot_config import RobotConfig
from mjcf.track import GROUND_GREY, LINE_GREY, FloorTexture, Track
from mjcf.urdf_to_mjcf import RobotInfo
from mjcf.world import AXLE_SITE, FLOOR, MOTORS, SENSOR_SITE, PhysicsOptions, build_world, compile_world, write_texture_png
from line_sensor.geometry import SensorArray, SensorError
from line_sensor.reflectance import SensorModel
from line_sensor.working_range import describe as describe_sensor, max_working_height_m
from motors import MotorConstants
from motors.actuator import write_fields
from twin.core import native as core
from twin.model.control import ControlParams
from twin.model.environment import load_track
from twin.errors import TwinError
from twin.core.lap import LapLimits
from twin.core.lap_cache import BatchCache, CalibrationCache
from twin.model.space import ChangeCost, ModelSpace
from twin.model.partial_models import default_space
from twin.model.power import Power
from twin.model.timing import Timing

log = logging.getLogger(__name__)


def _digest(obj) -> str:
    return hashlib.sha256(json.dumps(obj, sort_keys=True, default=str).encode()).hexdigest()[:16]


def check_whole_steps(dt_s: float, timestep_s: float) -> None:
    """The control period ``control.dt`` must be a whole number of physics steps ``motion.timestep`` [s]; else a
    TwinError names a step that is."""
    steps = dt_s / timestep_s
    if abs(steps - round(steps)) > 1e-9 or round(steps) < 1:
        fit = dt_s / max(1, math.ceil(dt_s / timestep_s - 1e-9))
        # the suggestion in full (repr): rounded to a few digits it would not divide control.dt either
        raise TwinError(f"control.dt: {dt_s:g} s is not a whole number of physics steps ({timestep_s:g} s); "
                        f"set motion.timestep to a fraction of it, e.g. {fit!r}")


class DigitalTwin:
    """The integrated model of one robot on one track.

    Args:
      track: built-in track name or PNG path.
      robot_urdf: a robot description (URDF or xacro) to use instead of the generated robot; then of ``cad.*``
        only ``cad.S`` can be set (it moves the line array to S ahead of the axle).
      robot_config: names of wheels, caster and sensor mount in ``robot_urdf``, xacro arguments, packages.
      track_metres_per_pixel: scale of a PNG track without DPI metadata, in [m].
      space: the model space (default: :func:`twin.model.partial_models.default_space`).
    """

    def __init__(
        self,
        track: str = "default",
        robot_urdf: str | None = None,
        robot_config: RobotConfig = RobotConfig(),
        track_metres_per_pixel: float | None = None,
        space: ModelSpace | None = None,
    ):
        self.space = space if space is not None else default_space()
        self.track_source = track
        self.robot_urdf = os.path.abspath(robot_urdf) if robot_urdf else None
        self.robot_config = robot_config
        self.track_metres_per_pixel = track_metres_per_pixel
        self._model: mujoco.MjModel | None = None
        self._spec: mujoco.MjSpec | None = None
        self._built_key = None
        self._track_key = None
        self.track: Track | None = None
        self.texture: FloorTexture | None = None
        self.info: RobotInfo | None = None
        self.rebuilds = 0  # how many times the world was compiled: tests and logs read it
        self.sensor_distance = 0.0  # S measured on the built robot: axle centre to sensor array [m]
        self.batches = BatchCache()  # run_laps' mujoco.batch, per build
        self.calibrations = CalibrationCache()  # calibration turns made, per build
        self.sensor_ahead: float | None = None  # cad.S set for a description's robot: where its array goes [m]

    def clone(self, changes: Mapping[str, float] | None = None) -> "DigitalTwin":
        """Another twin of the same robot on the same track with the same values (and ``changes``), built on its
        own: a change that rebuilds it never touches this one."""
        other = DigitalTwin(track=self.track_source, robot_urdf=self.robot_urdf, robot_config=self.robot_config,
                            track_metres_per_pixel=self.track_metres_per_pixel)
        other.space.values.update(self.space.values)
        other.sensor_ahead = self.sensor_ahead
        if changes:
            other.update(dict(changes))
        return other

    # --- parameters
    def _check_applies(self, address: str) -> None:
        """CAD parameters shape the generated robot; a given description is its own CAD model, except for where
        its line array sits ahead of the axle (``cad.S``)."""
        if address.startswith("cad.") and address != "cad.S" and self.robot_urdf is not None:
            self.space.parameter(address)  # an unknown address is reported as such first
            raise TwinError(f"{address}: the robot comes from {self.robot_urdf}; of the CAD parameters only cad.S "
                            "(the line array's distance ahead of the axle) applies to it")

    def _note_sensor_ahead(self, changes: Mapping[str, float]) -> None:
        if self.robot_urdf is not None and "cad.S" in changes:
            self.sensor_ahead = self.space.get("cad.S")

    def set(self, address: str, value: float) -> ChangeCost:
        """Set a model-space parameter; returns what it costs (applied at the next :meth:`model`)."""
        self._check_applies(address)
        cost = self.space.set(address, value)
        self._note_sensor_ahead({address: value})
        return cost

    def update(self, changes: dict[str, float]) -> None:
        """Set several parameters, all checked before any is stored."""
        for address in changes:
            self._check_applies(address)
        self.space.update(changes)
        self._note_sensor_ahead(changes)

    def checked_values(self, changes: Mapping[str, float]) -> dict[str, float]:
        """The twin's values with ``changes`` applied, each checked as :meth:`set` checks it; the twin is not changed."""
        for address in changes:
            self._check_applies(address)
        return {**self.space.values, **{a: self.space.parameter(a).check(a, v) for a, v in changes.items()}}

    def _all(self, values: Mapping[str, float] | None) -> Mapping[str, float]:
        """``values`` (every address), or the twin's own."""
        return self.space.values if values is None else values

    def _values(self, model: str, values: Mapping[str, float] | None) -> dict[str, float]:
        """{name: value} of one partial model's parameters, from ``values`` (every address) or the twin's own."""
        v = self._all(values)
        return {p.name: v[f"{model}.{p.name}"] for p in self.space.models[model].parameters}

    def design(self) -> RobotDesign:
        try:
            return RobotDesign(**self.space.model_values("cad"))
        except ValueError as e:
            raise TwinError(str(e)) from None

    def motor(self, values: Mapping[str, float] | None = None) -> MotorConstants:
        """The motor constants of the twin's values, or of ``values`` (every address, e.g. :meth:`checked_values`)."""
        v = self._values("motor", values)
        v.pop("supply_voltage")
        try:
            return MotorConstants(**v)
        except ValueError as e:
            raise TwinError(str(e)) from None

    def sensor_array(self) -> SensorArray:
        return SensorArray(count=int(self.space.get("sensor.count")), pitch=self.space.get("sensor.pitch"))

    def sensor_model(self, values: Mapping[str, float] | None = None) -> SensorModel:
        """The sensor response of the twin's values, or of ``values`` (every address)."""
        v = self._values("sensor", values)
        try:
            return SensorModel(
                aperture_m=v["aperture"], half_angle_rad=v["half_angle"], falloff_height_m=v["falloff_height"],
                t_unit_us=v["t_unit"], timeout_us=v["timeout"], noise_rel=v["noise"],
            )
        except SensorError as e:
            raise TwinError(str(e)) from None

    def timing(self, values: Mapping[str, float] | None = None) -> Timing:
        """The robot's timing of the twin's values, or of ``values`` (every address)."""
        v = self._values("timing", values)
        return Timing(release_us=v["release"], compute_us=v["compute"], compute_centred_us=v["compute_centred"],
                      compute_lost_us=v["compute_lost"], compute_calibrate_us=v["compute_calibrate"],
                      pwm_counts=int(v["pwm_counts"]))

    def power(self, values: Mapping[str, float] | None = None) -> Power:
        """The motor driver's supply of the twin's values, or of ``values`` (every address)."""
        v = self._values("power", values)
        return Power(battery_v=self._all(values)["motor.supply_voltage"], source_ohm=v["source_resistance"],
                     regulator_v=v["regulator_voltage"], regulator_min_input_v=v["regulator_min_input"])

    def control_params(self, values: Mapping[str, float] | None = None) -> ControlParams:
        """The firmware's parameters: gains from ``control.*`` of the twin's values or of ``values`` (every
        address), geometry measured on the built robot."""
        self.model()  # the robot's geometry (info, sensor_distance) comes from the build
        v = self._all(values)
        c = self._values("control", values)
        check_whole_steps(c["dt"], v["motion.timestep"])
        # the firmware's belief about its motors is its own constant (control.full_speed), not the simulated motor:
        # a robot whose real motors differ from the datasheet drives differently, as it would
        return ControlParams(
            count=int(v["sensor.count"]), pitch_m=v["sensor.pitch"],
            sensor_distance_m=self.sensor_distance, v_max=c["v_max"], k_b=c["kb"], k_p=c["kp"], k_i=c["ki"],
            k_d=c["kd"], dt_s=c["dt"], wheel_radius_m=self.info.wheel_radius, half_track_m=self.info.half_track,
            wheel_speed_max=c["full_speed"], accel_max=c["accel_max"],
            integral_limit=c["integral_limit"], cal_duty=c["cal_duty"], cal_sweep_rad=c["cal_sweep"],
            cal_sweeps=int(c["cal_sweeps"]),
        )

    def physics(self, values: Mapping[str, float] | None = None) -> PhysicsOptions:
        """The physics options of the twin's values, or of ``values`` (every address); their supply voltage is the
        nominal one PWM duty 1 gives (the regulator's, or the battery's: :attr:`Power.nominal_v`)."""
        v = self._values("motion", values)
        return PhysicsOptions(
            timestep=v["timestep"], tyre_mu=v["mu"], floor_mu=v["floor_mu"], caster_mu=v["caster_mu"],
            supply_voltage=self.power(values).nominal_v, impratio=v["impratio"],
        )

    # --- building
    def _rebuild_key(self) -> tuple:
        rebuild = {a: self.space.values[a] for a in self.space.addresses if self.space.parameter(a).cost is ChangeCost.REBUILD}
        # inductance 0 ↔ > 0 adds or removes the current state: a structural change
        return (_digest(rebuild), self.space.get("motor.L_M") > 0, self.robot_urdf, self.track_source, self.sensor_ahead)

    def _ensure_track(self) -> None:
        env = self.space.model_values("environment")
        key = (self.track_source, env["line_width"], env["texture_resolution"], self.track_metres_per_pixel)
        if key == self._track_key:
            return
        self.track, self.texture = load_track(
            self.track_source, env["line_width"], env["texture_resolution"], self.track_metres_per_pixel
        )
        self._track_key = key

    def _texture_png(self) -> str:
        """The floor texture as a PNG in the verified cache (MJCF references textures by file)."""
        tex = self.texture
        digest = hashlib.sha256(tex.grey.tobytes() + repr((tex.origin_xy, tex.metres_per_pixel)).encode()).hexdigest()[:16]
        folder = cached_folder(os.path.join(cache_dir(), "tracks", f"{self.track.name}-{digest}"),
                               lambda tmp: write_texture_png(tex, os.path.join(tmp, "floor.png")), "track texture")
        return os.path.join(folder, "floor.png")

    def _urdf(self) -> str:
        if self.robot_urdf is not None:
            return self.robot_urdf
        design = self.design()
        folder = cached_folder(os.path.join(cache_dir(), "robots", _digest(dataclasses.asdict(design))),
                               lambda tmp: write_robot(design, tmp), "generated robot")
        return os.path.join(folder, "robot.urdf")

    def sensor_height(self) -> float:
        """The line array's height above the floor at the start pose [m]."""
        return float(_at_start(self._model).site(SENSOR_SITE).xpos[2])

    def _check_sensor_mount(self, info: RobotInfo) -> None:
        """The one check of where the line array sits, whatever placed it (``--sensor-mount``, ``--sensor-link``, a
        link named *sensor*, ``cad.S``, the generated robot's CAD), run by every command that builds a world: ahead
        of the axle, and on a description's robot at a height where the sensor model can tell the line from the
        ground (the generated robot's height is a design parameter: too high a design fails its calibration turn,
        as a lap result). Sets :attr:`sensor_distance` (S)."""
        fix = "place it with --sensor-mount LINK:X,Y,Z (X ahead, Z up, in LINK's frame)"
        what = f"{self.robot_urdf or 'generated robot'}: the line array ({self._mount_source(info)})"
        s = _sensor_distance(self._model, self.track.start_pose().yaw)
        if s <= MIN_SENSOR_AHEAD_M:
            where = f"{s * 1000:.1f} mm ahead of" if s >= 0 else f"{-s * 1000:.1f} mm behind"
            how = f"{fix}, or move it ahead with --set cad.S=DISTANCE" if self.robot_urdf else "set cad.S"
            raise TwinError(f"{what} is {where} the axle; a line follower needs it more than "
                            f"{MIN_SENSOR_AHEAD_M * 1000:g} mm in front; {how}")
        self.sensor_distance = s
        if self.robot_urdf is None:
            return
        h = self.sensor_height()
        model = self.sensor_model()
        top = max_working_height_m(model, self.space.get("environment.line_width"), GROUND_GREY / 255,
                                   LINE_GREY / 255, LapLimits().min_calibration_range_us)
        if h <= 0:
            raise TwinError(f"{what} is {-h * 1000:.1f} mm below the floor; {fix}")
        if h > top:
            raise TwinError(f"{what} is {h * 1000:.1f} mm above the floor, where the sensor model cannot tell the line "
                            f"from the ground (it can up to {top * 1000:.1f} mm; {describe_sensor(model)}); {fix}")

    def _mount_source(self, info: RobotInfo) -> str:
        """How the line array was placed, as the user said it (or as the converter found it)."""
        config = self.robot_config
        if self.robot_urdf is None:
            return f"cad.S={self.space.get('cad.S'):g}"
        if config.sensor_mount is not None:
            link, xyz = config.sensor_mount
            placed = f"--sensor-mount {link}:{','.join(f'{v:g}' for v in xyz)}"
        elif config.sensor_link is not None:
            placed = f"--sensor-link {config.sensor_link}"
        else:
            placed = f"at link {info.sensor_body}'s origin: no --sensor-mount or --sensor-link given"
        return placed + (f", cad.S={self.sensor_ahead:g}" if self.sensor_ahead is not None else "")

    def spec(self) -> mujoco.MjSpec:
        """The world's spec (built if needed), e.g. to save it as MJCF."""
        self.model()
        return self._spec

    def model(self) -> mujoco.MjModel:
        """The compiled world with the current parameter values."""
        key = self._rebuild_key()
        if self._model is None or key != self._built_key:
            self._ensure_track()
            urdf = self._urdf()
            config = self.robot_config
            if self.sensor_ahead is not None:
                config = dataclasses.replace(config, sensor_ahead=self.sensor_ahead)
            spec, info = build_world(
                urdf, self.texture, self._texture_png(), self.track.start_pose(), self.motor(), self.physics(),
                config, self.sensor_array(),
            )
            spec.nuserdata = core.SIM_WORDS + RECORD_CAPACITY * core.RECORD_WORDS  # the C loop's state and trace
            spec.add_numeric(name=CENTRE_LINE, data=centre_line_data(self.track))  # the C loop's lap progress
            self._model = compile_world(spec, urdf)
            _hold_texture(self._model, self.texture)
            self._check_sensor_mount(info)
            self._spec, self.info, self._built_key = spec, info, key
            self.rebuilds += 1
            log.info("built world: robot %s on track %s", urdf, self.track.name)
        apply_fields(self._model, self.info, self.motor(), self.physics())
        return self._model


CENTRE_LINE = "track_centre"


def centre_line_data(track: Track) -> np.ndarray:
    """The centre line for the C loop: x, y, arc length of each vertex [m], then the track length."""
    return np.concatenate([np.column_stack([track.centre, track.arc_length[:-1]]).ravel(), [track.length_m]])


MIN_SENSOR_AHEAD_M = 0.005  # [m] nearer the axle, the array sees no line angle to steer by
RECORD_CAPACITY = 448  # trace ring per simulation, in control ticks; the runner drains it every chunk (≤ 400 ticks)


def _hold_texture(model: mujoco.MjModel, texture: FloorTexture) -> None:
    """Make the compiled floor texture the one the twin holds, byte for byte: the C loop reads the model's
    texture, and it must not depend on a file that could differ from the twin's own track."""
    t = model.texture("track")
    h, w = texture.grey.shape
    if (model.tex_height[t.id], model.tex_width[t.id]) != (h, w):
        raise TwinError(f"track texture: the compiled floor is {model.tex_width[t.id]}×{model.tex_height[t.id]} px, "
                        f"the track {w}×{h} px")
    n = int(model.tex_nchannel[t.id])
    adr = int(model.tex_adr[t.id])
    model.tex_data[adr: adr + h * w * n] = np.repeat(texture.grey[:, :, None], n, axis=2).ravel()


def _at_start(model: mujoco.MjModel) -> mujoco.MjData:
    """The world's kinematics at its start keyframe (the robot on the start line)."""
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, 0)
    mujoco.mj_kinematics(model, data)
    return data


def _sensor_distance(model: mujoco.MjModel, yaw: float) -> float:
    """S: how far the sensor array sits ahead of the axle centre along the heading, at the start pose [m]."""
    data = _at_start(model)
    ahead = data.site(SENSOR_SITE).xpos[:2] - data.site(AXLE_SITE).xpos[:2]
    return float(ahead @ np.array([np.cos(yaw), np.sin(yaw)]))


def apply_fields(model: mujoco.MjModel, info: RobotInfo, motor: MotorConstants, physics: PhysicsOptions) -> None:
    """Write the motion and motor parameters into a compiled world's fields."""
    for g in info.tyre_geoms:
        model.geom(g).friction[0] = physics.tyre_mu
    model.geom(FLOOR).friction[0] = physics.floor_mu
    for g in info.caster_geoms:
        model.geom(g).friction[0] = physics.caster_mu
    model.opt.timestep = physics.timestep
    model.opt.impratio = physics.impratio
    ids = [model.actuator(n).id for n in MOTORS]
    write_fields(model, ids, motor)
    model.actuator_ctrlrange[ids] = np.array([-physics.supply_voltage, physics.supply_voltage])
