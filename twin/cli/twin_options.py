"""The twin, and the program it runs, that a command's options describe: the one public way to build a twin from
the command line (:func:`twin_from_args`). The libraries load here, when a command first builds what its flags
describe; :mod:`twin.cli.options` builds the parsers without them."""

from __future__ import annotations

import argparse
import logging
import math
import os
from typing import TYPE_CHECKING

from mjcf.robot_config import RobotConfig
from twin.cli import options as o
from twin.cli.library_values import MOTOR_MODEL
from twin.cli.startup import loading
from twin.errors import TwinError

if TYPE_CHECKING:
    from twin.core.digital_twin import DigitalTwin

log = logging.getLogger(__name__)


def check_program_runs(twin: DigitalTwin, program) -> None:
    """The program ``--firmware`` names (None: the twin's own, built here) checked against ``twin`` before any lap:
    one line (a missing simavr included) otherwise."""
    with loading():
        from twin.pil import runnable_firmware
        from twin.pil.board import runnable_program

    if program is None:
        runnable_firmware(twin)
    else:
        runnable_program(twin, program.path)


def program_from_args(args: argparse.Namespace):
    """The program ``--firmware FILE`` names, loaded and checked for the MCU (None for c and avr); the ``--operator``
    script if one is given. A one-line TwinError on a bad file."""
    with loading():
        from twin.pil.board import load_script
        from twin.pil.program import load_program

    firmware = getattr(args, "firmware", "c")
    program = None if firmware in ("c", "avr") else load_program(firmware)
    script = getattr(args, "operator", None)
    if script and (program is None or program.traced):
        raise TwinError("--operator: presses buttons for a 3pi program run on the board (--firmware FILE of a program "
                        "other than the twin's own firmware)")
    return program, load_script(script) if script else None


def parse_sensor_mount(text: str | None) -> tuple[str, tuple[float, float, float]] | None:
    """``"base_link:0.1,0,-0.03"`` → ("base_link", (0.1, 0.0, -0.03))."""
    if not text:
        return None
    link, sep, xyz = text.rpartition(":")
    try:
        values = tuple(float(v) for v in xyz.split(","))
    except ValueError:
        values = ()
    if not sep or not link or len(values) != 3 or not all(math.isfinite(v) and abs(v) < 10 for v in values):
        raise TwinError(f"--sensor-mount {text!r}: expected LINK:X,Y,Z in metres, e.g. base_link:0.1,0,-0.03")
    return link, values  # type: ignore[return-value]


def robot_config(args: argparse.Namespace) -> RobotConfig:
    """Which parts of the robot description are the wheels, caster and sensor mount, and how to read it."""
    wheels = None
    if getattr(args, "wheel_joints", None):
        parts = args.wheel_joints.split(",")
        if len(parts) != 2 or not all(p.strip() for p in parts):
            raise TwinError(f"--wheel-joints {args.wheel_joints!r}: expected LEFT,RIGHT")
        wheels = (parts[0].strip(), parts[1].strip())
    packages = []
    for item in getattr(args, "package", None) or ():
        name, sep, path = item.partition("=")
        if not sep or not name.strip() or not path.strip():
            raise TwinError(f"--package {item!r}: expected NAME=DIR")
        if not os.path.isdir(path):
            raise TwinError(f"--package {item}: {path} is not a folder")
        packages.append((name.strip(), path))
    xacro_args = tuple(o.parse_assignments(getattr(args, "xacro_arg", None), "--xacro-arg").items())
    description = getattr(args, "robot", None) or getattr(args, "urdf", None)
    given = [f for f, v in (("--wheel-joints", wheels), ("--caster", getattr(args, "caster", None)),
                            ("--sensor-link", getattr(args, "sensor_link", None)),
                            ("--sensor-mount", getattr(args, "sensor_mount", None)), ("--package", packages),
                            ("--xacro-arg", xacro_args)) if v]
    if given and not description:
        raise TwinError(f"{given[0]}: describes a robot description; give one with --robot")
    return RobotConfig(wheel_joints=wheels, caster=getattr(args, "caster", None),
                       sensor_link=getattr(args, "sensor_link", None),
                       sensor_mount=parse_sensor_mount(getattr(args, "sensor_mount", None)),
                       package_dirs=tuple(packages), xacro_args=xacro_args)


def twin_from_args(args: argparse.Namespace, track: str | None = None, robot: str | None = None) -> DigitalTwin:
    """The twin the command line describes: world options (a named robot's values: ``--robot 3pi``), then --gains,
    --params, then --set (which wins).

    Args:
      args: parsed options of :func:`add_world` and :func:`add_values` (missing ones are skipped).
      track: overrides ``args.track`` (e.g. the track a telemetry file names).
      robot: the named robot when ``--robot`` names none (a 3pi program runs on the 3pi).
    """
    with loading():
        from twin.core.digital_twin import DigitalTwin
        from twin.model.parameter_files import load_gains, load_values
        from twin.model.robots import named_robot, use_robot

    given = getattr(args, "robot", None)
    named = named_robot(given or robot or "")
    config = robot_config(args)
    if named is not None and given and config != RobotConfig():
        raise TwinError(f"--robot {given}: a named robot has no description to read; the description flags apply to a "
                        "URDF or xacro")
    twin = DigitalTwin(track=track or getattr(args, "track", None) or "default",
                       robot_urdf=None if named is not None else given, robot_config=config,
                       track_metres_per_pixel=getattr(args, "metres_per_pixel", None))
    if named is not None:
        use_robot(twin, named)
    changes: dict = {}
    if getattr(args, "gains", None):
        changes.update(load_gains(args.gains, twin.space))
    if getattr(args, "params", None):
        changes.update(load_values(args.params, twin.space))
    changes.update(o.parse_assignments(getattr(args, "set", None)))
    model = changes.pop(MOTOR_MODEL, None)
    if model is not None and getattr(args, "motor", None) not in (None, model):
        raise TwinError(f"--motor {args.motor} and --set {MOTOR_MODEL}={model}: two motors; give one")
    twin.update(changes)
    _choose_motor(twin, getattr(args, "motor", None) or model, changes)
    return twin


