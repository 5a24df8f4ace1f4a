"""A robot description as published: a URDF, or a xacro file expanded with the ``xacro`` package; its ROS
packages found without ROS; the drive joints its diff-drive plugin names.

* **Xacro** (``.xacro``, ``.urdf.xacro``, or a ``.urdf`` that uses the xacro namespace) is expanded in memory by
  the ``xacro`` package with the user's ``NAME=VALUE`` arguments. ``$(find PKG)`` normally asks ROS's ament
  index; here it is answered by :func:`find_package`. A ``.urdf`` with ``${…}`` or ``$(…)`` left in it is an
  unexpanded xacro, and is refused with the fix, rather than converted with names like ``${ns}wheel_joint``.
* **Packages** (``$(find PKG)``, ``package://PKG/…``): an explicit ``NAME=DIR`` map first, then the folders above
  the description and up to three below each (a colcon workspace's ``src/<repo>/<pkg>``), nearest first: a folder
  that is the package (its ``package.xml`` names it, or it is called PKG).
* **Drive joints**: the joints a Gazebo diff-drive plugin (classic ``libgazebo_ros_diff_drive``: ``leftJoint``,
  ``left_joint``; Gazebo Sim's ``DiffDrive``: ``left_joint``) or a ``ros2_control`` block with a velocity
  command names. yourdfpy drops ``<gazebo>`` and ``<ros2_control>`` elements, so they are read here.
"""

from __future__ import annotations

import contextlib
import dataclasses
import io
import logging
import os
import re
import threading
import xml.etree.ElementTree as ET

from lf_common.errors import LineFollowerError
from lf_common.files import read_bytes
from mjcf.errors import MjcfError

log = logging.getLogger(__name__)

MAX_DESCRIPTION_BYTES = 16_000_000  # a robot description is text: tens of kB; this is junk or a mistake
XACRO_NS = "http://www.ros.org/wiki/xacro"
_UNEXPANDED = re.compile(r"\$\{[^}]*\}|\$\([^)]*\)")
_xacro_lock = threading.Lock()  # the xacro package keeps its state in module globals


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
    if not os.path.lexists(path):
        raise MjcfError(f"{path}: robot description not found")
    try:
        raw = read_bytes(path, MAX_DESCRIPTION_BYTES, "robot description")
    except LineFollowerError as e:
        raise MjcfError(str(e)) from None
    notes: list[str] = []
    folder = os.path.dirname(os.path.abspath(path))
    if is_xacro_name(path) or _uses_xacro(raw):
        xml = expand_xacro(path, xacro_args, package_dirs)
        notes.append(f"expanded {os.path.basename(path)} with xacro"
                     + (f" ({', '.join(f'{k}={v}' for k, v in xacro_args)})" if xacro_args else ""))
    else:
        if xacro_args:
            raise MjcfError(f"{path}: --xacro-arg is given but the description is not xacro")
        xml = raw
    root = _parse(path, xml)
    _refuse_unexpanded(path, root)
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


def expand_xacro(path: str, args: tuple[tuple[str, str], ...], package_dirs: tuple[tuple[str, str], ...]) -> bytes:
    """``path`` expanded by the xacro package, ``$(find PKG)`` answered by :func:`find_package`."""
    import xacro
    import xacro.substitution_args as subst

    start = os.path.dirname(os.path.abspath(path))

    def find(pkg: str) -> str:
        found = find_package(pkg, start, package_dirs)
        if found is None:
            raise MjcfError(f"{path}: $(find {pkg}): package {pkg!r} not found beside the description or above it; "
                            f"give --package {pkg}=DIR")
        return found

    chatter = io.StringIO()  # xacro prints warnings and its include stack to stderr: keep them for the log
    with _xacro_lock, contextlib.redirect_stderr(chatter), contextlib.redirect_stdout(chatter):
        saved = subst._eval_find
        subst._eval_find = find
        try:
            doc = xacro.process_file(path, mappings=dict(args))
            xml = doc.toprettyxml(indent="  ").encode()
        except MjcfError:
            raise
        except xacro.XacroException as e:
            raise MjcfError(f"{path}: xacro cannot expand it ({_one_line(e)}){_arg_hint(e)}") from None
        except Exception as e:  # xacro surfaces parse, name and evaluation errors as assorted types
            raise MjcfError(f"{path}: xacro cannot expand it ({type(e).__name__}: {_one_line(e)}){_arg_hint(e)}") from None
        finally:
            subst._eval_find = saved
    for line in chatter.getvalue().splitlines():
        if line.strip():
            log.info("xacro: %s", line.strip())
    return xml


def _one_line(e: BaseException) -> str:
    text = " ".join(str(e).split())
    return text[:300] or type(e).__name__


def _arg_hint(e: BaseException) -> str:
    m = re.search(r"[Uu]ndefined substitution argument (\w+)|arg[^\w]+(\w+)[^\w]+is not defined", str(e))
    name = m and (m.group(1) or m.group(2))
    return f"; give it with --xacro-arg {name}=VALUE" if name else ""


SEARCH_UP = 5  # folders above the description searched for packages
SEARCH_DEPTH = 3  # below each: a colcon workspace's src/<repo>/<pkg> is three down from the workspace
SEARCH_ENTRIES = 2000  # folders looked at below each, at most: a search never walks a whole disk


def find_package(name: str, start: str, package_dirs: tuple[tuple[str, str], ...] = ()) -> str | None:
    """The folder of ROS package ``name``: from ``package_dirs``, else the first found from ``start`` upwards
    (``SEARCH_UP`` folders): the folder itself, or one up to ``SEARCH_DEPTH`` below it, nearest first."""
    for pkg, folder in package_dirs:
        if pkg == name:
            return os.path.abspath(folder)
    here = os.path.abspath(start)
    for _ in range(SEARCH_UP + 1):
        found = _search_below(here, name)
        if found is not None:
            return found
        parent = os.path.dirname(here)
        if parent == here:
            return None
        here = parent
    return None


def _search_below(top: str, name: str) -> str | None:
    """Breadth first, so the nearest match wins; hidden folders and symlinks are not entered."""
    level, seen = [top], 0
    for _ in range(SEARCH_DEPTH + 1):
        nxt = []
        for folder in level:
            if _is_package(folder, name):
                return folder
            try:
                entries = sorted(os.scandir(folder), key=lambda e: e.name)
            except OSError:
                continue
            for e in entries:
                if not e.name.startswith(".") and e.is_dir(follow_symlinks=False):
                    nxt.append(e.path)
            seen += len(entries)
            if seen > SEARCH_ENTRIES:
                return None
        level = nxt
    return None


def _is_package(folder: str, name: str) -> bool:
    if not os.path.isdir(folder):
        return False
    manifest = os.path.join(folder, "package.xml")
    if os.path.isfile(manifest):
        try:
            declared = ET.parse(manifest).getroot().findtext("name")
        except (ET.ParseError, OSError):
            declared = None
        if declared is not None:
            return declared.strip() == name
    return os.path.basename(folder) == name


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
