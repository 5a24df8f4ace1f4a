"""A third-party controller FMU in the twin's loop: opened with fmpy, checked, its variables mapped to the twin's ports.

The FMU must be FMI 2.0 or 3.0 Co-Simulation with a binary for this platform; anything else is refused in one line
before the lap (not a zip, no modelDescription.xml, FMI 1.0, Model Exchange only, no binary here). Its inputs take
the twin's sensor side (:func:`sense_ports`: the readLine position, Eq. 9's angle, the readings, the encoders, the
energy used); its outputs drive the motors (:data:`DRIVE_PORTS`: both voltages, both wheel-speed set-points, or both
PWM duties). Each variable maps by its name (or a common spelling of it, :func:`default_mapping`) unless ``--map``
says otherwise, with sign, scale and offset (:mod:`twin.fmi.mapping`); one pair of outputs must map, and an input
that maps to nothing keeps its start value (with a note). ``--controller-param`` sets its parameters
(:mod:`twin.fmi.parameters`). The controller runs at its DefaultExperiment step size (else the twin's control.dt),
stepped from t to t + T on the inputs read at t; its outputs drive the motors from t on, as the firmware's do.
"""

from __future__ import annotations

import logging
import os
import re
import weakref
import zipfile
from typing import Mapping

from lf_common.errors import LineFollowerError
from lf_common.files import input_file
from twin.errors import TwinError
from twin.fmi.mapping import Link, check_unit
from twin.fmi.parameters import resolve_params
from twin.fmi.wall import ControllerHost, WalledController

log = logging.getLogger(__name__)

VOLTAGE, SETPOINT = ("voltage_left", "voltage_right"), ("wheel_speed_setpoint_left", "wheel_speed_setpoint_right")
DUTY = ("wheel_duty_left", "wheel_duty_right")
ACTUATION = {VOLTAGE: "voltage", SETPOINT: "setpoint", DUTY: "duty"}
DRIVE_PORTS = {
    "voltage_left": "left motor voltage [V]", "voltage_right": "right motor voltage [V]",
    "wheel_speed_setpoint_left": "left wheel speed set-point [rad/s] (PWM duty = set-point / control.full_speed)",
    "wheel_speed_setpoint_right": "right wheel speed set-point [rad/s] (PWM duty = set-point / control.full_speed)",
    "wheel_duty_left": "left motor PWM duty in [-1, 1] (> 0 forward; clipped)",
    "wheel_duty_right": "right motor PWM duty in [-1, 1] (> 0 forward; clipped)",
}
# the ports' units (None: dimensionless), for the FMU's declared units; a key is a port or a sensor port's kind
PORT_UNITS = {"line_angle": "rad", "wheel_speed_left": "rad/s", "wheel_speed_right": "rad/s", "energy_used": "J",
              "voltage_left": "V", "voltage_right": "V", "wheel_speed_setpoint_left": "rad/s",
              "wheel_speed_setpoint_right": "rad/s", "sensor.raw": "us"}
# the twin's own names, then other common spellings (compared lower-case, letters and digits only)
ALIASES = {
    "line_position": ("position", "linepos", "readline"),
    "line_angle": ("e", "angle", "lineerror", "error", "bearing"),
    "line_seen": ("online", "seen"),
    "wheel_speed_left": ("leftwheelspeed", "omegaleft", "speedleft", "encoderleft"),
    "wheel_speed_right": ("rightwheelspeed", "omegaright", "speedright", "encoderright"),
    "voltage_left": ("leftvoltage", "uleft", "ul", "motorleft", "leftmotor"),
    "voltage_right": ("rightvoltage", "uright", "ur", "motorright", "rightmotor"),
    "wheel_speed_setpoint_left": ("setpointleft", "leftsetpoint", "wheelspeedleftsetpoint"),
    "wheel_speed_setpoint_right": ("setpointright", "rightsetpoint", "wheelspeedrightsetpoint"),
    "wheel_duty_left": ("dutyleft", "leftduty", "pwmleft", "leftpwm"),
    "wheel_duty_right": ("dutyright", "rightduty", "pwmright", "rightpwm"),
    "energy_used": ("energy", "totalenergyused", "energyconsumed"),
}
FMI2_PLATFORM, FMI3_PLATFORM = "linux64", "x86_64-linux"
REAL_TYPES = ("Real", "Float64", "Float32")
INTEGER_TYPES = ("Integer", "Int32", "Int64", "Int16", "Int8", "UInt8", "UInt16", "UInt32", "UInt64")


