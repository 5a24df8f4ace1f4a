"""A robot description as published: a URDF, or a xacro file expanded with the ``xacro`` package; the drive
joints its diff-drive plugin names.

* **Xacro** (``.xacro``, ``.urdf.xacro``, or a ``.urdf`` that uses the xacro namespace) is expanded by the ``xacro``
  package with the user's ``NAME=VALUE`` arguments, in a child process under a memory and time limit
  (:mod:`mjcf.xacro_expand`); its ``$(find PKG)`` is answered by :mod:`mjcf.ros_packages`. A ``.urdf`` with ``${…}``
  or ``$(…)`` left in it is an unexpanded xacro, and is refused with the fix, rather than converted with names like
  ``${ns}wheel_joint``.
* **Numbers**: every number the converter reads is checked where the description is read (:mod:`mjcf.urdf_numbers`).
* **Drive joints**: the joints a Gazebo diff-drive plugin (classic ``libgazebo_ros_diff_drive``: ``leftJoint``,
  ``left_joint``; Gazebo Sim's ``DiffDrive``: ``left_joint``) or a ``ros2_control`` block with a velocity
  command names. yourdfpy drops ``<gazebo>`` and ``<ros2_control>`` elements, so they are read here.
"""

from __future__ import annotations

import dataclasses
import logging
import os
import re
import xml.etree.ElementTree as ET

from lf_common.errors import LineFollowerError
from lf_common.files import read_bytes
from mjcf.errors import MjcfError
from mjcf.urdf_numbers import check_numbers
from mjcf.xacro_expand import expand_xacro

log = logging.getLogger(__name__)

MAX_DESCRIPTION_BYTES = 16_000_000  # a robot description is text: tens of kB; this is junk or a mistake
XACRO_NS = "http://www.ros.org/wiki/xacro"
_UNEXPANDED = re.compile(r"\$\{[^}]*\}|\$\([^)]*\)")


@dataclasses.dataclass(frozen=True)
class Description:
    """A robot description ready to parse.

    Attributes:
      path: the file the user named.
      xml: the URDF text (xacro expanded).
      folder: the folder relative mesh paths are resolved from (the named file's).
      drive_joints: (left, right) joints a diff-drive plugin or ros2_control names, if any.
      notes: what was done to read it, one line each.
    """

    path: str
    xml: bytes
    folder: str
    drive_joints: tuple[str, str] | None
    notes: tuple[str, ...]


def is_xacro_name(path: str) -> bool:
    return path.lower().endswith(".xacro")


def read_description(path: str, xacro_args: tuple[tuple[str, str], ...] = (),
                     package_dirs: tuple[tuple[str, str], ...] = ()) -> Description:
    """The URDF text of ``path`` (expanded if it is xacro) and what it says about its drive wheels.

    Raises:
      MjcfError: missing or unreadable file, xacro that does not expand, a package that cannot be found, or a
        URDF with unexpanded xacro in it; each names the file and the fix.
    """
    try:
        raw = read_bytes(path, MAX_DESCRIPTION_BYTES, "robot description")
    except LineFollowerError as e:
        raise MjcfError(str(e)) from None
    notes: list[str] = []
    folder = os.path.dirname(os.path.abspath(path))
    if is_xacro_name(path) or _uses_xacro(raw):
        xml, chatter = expand_xacro(path, xacro_args, package_dirs, MAX_DESCRIPTION_BYTES)
        for line in chatter:
            log.info("xacro: %s", line)
        notes.append(f"expanded {os.path.basename(path)} with xacro"
                     + (f" ({', '.join(f'{k}={v}' for k, v in xacro_args)})" if xacro_args else ""))
    else:
        if xacro_args:
            raise MjcfError(f"{path}: --xacro-arg is given but the description is not xacro")
        xml = raw
    root = _parse(path, xml)
    _refuse_unexpanded(path, root)
    check_numbers(path, root)
    return Description(os.path.abspath(path), xml, folder, drive_joints(root), tuple(notes))


def _parse(path: str, xml: bytes) -> ET.Element:
    """The description's root element; yourdfpy silently "recovers" broken XML, so it is refused here with the
    parser's line and column."""
    try:
        root = ET.fromstring(xml)
    except ET.ParseError as e:
        raise MjcfError(f"{path}: not a well-formed URDF ({e})") from None
    if root.tag != "robot":
        raise MjcfError(f"{path}: root element is <{root.tag}>, expected <robot>")
    return root


def _uses_xacro(raw: bytes) -> bool:
    """A file that declares the xacro namespace (some packages ship xacro under a .urdf name)."""
    return XACRO_NS.encode() in raw[:4096] or b"<xacro:" in raw


def _refuse_unexpanded(path: str, root: ET.Element) -> None:
    for el in root.iter():
        for name, value in el.attrib.items():
            m = _UNEXPANDED.search(value)
            if m:
                raise MjcfError(f"{path}: <{el.tag} {name}=\"{value}\"> holds unexpanded xacro {m.group(0)!r}; give the "
                                ".xacro (or .urdf.xacro) file itself, with --xacro-arg NAME=VALUE for its arguments")


_PLUGIN_TAGS = {"left": ("leftjoint", "left_joint"), "right": ("rightjoint", "right_joint")}


def drive_joints(root: ET.Element) -> tuple[str, str] | None:
    """(left, right) joints named by a diff-drive plugin or by ``ros2_control`` velocity-commanded joints."""
    for plugin in root.iter("plugin"):
        found = {}
        for side, tags in _PLUGIN_TAGS.items():
            for el in plugin.iter():
                if el.tag.lower() in tags and (el.text or "").strip():
                    found.setdefault(side, el.text.strip())
        if len(found) == 2:
            return found["left"], found["right"]
    velocity = [j.get("name") for rc in root.iter("ros2_control") for j in rc.iter("joint")
                if any(ci.get("name") == "velocity" for ci in j.iter("command_interface"))]
    if len(velocity) == 2 and all(velocity):
        return velocity[0], velocity[1]  # sides are checked by position when the robot is built
    return None
