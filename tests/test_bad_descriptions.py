"""Bad robot descriptions and description flags (``--robot``, ``convert``, ``--xacro-arg``, ``--package``,
``--sensor-mount``, ``--sensor-link``), one row each: exit 2, one ``error: …`` line naming the input and the fault,
no traceback, in time (:mod:`bad_input`). A new flag or fault of this family gets its bad inputs by adding a row."""

from __future__ import annotations

import uuid

import pytest

from bad_input import BadFiles, check_bad_input, check_in_fresh_process
from conftest import minimal_urdf

XACRO = 'xmlns:xacro="http://www.ros.org/wiki/xacro"'
NOWHERE = f"pkg_{uuid.uuid4().hex[:10]}"  # a package no folder on this machine claims
MOUNT_OK = "--sensor-mount base:0.05,0,-0.015"  # minimal_urdf's array 5 mm above the floor, 50 mm ahead of the axle


def _with(old: str, new: str, extra: str = "") -> str:
    text = minimal_urdf(extra)
    assert old in text
    return text.replace(old, new, 1)


@pytest.fixture(scope="module")
def files(tmp_path_factory) -> BadFiles:
    f = BadFiles(tmp_path_factory.mktemp("bad_descriptions"))
    f.put("mini.urdf", minimal_urdf())
    f.put("urdf_garbage.urdf", "<robot><link name='a'>")
    f.put("urdf_cycle.urdf", """<robot name="c"><link name="a"/><link name="b"/>
        <joint name="j" type="fixed"><parent link="a"/><child link="a"/></joint></robot>""")
    mesh_robot = minimal_urdf().replace('<cylinder radius="0.02" length="0.01"/>', '<mesh filename="wheel.stl"/>')
    f.put("wheel.stl", b"solid garbage\n this is not an STL at all")
    f.put("urdf_garbage_mesh.urdf", mesh_robot)
    f.put("urdf_tiny_wheel.urdf", minimal_urdf().replace('radius="0.02"', 'radius="1e-9"'))
    f.put("big/robot.urdf", mesh_robot)
    with open(f.folder / "big" / "wheel.stl", "wb") as out:
        out.truncate(65_000_000)  # a sparse 65 MB file: refused by its size, never read
    # numbers: one rule for every number the converter reads, naming link or joint, element and attribute
    f.put("nan_rpy.urdf", _with('<origin xyz="0.05 0 -0.015"/>', '<origin xyz="0.05 0 -0.015" rpy="nan 0 0"/>'))
    f.put("nan_wheel.urdf", _with('<origin xyz="0 0.05 0"', '<origin xyz="0 nan 0"'))
    f.put("inf_wheel.urdf", _with('<origin xyz="0 0.05 0"', '<origin xyz="0 inf 0"'))
    f.put("huge_mass.urdf", _with('<mass value="0.3"/>', '<mass value="1e308"/>'))
    f.put("negative_mass.urdf", _with('<mass value="0.3"/>', '<mass value="-0.3"/>'))
    f.put("two_numbers.urdf", _with('<origin xyz="0 0.05 0"', '<origin xyz="0 0.05"'))
    f.put("word.urdf", _with('<origin xyz="0 0.05 0"', '<origin xyz="0 five 0"'))
    f.put("km_box.urdf", minimal_urdf("""<joint name="j" type="fixed"><parent link="base"/><child link="lid"/></joint>
        <link name="lid"><visual><geometry><box size="1000 0.1 0.1"/></geometry></visual></link>"""))
    f.put("zero_scale.urdf", mesh_robot.replace('<mesh filename="wheel.stl"/>', '<mesh filename="wheel.stl" scale="0 1 1"/>'))
    f.put("negative_damping.urdf", _with('<axis xyz="0 0 1"/></joint>', '<axis xyz="0 0 1"/><dynamics damping="-1"/></joint>'))
    f.put("bright.urdf", minimal_urdf('<material name="m"><color rgba="2 0 0 1"/></material>'))
    # packages
    f.put("no_package.urdf", minimal_urdf(f"""<joint name="j" type="fixed"><parent link="base"/><child link="m"/></joint>
        <link name="m"><visual><geometry><mesh filename="package://{NOWHERE}/meshes/m.stl"/></geometry></visual></link>"""))
    f.put("find.urdf.xacro", minimal_urdf(f'<xacro:include filename="$(find {NOWHERE})/urdf/parts.xacro"/>')
          .replace('<robot name="mini">', f'<robot name="mini" {XACRO}>'))
    # xacro: arguments, and a program that would take all memory
    f.put("mini.urdf.xacro", minimal_urdf().replace('<robot name="mini">', f'<robot name="mini" {XACRO}>'))
    f.put("bomb.urdf.xacro", minimal_urdf('<xacro:property name="big" value="${\'x\' * (10**10)}"/><link name="${big}"/>')
          .replace('<robot name="mini">', f'<robot name="mini" {XACRO}>'))
    # the line array: a link named as a sensor mount, behind the axle
    f.put("rear_sensor.urdf", minimal_urdf("""<joint name="s" type="fixed"><parent link="base"/><child link="rear"/>
        <origin xyz="-0.03 0 -0.015"/></joint><link name="rear"/>"""))
    return f