def sense_ports(count: int) -> dict[str, str]:
    """The twin's ports a controller may read, with what each is."""
    ports = {
        "line_position": f"readLine position, 0 (sensor 1) to {(count - 1) * 1000} (sensor {count})",
        "line_angle": "Eq. 9 line angle [rad], > 0 to the left",
        "line_seen": "1 if a calibrated reading is above 200",
        "wheel_speed_left": "left wheel speed [rad/s] (encoder)", "wheel_speed_right": "right wheel speed [rad/s]",
        "energy_used": "electrical energy drawn by both motors since the lap's start [J]",
    }
    for i in range(1, count + 1):
        ports[f"sensor.calibrated[{i}]"] = f"sensor {i}, calibrated 0..1000 (Eq. 8; 1000 black)"
        ports[f"sensor.raw[{i}]"] = f"sensor {i}, raw RC reading [us]"
        ports[f"sensor.white_8bit[{i}]"] = f"sensor {i}, 8-bit, white high: round(255 (1000 - calibrated) / 1000)"
    return ports


def port_unit(port: str) -> str | None:
    return PORT_UNITS.get(port.split("[")[0])


SENSE_PORTS = sense_ports(8)  # for the default 8-sensor array


def _norm(name: str) -> str:
    return re.sub(r"[^a-z0-9]", "", name.lower())


def _aliases(port: str) -> set[str]:
    out = {_norm(port)} | set(ALIASES.get(port, ()))
    m = re.fullmatch(r"sensor\.(calibrated|raw|white_8bit)\[(\d+)\]", port)
    if m:
        kind, i = m.groups()
        out |= {_norm(f"{kind}{i}"), _norm(f"sensor{kind}{i}")}
        out |= {f"sensor{i}", f"s{i}"} if kind == "calibrated" else set()
    return out


def default_mapping(inputs: list[str], outputs: list[str], count: int) -> tuple[dict[str, str], dict[str, str]]:
    """({FMU input: twin port}, {FMU output: twin port}) for the variables whose names say which port they are."""
    def match(names, ports):
        table = {alias: port for port in ports for alias in _aliases(port)}
        return {n: table[_norm(n)] for n in names if _norm(n) in table}
    return match(inputs, sense_ports(count)), match(outputs, DRIVE_PORTS)


def _fail(path: str, why: str) -> TwinError:
    return TwinError(f"--controller-fmu {path}: {why}")


def read_controller(path: str):
    """fmpy's model description of a controller FMU that this platform can run, or TwinError in one line."""
    try:
        input_file(path, "file")  # a folder or a FIFO is not "no such file"
    except LineFollowerError as e:
        raise TwinError(f"--controller-fmu {e}") from None
    if not zipfile.is_zipfile(path):
        raise _fail(path, "not an FMU (not a zip archive)")
    from fmpy import read_model_description  # the loader (a dependency); imported when an FMU is used
    try:
        with zipfile.ZipFile(path) as z:
            names = set(z.namelist())
    except (OSError, zipfile.BadZipFile) as e:
        raise _fail(path, f"not an FMU ({e})") from None
    if "modelDescription.xml" not in names:
        raise _fail(path, "not an FMU (no modelDescription.xml in the archive)")
    with zipfile.ZipFile(path) as z, z.open("modelDescription.xml") as f:
        declared = re.search(rb"<fmiModelDescription[^>]*?\sfmiVersion\s*=\s*[\"']([^\"']*)", f.read(1 << 16))
    if declared and not declared.group(1).startswith((b"2.", b"3.")):
        raise _fail(path, f"FMI {declared.group(1).decode(errors='replace')} is not supported: the twin runs FMI 2.0 "
                    "or 3.0 Co-Simulation FMUs")
    try:
        md = read_model_description(path, validate=False)
    except Exception as e:  # fmpy raises plain exceptions for broken XML
        raise _fail(path, f"its modelDescription.xml cannot be read ({' '.join(str(e).split())[:200]})") from None
    version = str(md.fmiVersion)
    if not version.startswith(("2.", "3.")):
        raise _fail(path, f"FMI {version} is not supported: the twin runs FMI 2.0 or 3.0 Co-Simulation FMUs")
    if md.coSimulation is None:
        raise _fail(path, "it is for Model Exchange only: the twin runs Co-Simulation FMUs (export it for co-simulation)")
    folder = FMI2_PLATFORM if version.startswith("2.") else FMI3_PLATFORM
    binary = f"binaries/{folder}/{md.coSimulation.modelIdentifier}.so"
    if binary not in names:
        have = sorted({n.split("/")[1] for n in names if n.startswith("binaries/") and n.count("/") >= 2})
        raise _fail(path, f"it has no binary for this platform ({binary}; it has: {', '.join(have) or 'none'})")
    return md


