"""``lap --multi-model FILE.mm.json --stand-in FILE.json``: an INTO-CPS multi-model run against the twin, which stands
in for its body and sensor blocks (examples/intocps-line-follower.json) while its controller FMU drives. The
project here is laid out as the INTO-CPS example's (github.com/INTO-CPS-Association/example-line_follower_robot):
its controller FMU in ``FMUs/`` (built from C, tests/fmu/lfr_controller.c), the multi-model
``Multi-models/lfr-non3d/lfr-non3d.mm.json`` with that file's FMUs, connections and parameters. Bad multi-models
are one line and exit 2."""

from __future__ import annotations

import copy
import json
import os
import subprocess
import sys

import pytest

pytest.importorskip("fmpy")

from fmu_helpers import build_controller, build_lfr_controller, have_compiler  # noqa: E402
from twin.cli import main as front_door  # noqa: E402
from twin.core import DigitalTwin  # noqa: E402

pytestmark = pytest.mark.skipif(not have_compiler(), reason="the controller FMUs are compiled from C (gcc)")
ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
STAND_IN = os.path.join(ROOT, "examples", "intocps-line-follower.json")
B, S1, S2, C = "{bodyFMU}.body", "{sensor1FMU}.sensor1", "{sensor2FMU}.sensor2", "{controllerFMU}.controller"
# the INTO-CPS example's Multi-models/lfr-non3d/lfr-non3d.mm.json, as data
LFR_NON3D = {
    "fmus": {"{controllerFMU}": "LFRController_Standalone.fmu", "{sensor1FMU}": "Sensor_Block_01.fmu",
             "{sensor2FMU}": "Sensor_Block_02.fmu", "{bodyFMU}": "Body_Block.fmu"},
    "connections": {
        **{f"{B}.robot_{q}": [f"{S1}.robot_{q}", f"{S2}.robot_{q}"] for q in ("x", "y", "z", "theta")},
        f"{B}.total_energy_used": [f"{C}.total_energy_used"],
        f"{S1}.lf_1_sensor_reading": [f"{C}.lfLeftVal"], f"{S2}.lf_1_sensor_reading": [f"{C}.lfRightVal"],
        f"{C}.servoRightVal": [f"{B}.servo_right_input"], f"{C}.servoLeftVal": [f"{B}.servo_left_input"]},
    "parameters": {f"{S1}.lf_position_x": 0.01, f"{S1}.lf_position_y": 0.065, f"{S2}.lf_position_x": -0.01,
                   f"{S2}.lf_position_y": 0.065, f"{C}.forwardSpeed": 0.4, f"{C}.forwardRotate": 0.5,
                   f"{C}.backwardRotate": 0.1}}
SAME_BY_HAND = ["--map", "lfLeftVal=sensor.white_8bit[5]", "--map", "lfRightVal=sensor.white_8bit[4]",
                "--map", "servoLeftVal=wheel_duty_left", "--map", "servoRightVal=-1*wheel_duty_right",
                "--controller-param", "forwardSpeed=0.4", "--controller-param", "forwardRotate=0.5",
                "--controller-param", "backwardRotate=0.1"]

PLACED_BY_HAND = ["--set", "sensor.count=2", "--set", "sensor.pitch=0.02", "--set", "cad.S=0.065",
                  "--map", "lfLeftVal=sensor.white_8bit[2]", "--map", "lfRightVal=sensor.white_8bit[1]",
                  *SAME_BY_HAND[4:]]


@pytest.fixture(scope="module")
def project(tmp_path_factory):
    root = tmp_path_factory.mktemp("intocps")
    (root / "FMUs").mkdir()
    (root / "Multi-models" / "lfr-non3d").mkdir(parents=True)
    build_lfr_controller(str(root / "FMUs" / "LFRController_Standalone.fmu"))
    build_controller(DigitalTwin(), str(root / "FMUs" / "odd.fmu"), names=("x", "y1", "y2"))
    return root


def multi_model(project, doc: dict, name: str = "lfr-non3d", coe: dict | None = None) -> str:
    folder = project / "Multi-models" / name
    folder.mkdir(exist_ok=True)
    (folder / f"{name}.mm.json").write_text(json.dumps(doc))
    if coe is not None:
        (folder / f"{name}.coe.json").write_text(json.dumps(coe))
    return str(folder / f"{name}.mm.json")


def lap_json(argv: list[str]) -> tuple[dict, str]:
    done = subprocess.run([sys.executable, "-m", "twin.run", "lap", *argv, "--json"], capture_output=True, text=True,
                          cwd=ROOT, timeout=600)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout), done.stderr