# (command line with {name} placeholders, text the one error line must contain)
CASES = [
    ("lap --robot {dir}", "{dir}: is a folder, not a regular file"),
    ("convert {dir} -o {dir}/w.xml", "{dir}: is a folder, not a regular file"),
    ("convert {missing_dir}/r.urdf -o {dir}/w.xml", "no such robot description"),
    ("lap --robot {urdf_garbage.urdf}", "well-formed"),
    ("lap --robot {urdf_cycle.urdf}", "{urdf_cycle.urdf}"),
    ("lap --robot {urdf_garbage_mesh.urdf}", "wheel.stl"),
    ("lap --robot {urdf_tiny_wheel.urdf}", "wheel radius"),
    ("lap --robot {big/robot.urdf}", "MB limit"),
    # numbers
    ("lap --robot {nan_rpy.urdf}", 'link base, collision 0 <origin rpy="nan 0 0">: rpy holds nan, not a finite number'),
    ("convert {nan_rpy.urdf} -o {dir}/w.xml", 'link base, collision 0 <origin rpy="nan 0 0">'),
    ("lap --robot {nan_wheel.urdf}", 'joint w0 <origin xyz="0 nan 0">: xyz holds nan, not a finite number'),
    ("lap --robot {inf_wheel.urdf}", 'joint w0 <origin xyz="0 inf 0">: xyz holds inf, not a finite number'),
    ("lap --robot {huge_mass.urdf}", 'link base, inertial <mass value="1e308">: value holds 1e+308 kg, outside 0 … 10000 kg'),
    ("lap --robot {negative_mass.urdf}", "value holds -0.3 kg, outside 0 … 10000 kg"),
    ("lap --robot {two_numbers.urdf}", 'joint w0 <origin xyz="0 0.05">: xyz must be 3 numbers, got 2'),
    ("lap --robot {word.urdf}", "xyz holds 'five', not a number"),
    ("lap --robot {km_box.urdf}", 'link lid, visual 0 <box size="1000 0.1 0.1">: size holds 1000 m, outside 0 … 100 m'),
    ("lap --robot {zero_scale.urdf}", "scale holds 0, outside -1000 … 1000, not 0"),
    ("lap --robot {negative_damping.urdf}", 'joint w0 <dynamics damping="-1">: damping holds -1 N·m·s/rad'),
    ("lap --robot {bright.urdf}", 'material m <color rgba="2 0 0 1">: rgba holds 2, outside 0 … 1'),
    # packages: named, with the description, the folders searched and the flag
    ("lap --robot {no_package.urdf}", f"{{no_package.urdf}}: package://{NOWHERE}/meshes/m.stl: package '{NOWHERE}' not "
                                      "found: no package.xml naming it"),
    ("convert {no_package.urdf} -o {dir}/w.xml", f"give --package {NOWHERE}=DIR"),
    ("lap --robot {find.urdf.xacro}", f"{{find.urdf.xacro}}: $(find {NOWHERE}): package '{NOWHERE}' not found"),
    ("lap --robot {mini.urdf} --package x", "--package 'x': expected NAME=DIR"),
    # xacro
    ("lap --robot {mini.urdf.xacro} --xacro-arg prefix", "--xacro-arg 'prefix': expected NAME=VALUE, e.g."),
    ("lap --robot {mini.urdf} --xacro-arg a=1", "--xacro-arg is given but the description is not xacro"),
    ("lap --robot {bomb.urdf.xacro}", "{bomb.urdf.xacro}: xacro needs more than 1024 MB of memory to expand it"),
    # the line array: one check for every command and every way of placing it
    ("convert {mini.urdf} -o {dir}/w.xml --sensor-mount base:-0.03,0,-0.015", "30.0 mm behind the axle"),
    ("lap --robot {mini.urdf} --sensor-mount base:-0.03,0,-0.015", "30.0 mm behind the axle"),
    ("convert {mini.urdf} -o {dir}/w.xml --sensor-mount base:0.05,0,0.01", "30.0 mm above the floor"),
    ("lap --robot {mini.urdf} --sensor-mount base:0.05,0,0.01", "30.0 mm above the floor"),
    ("convert {mini.urdf} -o {dir}/w.xml --sensor-mount base:0.05,0,-0.03", "10.0 mm below the floor"),
    ("convert {rear_sensor.urdf} -o {dir}/w.xml --sensor-link rear", "30.0 mm behind the axle"),
    ("lap --robot {rear_sensor.urdf} --sensor-link rear", "30.0 mm behind the axle"),
    ("convert {mini.urdf} -o {dir}/w.xml", "0.0 mm ahead of the axle"),
    ("lap --robot {mini.urdf} --sensor-mount base:0.05,0,0.01 --set cad.S=0.06", "30.0 mm above the floor"),
    ("lap --robot {mini.urdf} --sensor-mount nope:0,0,0", "sensor mount link 'nope' not in the URDF"),
]


@pytest.mark.parametrize("row, needle", CASES, ids=[c[0] for c in CASES])
def test_bad_description_is_one_line_and_exit_2(files, row, needle, capsys):
    check_bad_input(row, needle, files, capsys)


def test_a_missing_package_is_named_in_full(files, capsys):
    """The package, the description, the folders searched and the flag; no class name, nothing cut off."""
    for row in ("lap --robot {no_package.urdf}", "lap --robot {find.urdf.xacro}"):
        line = check_bad_input(row, NOWHERE, files, capsys)
        assert "<class" not in line and "MjcfError" not in line, line
        assert str(files.folder) in line and "ROS_PACKAGE_PATH" in line, line
        assert line.endswith(f"give --package {NOWHERE}=DIR"), line


def test_a_good_mount_converts(files, capsys):
    """The rows above fail for their mount, not for the robot: the same robot with its array in front converts."""
    from twin.cli.main import main

    assert main(["convert", files["mini.urdf"], "-o", str(files.folder / "ok.xml"), *MOUNT_OK.split()]) == 0
    capsys.readouterr()


def test_a_fresh_process_never_shows_a_traceback(files):
    check_in_fresh_process(["lap", "--robot", files["urdf_cycle.urdf"]])
    check_in_fresh_process(["convert", files["bomb.urdf.xacro"], "-o", str(files.folder / "w.xml")])