def _variables(md) -> tuple[dict, dict]:
    ins = {v.name: v for v in md.modelVariables if v.causality == "input"}
    outs = {v.name: v for v in md.modelVariables if v.causality == "output"}
    return ins, outs


def resolve_mapping(path: str, md, overrides: Mapping[str, Link], count: int) -> tuple[dict, dict, dict]:
    """({FMU input: Link}, {twin drive port: Link of the FMU output that drives it}, {FMU input left at its start
    value: that value}), or TwinError in one line listing the FMU's variables."""
    ins, outs = _variables(md)
    by_name, by_output = default_mapping(list(ins), list(outs), count)
    sense = {n: Link(n, p) for n, p in by_name.items()}
    drive = {n: Link(n, p) for n, p in by_output.items()}
    ports = sense_ports(count)
    for name, link in overrides.items():
        if name in ins and link.port in ports:
            sense[name] = link
        elif name in outs and link.port in DRIVE_PORTS:
            drive = {n: k for n, k in drive.items() if k.port != link.port}
            drive[name] = link
        elif name not in ins and name not in outs:
            raise _fail(path, f"--map {name}={link.expression}: the FMU has no input or output {name!r} "
                        f"({_listing(ins, outs)})")
        else:
            side = ports if name in ins else DRIVE_PORTS
            raise _fail(path, f"--map {name}={link.expression}: {link.port!r} is not a twin port for an FMU "
                        f"{'input' if name in ins else 'output'} (choose from {', '.join(side)})")
    for name, v in list(ins.items()):
        if name in sense and v.type not in REAL_TYPES + INTEGER_TYPES + ("Boolean",):
            raise _fail(path, f"input {name} is of type {v.type}, which no twin port feeds")
    left = {n: ins[n].start for n in ins if n not in sense}
    by_port = {k.port: k for k in drive.values()}
    pairs = [pair for pair in ACTUATION if all(p in by_port for p in pair)]
    startless = [n for n, start in left.items() if start in (None, "")]
    if startless or len(pairs) != 1:
        why = (f"no twin port for its input{'s' if len(startless) > 1 else ''} {', '.join(startless)}, which has no "
               "start value to keep" if startless else
               "several pairs of motor outputs (voltages, set-points, duties): map one pair" if pairs else
               "no outputs for both motors (voltage_left/right, wheel_speed_setpoint_left/right or "
               "wheel_duty_left/right)")
        raise _fail(path, f"the mapping is incomplete: {why} ({_listing(ins, outs)}); map with --map "
                    f"FMU_VARIABLE=TWIN_PORT (twin ports: in {', '.join(p for p in ports if '[' not in p)}, "
                    f"sensor.calibrated[i], sensor.raw[i], sensor.white_8bit[i]; out {', '.join(DRIVE_PORTS)})")
    for port in pairs[0]:
        if outs[by_port[port].variable].type not in REAL_TYPES + INTEGER_TYPES:
            raise _fail(path, f"output {by_port[port].variable} is of type {outs[by_port[port].variable].type}, "
                        "not a number")
    drive = {p: by_port[p] for p in pairs[0]}
    for link in [*sense.values(), *drive.values()]:
        check_unit(path, md, ins.get(link.variable) or outs[link.variable], link, port_unit(link.port))
    return sense, drive, {n: _start(ins[n], start) for n, start in left.items()}


