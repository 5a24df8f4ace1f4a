"""``package://`` and ``$(find)`` resolved as ROS and yourdfpy resolve them: a ``package.xml`` ``<name>`` names a
package whatever its folder is called; ``--package`` wins, then ROS's own paths, then the folders around the
description; when nothing claims a name, the folder above the description that holds the path, as yourdfpy's own
resolution (``yourdfpy.filename_handler_magic``) finds it. Package names are unique per test, so no folder left on
this machine by another run can claim them."""

from __future__ import annotations

import os
import uuid

import pytest
import trimesh
import yourdfpy

from conftest import THIRD_PARTY_URDF
from mjcf.errors import MjcfError
from mjcf.robot_config import RobotConfig
from mjcf.robot_source import read_description
from mjcf.ros_packages import find_package
from mjcf.urdf_parse import UrdfTree
from mjcf.urdf_to_mjcf import convert


def _package(root, folder: str, name: str, manifest: str | None) -> str:
    """``root/folder/urdf/robot.urdf`` with meshes in ``root/folder/meshes`` referenced as ``package://name/…``,
    and a package.xml naming ``manifest`` (none when None); returns the URDF's path."""
    pkg = root / folder
    (pkg / "urdf").mkdir(parents=True)
    (pkg / "meshes").mkdir()
    trimesh.creation.box([0.16, 0.12, 0.03]).export(pkg / "meshes" / "body.stl")
    trimesh.creation.cylinder(radius=0.033, height=0.018).export(pkg / "meshes" / "wheel.stl")
    if manifest is not None:
        (pkg / "package.xml").write_text(f'<?xml version="1.0"?>\n<package format="3"><name>{manifest}</name></package>\n')
    urdf = pkg / "urdf" / "robot.urdf"
    urdf.write_text(THIRD_PARTY_URDF.replace("package://tb_like/", f"package://{name}/"))
    return str(urdf)


@pytest.fixture
def name() -> str:
    return f"bot_{uuid.uuid4().hex[:10]}"


@pytest.fixture(autouse=True)
def _no_ros(monkeypatch):
    monkeypatch.delenv("ROS_PACKAGE_PATH", raising=False)
    monkeypatch.delenv("AMENT_PREFIX_PATH", raising=False)


def _resolved(urdf: str, fname: str, config: RobotConfig = RobotConfig()) -> tuple[str, list[str]]:
    tree = UrdfTree(urdf, config)
    return tree.resolve(fname), tree.notes


@pytest.mark.parametrize("folder, manifest", [
    ("some_folder", None),  # urdf/ and ../meshes in a folder not named after the package, no package.xml
    ("mybot-main", "{name}"),  # a GitHub zip's folder whose package.xml names the package
])
def test_package_paths_resolve_as_yourdfpy_resolves_them(tmp_path, name, folder, manifest):
    urdf = _package(tmp_path, folder, name, manifest and manifest.format(name=name))
    for mesh in ("body.stl", "wheel.stl"):
        fname = f"package://{name}/meshes/{mesh}"
        ours, notes = _resolved(urdf, fname)
        theirs = yourdfpy.filename_handler_magic(fname, dir=os.path.dirname(urdf))
        assert os.path.isfile(theirs) and os.path.samefile(ours, theirs)
    stand_in = [n for n in notes if "no package.xml or folder claims the name" in n]
    assert bool(stand_in) == (manifest is None), notes  # a guess is said; a package.xml is no guess
    _, info = convert(urdf)  # and the whole robot converts, meshes and all
    assert info.wheel_radius == pytest.approx(0.033)


def test_ros_package_path_and_ament_prefix_path_are_honoured(tmp_path, name, monkeypatch):
    urdf = str(tmp_path / "desc" / "robot.urdf")
    os.makedirs(os.path.dirname(urdf))
    open(urdf, "w").write(THIRD_PARTY_URDF.replace("package://tb_like/", f"package://{name}/"))
    elsewhere = _package(tmp_path / "ws" / "src", "repo/any_name", "unused", name)
    pkg = os.path.dirname(os.path.dirname(elsewhere))
    assert find_package(name, os.path.dirname(urdf)) is None
    monkeypatch.setenv("ROS_PACKAGE_PATH", os.pathsep.join(["/nonexistent", str(tmp_path / "ws" / "src")]))
    assert find_package(name, os.path.dirname(urdf)) == pkg
    assert _resolved(urdf, f"package://{name}/meshes/body.stl")[0] == os.path.join(pkg, "meshes", "body.stl")
    monkeypatch.delenv("ROS_PACKAGE_PATH")
    share = tmp_path / "install" / "share" / name
    share.mkdir(parents=True)
    (share / "package.xml").write_text(f"<package><name>{name}</name></package>")
    monkeypatch.setenv("AMENT_PREFIX_PATH", str(tmp_path / "install"))
    assert find_package(name, os.path.dirname(urdf)) == str(share)


def test_a_claim_wins_over_the_folder_above_and_the_flag_over_both(tmp_path, name, monkeypatch):
    urdf = _package(tmp_path / "here", "some_folder", name, None)  # its meshes above it: a stand-in
    claimed = os.path.dirname(os.path.dirname(_package(tmp_path / "there", "pkg", "other", name)))
    monkeypatch.setenv("ROS_PACKAGE_PATH", str(tmp_path / "there"))
    ours, notes = _resolved(urdf, f"package://{name}/meshes/body.stl")
    assert ours == os.path.join(claimed, "meshes", "body.stl")
    assert not any("claims the name" in n for n in notes), notes
    flag = str(tmp_path / "here" / "some_folder")
    ours, _ = _resolved(urdf, f"package://{name}/meshes/body.stl", RobotConfig(package_dirs=((name, flag),)))
    assert ours == os.path.join(flag, "meshes", "body.stl")


def test_xacro_find_honours_ros_package_path(tmp_path, name, monkeypatch):
    """``$(find)`` runs in xacro's child process, which inherits the environment."""
    elsewhere = _package(tmp_path / "ws", "pkg", "unused", name)
    part = os.path.join(os.path.dirname(elsewhere), "part.xacro")
    open(part, "w").write('<robot xmlns:xacro="http://www.ros.org/wiki/xacro"><link name="from_part"/></robot>')
    desc = tmp_path / "a" / "b" / "c" / "d" / "e" / "desc" / "robot.urdf.xacro"  # beyond the search around it
    desc.parent.mkdir(parents=True)
    desc.write_text(f'<robot name="r" xmlns:xacro="http://www.ros.org/wiki/xacro">'
                    f'<xacro:include filename="$(find {name})/urdf/part.xacro"/></robot>')
    with pytest.raises(MjcfError, match=rf"\$\(find {name}\): package '{name}' not found"):
        read_description(str(desc))
    monkeypatch.setenv("ROS_PACKAGE_PATH", str(tmp_path / "ws"))
    assert b"from_part" in read_description(str(desc)).xml
