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


def build_controller(twin: DigitalTwin, path: str, position_input: bool = False, speed_outputs: bool = False,
                     names: tuple[str, str, str] | None = None, step: float | None = None) -> str:
    """A controller FMU with the firmware's control law and the twin's gains, at ``path``."""
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
                    + ("#define CTL_OUTPUT_SPEEDS\n" if speed_outputs else ""))
        tree = os.path.join(work, "fmu")
        os.makedirs(os.path.join(tree, "binaries", "linux64"))
        subprocess.run(["gcc", "-std=c99", "-O2", "-ffp-contract=off", "-fPIC", "-shared", f"-I{work}",
                        f"-I{os.path.join(os.path.dirname(fmpy.__file__), 'c-code')}", f"-I{CSRC}",
                        os.path.join(HERE, "fmu", "controller.c"), os.path.join(CSRC, "firmware", "line_follower.c"),
                        "-o", os.path.join(tree, "binaries", "linux64", "controller.so"), "-lm"], check=True)
        with open(os.path.join(tree, "modelDescription.xml"), "w") as f:
            f.write(_xml(names, step, kp=p.k_p))
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
