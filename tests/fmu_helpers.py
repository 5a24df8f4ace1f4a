"""FMUs for the tests: a controller FMU built from C (tests/fmu/controller.c, the firmware's control law) with gcc
against fmpy's FMI 2 headers, and broken FMUs for the error paths. Not a test module."""

from __future__ import annotations

import os
import shutil
import subprocess
import tempfile
import zipfile

import fmpy

from twin.core.digital_twin import DigitalTwin

HERE = os.path.dirname(os.path.abspath(__file__))
CSRC = os.path.join(HERE, "..", "twin", "csrc")
GUID = "{0d3f2a43-0000-4000-8000-7e57c0a7f00d}"
PARAM_ORDER = ("count", "pitch_m", "sensor_distance_m", "v_max", "k_b", "k_p", "k_i", "k_d", "dt_s", "wheel_radius_m",
               "half_track_m", "wheel_speed_max", "accel_max", "integral_limit", "cal_duty", "cal_sweep_rad",
               "cal_sweeps")  # lf_params


def have_compiler() -> bool:
    return shutil.which("gcc") is not None


def _xml(names: tuple[str, str, str], step: float | None, fmi_version: str = "2.0", kinds: str = "cs",
         kp: float = 0.0) -> str:
    inp, left, right = names
    cs = '<CoSimulation modelIdentifier="controller" canHandleVariableCommunicationStepSize="true"/>'
    me = '<ModelExchange modelIdentifier="controller"/>'
    kind = {"cs": cs, "me": me}[kinds]
    experiment = f'<DefaultExperiment stepSize="{step!r}"/>' if step else ""
    return f"""<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="{fmi_version}" modelName="controller" guid="{GUID}" variableNamingConvention="structured">
  {kind}
  {experiment}
  <ModelVariables>
    <ScalarVariable name="{inp}" valueReference="0" causality="input" variability="continuous"><Real start="0"/></ScalarVariable>
    <ScalarVariable name="{left}" valueReference="1" causality="output" variability="continuous"><Real/></ScalarVariable>
    <ScalarVariable name="{right}" valueReference="2" causality="output" variability="continuous"><Real/></ScalarVariable>
    <ScalarVariable name="kp" valueReference="3" causality="parameter" variability="tunable"><Real start="{kp!r}"/></ScalarVariable>
  </ModelVariables>
  <ModelStructure>
    <Outputs><Unknown index="2"/><Unknown index="3"/></Outputs>
  </ModelStructure>
</fmiModelDescription>
"""


def _zip(folder: str, path: str) -> str:
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as z:
        for here, _, files in os.walk(folder):
            for f in files:
                full = os.path.join(here, f)
                z.write(full, os.path.relpath(full, folder).replace(os.sep, "/"))
    return path


FAULTS = {"hang": 1, "segfault": 2, "exit": 3, "nan": 4}  # tests/fmu/controller.c's CTL_FAULT


def build_controller(twin: DigitalTwin, path: str, position_input: bool = False, speed_outputs: bool = False,
                     names: tuple[str, str, str] | None = None, step: float | None = None, fault: str | None = None,
                     fault_tick: int = 100) -> str:
    """A controller FMU with the firmware's control law and the twin's gains, at ``path``; with ``fault`` (a key of
    :data:`FAULTS`) its step number ``fault_tick`` hangs, segfaults, calls exit(0) or outputs NaN."""
    p = twin.control_params()
    supply = twin.physics().supply_voltage
    names = names or ("line_position" if position_input else "line_angle",
                      *(("wheel_speed_setpoint_left", "wheel_speed_setpoint_right") if speed_outputs
                        else ("voltage_left", "voltage_right")))
    with tempfile.TemporaryDirectory() as work:
        values = ", ".join(repr(getattr(p, f)) for f in PARAM_ORDER)
        with open(os.path.join(work, "controller_config.h"), "w") as f:
            f.write(f'#define CTL_GUID "{GUID}"\n#define CTL_PARAMS {{{values}}}\n#define CTL_SUPPLY_VOLTAGE {supply!r}\n'
                    + ("#define CTL_INPUT_POSITION\n" if position_input else "")
                    + ("#define CTL_OUTPUT_SPEEDS\n" if speed_outputs else "")
                    + (f"#define CTL_FAULT {FAULTS[fault]}\n#define CTL_FAULT_TICK {fault_tick}\n" if fault else ""))
        tree = os.path.join(work, "fmu")
        os.makedirs(os.path.join(tree, "binaries", "linux64"))
        subprocess.run(["gcc", "-std=c99", "-O2", "-ffp-contract=off", "-fPIC", "-shared", f"-I{work}",
                        f"-I{os.path.join(os.path.dirname(fmpy.__file__), 'c-code')}", f"-I{CSRC}",
                        os.path.join(HERE, "fmu", "controller.c"), os.path.join(HERE, "fmu", "fmi2_common.c"),
                        os.path.join(CSRC, "firmware", "line_follower.c"),
                        "-o", os.path.join(tree, "binaries", "linux64", "controller.so"), "-lm"], check=True)
        with open(os.path.join(tree, "modelDescription.xml"), "w") as f:
            f.write(_xml(names, step, kp=p.k_p))
        return _zip(tree, path)