def test_the_intocps_multi_model_laps_with_the_twin_standing_in(project):
    mm = multi_model(project, LFR_NON3D)
    doc, err = lap_json(["--multi-model", mm, "--stand-in", STAND_IN])
    assert doc["completed"] and doc["multi_model"]["controller"] == C
    c = doc["controller"]
    assert c["fmu"] == str(project / "FMUs" / "LFRController_Standalone.fmu")  # found in the project's FMUs folder
    assert c["parameters"] == {"forwardSpeed": 0.4, "forwardRotate": 0.5, "backwardRotate": 0.1}
    assert c["outputs"] == {"servoLeftVal": "wheel_duty_left", "servoRightVal": "-1*wheel_duty_right"}
    # the sensors where the multi-model puts them: lf_position_x +0.01 m (right) and -0.01 m (left), 0.065 m ahead,
    # so two sensors 0.02 m apart, 0.065 m ahead; sensor 1 (leftmost) is sensor2's, sensor 2 is sensor1's
    assert doc["multi_model"]["twin_values"] == {"sensor.count": 2, "sensor.pitch": pytest.approx(0.02, abs=1e-12),
                                                 "cad.S": pytest.approx(0.065, abs=1e-12)}
    assert c["inputs"] == {"lfLeftVal": "sensor.white_8bit[2]", "lfRightVal": "sensor.white_8bit[1]",
                           "total_energy_used": "energy_used"}
    assert c["first_step_inputs"] == {"lfLeftVal": 1.0, "lfRightVal": 1.0}  # the sensor blocks' outputs at t = 0
    assert "not used: {bodyFMU}" not in err and "lf_position" not in err.split("not used:")[-1]
    # the same controller, placement, mapping and parameters by hand, without the blocks' first readings: both
    # sensors straddle the line off it, so this bang-bang law keeps its first command (none) and the robot stays
    by_hand, _ = lap_json(["--controller-fmu", c["fmu"], *PLACED_BY_HAND, "--lap-timeout", "2"])
    assert not by_hand["completed"] and by_hand["distance_m"] < 0.01


def test_the_step_of_a_coe_file_beside_it(project):
    mm = multi_model(project, LFR_NON3D, "stepped", coe={"algorithm": {"type": "fixed-step", "size": 0.01}})
    doc, _ = lap_json(["--multi-model", mm, "--stand-in", STAND_IN, "--lap-timeout", "1"])
    assert doc["controller"]["sample_time_s"] == 0.01


def test_the_coe_file_that_names_it_in_a_folder_below(project):
    """As the INTO-CPS application keeps them: an experiment's coe file (naming the multi-model) and a run's."""
    mm = multi_model(project, LFR_NON3D, "below")
    folder = project / "Multi-models" / "below"
    (folder / "co-sim-3").mkdir()
    (folder / "co-sim-3" / "coe.json").write_text(json.dumps({"algorithm": {"type": "fixed-step", "size": 0.1}}))
    (folder / "Experiment").mkdir()
    (folder / "Experiment" / "below.coe.json").write_text(json.dumps({
        "multimodel_path": "Multi-models/below/below.mm.json", "algorithm": {"type": "fixed-step", "size": 0.02}}))
    doc, err = lap_json(["--multi-model", mm, "--stand-in", STAND_IN, "--lap-timeout", "1"])
    assert doc["controller"]["sample_time_s"] == 0.02
    assert "Experiment/below.coe.json (names this multi-model" in err and "co-sim-3/coe.json (step 0.1 s)" in err
    doc, _ = lap_json(["--multi-model", mm, "--stand-in", STAND_IN, "--lap-timeout", "1", "--coe",
                       str(folder / "co-sim-3" / "coe.json")])
    assert doc["controller"]["sample_time_s"] == 0.1


def test_a_sweep_with_the_multi_model(project, tmp_path):
    mm = multi_model(project, LFR_NON3D)
    done = subprocess.run([sys.executable, "-m", "twin.run", "sweep", "motion.mu=0.5:1.0:2", "--seeds", "1",
                           "--multi-model", mm, "--stand-in", STAND_IN, "--out-dir", str(tmp_path / "s"), "--json",
                           "--controller-param", "forwardRotate=0.6"],  # over the multi-model's 0.5
                          capture_output=True, text=True, cwd=ROOT, timeout=600)
    assert done.returncode == 0, done.stderr
    doc = json.loads(done.stdout)
    assert [p["completion_rate"] for p in doc["points"]] == [1.0, 1.0]
    assert doc["multi_model"]["controller"] == C and doc["controller"]["inputs"]["lfLeftVal"] == "sensor.white_8bit[2]"
    assert doc["controller"]["parameters"] == {"forwardSpeed": 0.4, "forwardRotate": 0.6, "backwardRotate": 0.1}


def _bad(**changes) -> dict:
    doc = copy.deepcopy(LFR_NON3D)
    for part, (drop, add) in changes.items():
        for key in drop:
            del doc[part][key]
        doc[part].update(add)
    return doc


# the tests' controller with the firmware's law (its outputs depend at once on its input) connected to itself
ODD = {"fmus": {**LFR_NON3D["fmus"], "{c}": "odd.fmu"},
       "connections": {**{k: v for k, v in LFR_NON3D["connections"].items() if "robot_" in k},
                       "{c}.c.y1": ["{c}.c.x"], "{c}.c.y2": [f"{B}.servo_left_input"]},
       "parameters": {k: v for k, v in LFR_NON3D["parameters"].items() if "lf_position" in k}}