def _start(variable, text: str):
    """An input's declared start value as a number (or a flag, or the text of a string)."""
    if variable.type == "Boolean":
        return str(text).lower() in ("true", "1")
    try:
        return int(text) if variable.type in INTEGER_TYPES else float(text)
    except (TypeError, ValueError):
        return text


def _listing(ins: dict, outs: dict) -> str:
    return (f"its inputs: {', '.join(ins) or 'none'}; its outputs: {', '.join(outs) or 'none'}")


class ControllerFmu:
    """A controller FMU, checked and mapped (nothing runs until :meth:`start`).

    Args:
      path: the .fmu file.
      mapping: {FMU variable: twin port, or a :class:`Link` with sign, scale and offset} that override the
        mapping by name.
      count: sensors of the twin's array (which sensor ports exist).
      control_dt: the twin's control period [s], the sample time if the FMU's DefaultExperiment has no stepSize.
      parameters: {parameter: value as text} set before the FMU's initialisation (``--controller-param``).
      sample_time: the step [s] to run it at instead (a multi-model's co-simulation step).

    Attributes: ``sense`` {FMU input: twin port} and ``drive`` {twin drive port: FMU output}, with their relations
    in ``inputs`` and ``outputs`` (:class:`Link`, in the order they cross the wall; outputs left, right);
    ``left_at_start`` {FMU input no port feeds: its start value}; ``parameters`` [(name, typed value)].
    """

    def __init__(self, path: str, mapping: Mapping[str, str | Link] | None = None, count: int = 8,
                 control_dt: float = 0.005, parameters: Mapping[str, str] | None = None,
                 sample_time: float | None = None):
        self.path = path
        self.md = read_controller(path)
        self.fmi_version = int(str(self.md.fmiVersion)[0])
        links = {n: k if isinstance(k, Link) else Link(n, k) for n, k in (mapping or {}).items()}
        sense, drive, self.left_at_start = resolve_mapping(path, self.md, links, count)
        self.parameters = resolve_params(path, self.md, dict(parameters or {}))
        self.inputs = list(sense.values())
        self.outputs = [drive[p] for p in sorted(drive)]  # *_left before *_right
        self.sense = {k.variable: k.port for k in self.inputs}
        self.drive = {p: k.variable for p, k in drive.items()}
        self.actuation = next(kind for pair, kind in ACTUATION.items() if pair[0] in drive)
        for name, value in self.left_at_start.items():
            log.info("controller FMU %s: its input %s keeps its start value %s (no twin port maps to it)", path, name,
                     value)
        step = self.md.defaultExperiment.stepSize if self.md.defaultExperiment else None
        self.sample_time = float(sample_time or (step if step not in (None, "") else control_dt))
        if not (self.sample_time > 0 and self.sample_time <= 1.0):
            raise _fail(path, f"its sample time {self.sample_time:g} s is outside (0, 1] s")
        self._host: ControllerHost | None = None
        self._finalizer = None

    def describe(self) -> dict:
        """What runs, for --json: the FMU, its version, sample time and the mapping used."""
        return {"fmu": os.path.abspath(self.path), "fmi_version": self.fmi_version, "sample_time_s": self.sample_time,
                "model_name": self.md.modelName, "inputs": {k.variable: k.expression for k in self.inputs},
                "outputs": {k.variable: k.expression for k in self.outputs}, "actuation": self.actuation,
                "left_at_start": dict(self.left_at_start), "parameters": dict(self.parameters),
                "first_step_inputs": {k.variable: k.at_start for k in self.inputs if k.at_start is not None}}

    def start(self) -> WalledController:
        """One lap: a fresh instance of the FMU, instantiated and initialised at time 0 in the controller's own
        process (started with the first lap, and again after a lap that ended in a fault), meanwhile the twin goes
        on; the returned controller steps it (use it in a ``with`` block)."""
        if self._host is None or not self._host.alive:
            self._host = ControllerHost(self)
            if self._finalizer is not None:
                self._finalizer.detach()
            self._finalizer = weakref.finalize(self, self._host.close)  # also at the interpreter's exit
        return WalledController(self._host)

    def close(self) -> None:
        """End the controller's process (it frees the FMU) and remove its files; a later lap starts it again."""
        if self._finalizer is not None:
            self._finalizer()
        self._host = self._finalizer = None