def gains_warning(args: argparse.Namespace, twin: DigitalTwin) -> str | None:
    """When ``--gains`` names a file tuned for another robot, motor or track than ``twin`` runs: one line, logged as
    a warning; the command puts it in its ``--json`` too (``gains_warning``, null when the gains fit)."""
    with loading():
        from twin.core.identity import mismatch
        from twin.model.parameter_files import tuned_for_record

    path = getattr(args, "gains", None)
    why = mismatch(tuned_for_record(path), twin, path) if path else None
    if why:
        log.warning(why)
    return why


def _choose_motor(twin: DigitalTwin, name: str | None, changes: dict) -> None:
    """``--motor NAME``, or for a robot description without motor values of its own, the motor that fits it;
    values given with --gains, --params or --set still win. Says what it chose."""
    with loading():
        from twin.model.motor_setup import catalogue_motor, motor_for_robot, use_motor

    if name is None and (twin.robot_urdf is None or any(a.startswith("motor.") and a != "motor.supply_voltage"
                                                        for a in changes)):
        return
    if name is not None:
        datasheet, why = catalogue_motor(name), f"--motor {name}"
    else:
        choice = motor_for_robot(twin, twin.power().nominal_v)
        datasheet, why = choice.datasheet, f"{choice.name}: {choice.reason}"
    use_motor(twin, datasheet, keep=changes)
    log.warning("motor: %s", why)


def place_sensors(args: argparse.Namespace, twin: DigitalTwin, values: dict[str, float]) -> None:
    """Put the twin's line array where a --multi-model's sensors are (``values``: sensor.count, sensor.pitch, cad.S);
    a --set of those addresses contradicts the stand-in file, and a place the twin's robot cannot take is refused,
    each in one line."""
    clash = sorted(set(o.parse_assignments(getattr(args, "set", None))) & set(values))
    if clash:
        raise TwinError(f"--set {clash[0]}: the --stand-in file places the sensors where the multi-model puts them "
                        f"({clash[0]}={values[clash[0]]:g}); leave it out, or drop \"sensor\" from the stand-in file")
    try:
        twin.update(values)
    except (TwinError, ValueError) as e:
        raise TwinError(f"--stand-in {args.stand_in}: cannot be stood in for: {e}") from None


def controller_from_args(args: argparse.Namespace, twin: DigitalTwin, out) -> tuple:
    """(the checked and mapped controller FMU that drives instead of the firmware, or None; the multi-model run it
    comes from, or None) of :func:`options.add_controller`'s options; a multi-model places the twin's sensors where
    its own are, and its notes are said on ``out``."""
    if bool(args.multi_model) != bool(args.stand_in):
        raise TwinError("--multi-model and --stand-in go together: the multi-model, and the file that says what in it "
                        "the twin stands in for")
    if args.coe and not args.multi_model:
        raise TwinError("--coe: the co-simulation configuration of a --multi-model; give one")
    if args.multi_model and (args.controller_fmu or args.firmware != "c"):
        raise TwinError("--multi-model: its controller FMU drives the twin; leave out --controller-fmu and --firmware")
    if args.map and not args.controller_fmu:
        raise TwinError("--map: maps the variables of a --controller-fmu; give one (a --multi-model's mapping is its "
                        "connections with the stand-in file's relations)")
    if args.controller_param and not (args.controller_fmu or args.multi_model):
        raise TwinError("--controller-param: sets the parameters of a --controller-fmu or a --multi-model's "
                        "controller; give one")
    if not (args.controller_fmu or args.multi_model):
        return None, None
    with loading():
        from twin.fmi import ControllerFmu, parse_map, parse_params, read_multi_model

    if args.controller_fmu:
        if args.firmware != "c":
            raise TwinError("--controller-fmu: the controller FMU drives instead of the firmware; leave out --firmware")
        return ControllerFmu(args.controller_fmu, parse_map(args.map), int(twin.space.get("sensor.count")),
                             twin.space.get("control.dt"), parse_params(args.controller_param)), None
    peer = read_multi_model(args.multi_model, args.stand_in, args.coe)
    peer.parameters.update(parse_params(args.controller_param))  # the command line over the multi-model's own
    place_sensors(args, twin, peer.values)
    for note in peer.notes:
        out.say(f"note: {note}")
    return ControllerFmu(peer.fmu, peer.mapping, int(twin.space.get("sensor.count")), twin.space.get("control.dt"),
                         peer.parameters, peer.step_s), peer