BAD = [
    ("unknown-fmu", _bad(connections=([], {"{nope}.n.out": [f"{C}.lfLeftVal"]})), "unknown FMU {nope}"),
    ("no-such-variable", _bad(connections=([f"{S1}.lf_1_sensor_reading"],
                                           {f"{S1}.lf_1_sensor_reading": [f"{C}.lfLeftValue"]})),
     "has no variable 'lfLeftValue'"),
    ("wrong-type", _bad(parameters=([], {f"{C}.forwardSpeed": "fast"})),
     f"parameter {C}.forwardSpeed=fast: forwardSpeed is of type Real; 'fast' is not a finite Real value"),
    ("not-a-parameter", _bad(parameters=([], {f"{C}.lfLeftVal": 3})), "lfLeftVal is of causality input"),
    ("cycle", ODD, "a cycle of algebraic connections: {c}.c.y1 feeds {c}.c.x"),
    ("not-stood-in", _bad(connections=([], {f"{B}.robot_z": [f"{C}.total_energy_used"]})),
     f"cannot be stood in for: {B}.robot_z (connected to {C}) is not in the stand-in file"),
    ("two-controllers", _bad(fmus=([], {"{other}": "odd.fmu"}), parameters=([], {"{other}.o.kp": 1.0})),
     "2 instances remain besides the twin"),
    ("missing-fmu", _bad(fmus=(["{controllerFMU}"], {"{controllerFMU}": "Gone.fmu"})),
     "FMU Gone.fmu ({controllerFMU}.controller) is neither beside it nor in the FMUs folder"),
    ("not-a-multi-model", {"fmus": []}, "not an INTO-CPS multi-model"),
    ("bad-name", _bad(parameters=([], {"forwardSpeed": 1})), "'forwardSpeed' is not {FMU}.instance.variable"),
    ("not-a-row", _bad(parameters=([], {f"{S2}.lf_position_x": -0.02})),
     "cannot be stood in for: the twin's line array is a row of 2 to 16 sensors, evenly spaced across the heading "
     "and centred on it"),
    ("position-unknown", _bad(parameters=([f"{S1}.lf_position_y"], {})),
     f"{S1}.lf_position_y places a sensor, but the multi-model does not set it and its FMU Sensor_Block_01.fmu is "
     "not found"),
    ("position-not-a-number", _bad(parameters=([], {f"{S1}.lf_position_y": "far"})),
     f"parameter {S1}.lf_position_y = 'far': not a number"),
]


@pytest.mark.parametrize("name, doc, needle", BAD, ids=[b[0] for b in BAD])
def test_a_bad_multi_model_is_one_line(project, capsys, name, doc, needle):
    mm = multi_model(project, doc, name)
    code = front_door.main(["lap", "--multi-model", mm, "--stand-in", STAND_IN])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and err.startswith("error: ") and needle in err, err


@pytest.mark.parametrize("argv, needle", [
    (["--multi-model", "x.mm.json"], "--multi-model and --stand-in go together"),
    (["--multi-model", "{mm}", "--stand-in", STAND_IN, "--controller-fmu", "c.fmu"], "leave out --controller-fmu"),
    (["--multi-model", "{mm}", "--stand-in", "{mm}"], "no \"instances\" object"),
    (["--multi-model", "{dir}", "--stand-in", STAND_IN], "is a folder"),
    (["--multi-model", "{stand_in}", "--stand-in", STAND_IN], "not an INTO-CPS multi-model"),
    (["--multi-model", "{mm}", "--stand-in", STAND_IN, "--set", "cad.S=0.05"],
     "--set cad.S: the --stand-in file places the sensors where the multi-model puts them (cad.S=0.065)"),
    (["--multi-model", "{mm}", "--stand-in", "{unplaced}"], "lf_1_sensor_reading=sensor.white_8bit: give the "
     "sensor's index (sensor.white_8bit[i]) or place the instance with \"sensor\""),
    (["--multi-model", "{mm}", "--stand-in", "{early}"], "\"at_start\" must give numbers for variables it maps"),
    (["--coe", "x.coe.json"], "--coe: the co-simulation configuration of a --multi-model; give one"),
    (["--multi-model", "{mm}", "--stand-in", STAND_IN, "--map", "lfLeftVal=line_position"],
     "--map: maps the variables of a --controller-fmu; give one (a --multi-model's mapping is its connections"),
])
def test_bad_multi_model_options_are_one_line(project, capsys, argv, needle):
    mm = multi_model(project, LFR_NON3D)
    with open(STAND_IN) as f:
        stand_in = json.load(f)
    unplaced, early = copy.deepcopy(stand_in), copy.deepcopy(stand_in)
    del unplaced["instances"][S1]["sensor"]
    early["instances"][S1]["at_start"] = {"lf_position_x": 1}
    for name, doc in (("unplaced", unplaced), ("early", early)):
        (project / f"{name}.json").write_text(json.dumps(doc))
    argv = [a.format(mm=mm, dir=str(project), stand_in=STAND_IN, unplaced=project / "unplaced.json",
                     early=project / "early.json") for a in argv]
    code = front_door.main(["lap", *argv])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and needle in err, err