LFR_GUID = "{adb6056a-0f07-4642-8ed3-b77b0de5f196}"  # LFRController_Standalone.fmu's, as lfr_controller.c has it
# (name, causality, variability, start) in value-reference order, as that FMU's modelDescription.xml declares them
LFR_VARIABLES = (("backwardRotate", "parameter", "fixed", 1.0), ("forwardRotate", "parameter", "fixed", 5.0),
                 ("forwardSpeed", "parameter", "fixed", 4.0), ("lfLeftVal", "input", "discrete", 0.0),
                 ("lfRightVal", "input", "discrete", 0.0), ("servoLeftVal", "output", "discrete", 0.0),
                 ("servoRightVal", "output", "discrete", 0.0), ("total_energy_used", "input", "discrete", 0.0))


def build_lfr_controller(path: str, units: dict[str, str] | None = None) -> str:
    """A controller FMU of the INTO-CPS kind (tests/fmu/lfr_controller.c: the LFRController's variables and bang-bang
    law; its parameters 0 unless set) at ``path``; ``units`` {variable: unit} declares units it does not have."""
    units = units or {}
    rows = []
    for vr, (name, causality, variability, start) in enumerate(LFR_VARIABLES):
        initial = {"parameter": ' initial="exact"', "output": ' initial="approx"'}.get(causality, "")
        unit = f' unit="{units[name]}"' if name in units else ""
        rows.append(f'    <ScalarVariable name="{name}" valueReference="{vr}" causality="{causality}" '
                    f'variability="{variability}"{initial}><Real start="{start!r}"{unit}/></ScalarVariable>')
    outputs = "".join(f'<Unknown index="{i + 1}" dependencies=""/>' for i, v in enumerate(LFR_VARIABLES)
                      if v[1] == "output")
    xml = f"""<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="2.0" modelName="LFRController" guid="{LFR_GUID}" variableNamingConvention="flat">
  <CoSimulation modelIdentifier="LFRController" canHandleVariableCommunicationStepSize="true"/>
  <ModelVariables>
{chr(10).join(rows)}
  </ModelVariables>
  <ModelStructure><Outputs>{outputs}</Outputs><InitialUnknowns>{outputs}</InitialUnknowns></ModelStructure>
</fmiModelDescription>
"""
    with tempfile.TemporaryDirectory() as tree:
        os.makedirs(os.path.join(tree, "binaries", "linux64"))
        subprocess.run(["gcc", "-std=c99", "-O2", "-fPIC", "-shared",
                        f"-I{os.path.join(os.path.dirname(fmpy.__file__), 'c-code')}",
                        os.path.join(HERE, "fmu", "lfr_controller.c"), os.path.join(HERE, "fmu", "fmi2_common.c"),
                        "-o", os.path.join(tree, "binaries", "linux64", "LFRController.so")], check=True)
        with open(os.path.join(tree, "modelDescription.xml"), "w") as f:
            f.write(xml)
        return _zip(tree, path)


def broken_fmu(path: str, what: str) -> str:
    """An FMU that the twin must refuse: ``not-zip``, ``no-binary`` (Windows only), ``model-exchange`` or ``fmi1``."""
    if what == "not-zip":
        with open(path, "w") as f:
            f.write("this is not an FMU\n")
        return path
    with tempfile.TemporaryDirectory() as tree:
        names = ("line_angle", "voltage_left", "voltage_right")
        xml = {"no-binary": _xml(names, None), "model-exchange": _xml(names, None, kinds="me"),
               "fmi1": _xml(names, None, fmi_version="1.0")}[what]
        with open(os.path.join(tree, "modelDescription.xml"), "w") as f:
            f.write(xml)
        folder = os.path.join(tree, "binaries", "win64" if what == "no-binary" else "linux64")
        os.makedirs(folder)
        with open(os.path.join(folder, "controller.dll" if what == "no-binary" else "controller.so"), "wb") as f:
            f.write(b"\0")
        return _zip(tree, path)


def controller_processes(pid: int) -> list[int]:
    """The controller FMU processes (``python -m twin.fmi.host``) whose parent is ``pid`` and that still run."""
    out = []
    for entry in filter(str.isdigit, os.listdir("/proc")):
        try:
            with open(f"/proc/{entry}/stat") as f:
                fields = f.read().rsplit(")", 1)[1].split()
            with open(f"/proc/{entry}/cmdline", "rb") as f:
                cmdline = f.read()
        except OSError:
            continue
        if int(fields[1]) == pid and fields[0] != "Z" and b"twin.fmi.host" in cmdline:
            out.append(int(entry))
    return out


# --- running FMUs with fmpy -----------------------------------------------------------------------------------------

class Slave:
    """One instance of an FMU through fmpy's FMU2Slave / FMU3Slave, with variables by name."""

    def __init__(self, path: str, name: str = "twin", unzipped: str | None = None):
        from fmpy import extract, read_model_description
        from fmpy.fmi2 import FMU2Slave
        from fmpy.fmi3 import FMU3Slave

        self.md = read_model_description(path)
        self.var = {v.name: v for v in self.md.modelVariables}
        self.version = int(self.md.fmiVersion[0])
        self.dir = unzipped or extract(path)
        cls, token = (FMU2Slave, self.md.guid) if self.version == 2 else (FMU3Slave, self.md.instantiationToken)
        self.fmu = cls(guid=token, unzipDirectory=self.dir, modelIdentifier=self.md.coSimulation.modelIdentifier,
                       instanceName=name)
        self.fmu.instantiate()
        self.time = 0.0

    def initialise(self, values: dict | None = None, start: float = 0.0) -> "Slave":
        if self.version == 2:
            self.fmu.setupExperiment(startTime=start)
            self.fmu.enterInitializationMode()
        else:
            self.fmu.enterInitializationMode(startTime=start)
        self.set(values or {})
        self.fmu.exitInitializationMode()
        self.time = start
        return self

    def set(self, values: dict) -> None:
        for name, value in values.items():
            v = self.var[name]
            setter = {"Real": "setReal", "Float64": "setFloat64", "Integer": "setInteger", "Int32": "setInt32",
                      "UInt64": "setUInt64", "Boolean": "setBoolean"}[v.type]
            getattr(self.fmu, setter)([v.valueReference], [value])

    def get(self, name: str):
        v = self.var[name]
        getter = {"Real": "getReal", "Float64": "getFloat64", "Integer": "getInteger", "Int32": "getInt32",
                  "UInt64": "getUInt64", "Boolean": "getBoolean"}[v.type]
        return getattr(self.fmu, getter)([v.valueReference])[0]

    def step(self, h: float) -> None:
        self.fmu.doStep(currentCommunicationPoint=self.time, communicationStepSize=h)
        self.time += h

    def run_until(self, stop: float, h: float) -> None:
        while self.time < stop - 1e-9:
            self.step(h)

    def reset(self) -> None:
        self.fmu.reset()
        self.time = 0.0

    def close(self) -> None:
        self.fmu.terminate()
        self.fmu.freeInstance()


def container(plant: str, controller: str, path: str, step: float, stop: float) -> str:
    """fmpy's container FMU (its own co-simulation master, in C): the plant's line angle into the controller, the
    controller's voltages into the plant; the plant's lap outputs exposed."""
    import copy
    import pathlib

    from fmpy import read_model_description
    from fmpy.container_fmu import Configuration
    from fmpy.container_fmu.cli import create_container_fmu
    from fmpy.container_fmu.config import Component, Connection
    from fmpy.model_description import CoSimulation, DefaultExperiment, ModelDescription, ModelVariable, Unknown

    def f64(v):  # the container names connection types as FMI 3 does
        v = copy.copy(v)
        v.type = "Float64"
        return v

    mp, mc = read_model_description(plant), read_model_description(controller)
    p, c = Component("plant", pathlib.Path(plant), mp), Component("controller", pathlib.Path(controller), mc)
    pv, cv = {v.name: v for v in mp.modelVariables}, {v.name: v for v in mc.modelVariables}
    md = ModelDescription(fmiVersion="3.0", modelName="loop", instantiationToken="{00c0ffee-0000-4000-8000-000000000001}",
                          coSimulation=CoSimulation(modelIdentifier="container_fmu", fixedInternalStepSize=step),
                          defaultExperiment=DefaultExperiment(startTime="0", stopTime=repr(stop), stepSize=repr(step)))
    md.modelVariables.append(ModelVariable(name="time", valueReference=0, type="Float64", causality="independent",
                                           variability="continuous"))
    mappings = {}
    for name, type_ in (("lap_time", "Float64"), ("lap_status", "Int32"), ("lap_distance", "Float64")):
        out = ModelVariable(name=name, valueReference=len(md.modelVariables), type=type_, causality="output",
                            variability="continuous" if type_ == "Float64" else "discrete")
        md.modelVariables.append(out)
        md.outputs.append(Unknown(variable=out))
        md.initialUnknowns.append(Unknown(variable=out))
        mappings[out] = [(p, pv[name])]
    connections = [Connection(p, [f64(pv["line_angle"])], c, [f64(cv["line_angle"])]),
                   Connection(c, [f64(cv["voltage_left"]), f64(cv["voltage_right"])], p,
                              [f64(pv["voltage_left"]), f64(pv["voltage_right"])])]
    config = Configuration(parallelDoStep=False, modelDescription=md, components=[p, c], connections=connections,
                           variableMappings=mappings)
    with tempfile.TemporaryDirectory() as work:
        create_container_fmu(config, pathlib.Path(work), pathlib.Path(path))
    return path
