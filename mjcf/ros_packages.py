"""Where a ROS package of a robot description lives, found without ROS, as ROS and yourdfpy find it.

A package is *claimed* by, in this order:

1. ``--package NAME=DIR`` (``package_dirs``): always wins;
2. ``ROS_PACKAGE_PATH`` (ROS 1: each entry and up to ``SEARCH_DEPTH`` folders below it) and ``AMENT_PREFIX_PATH``
   (ROS 2: ``PREFIX/share/NAME``);
3. the folders above the description, nearest first, each with up to ``SEARCH_DEPTH`` folders below it (a colcon
   workspace's ``src/<repo>/<pkg>``).

In 2 and 3 a folder is package NAME when its ``package.xml`` ``<name>`` says so (whatever the folder is called, as in
a GitHub zip's ``mybot-main/``), or, without a ``package.xml``, when it is called NAME. When nothing claims NAME,
``package://NAME/PATH`` is the nearest folder above the description that holds PATH, as yourdfpy resolves it
(a description in ``urdf/`` with its meshes in ``../meshes``). Only this module imports nothing beyond the
standard library: the xacro child process (:mod:`mjcf.xacro_child`) uses it too.
"""

from __future__ import annotations

import dataclasses
import os
import xml.etree.ElementTree as ET

SEARCH_UP = 5  # folders above the description searched for packages
SEARCH_DEPTH = 3  # below each: a colcon workspace's src/<repo>/<pkg> is three down from the workspace
SEARCH_ENTRIES = 2000  # folders looked at below each, at most: a search never walks a whole disk


@dataclasses.dataclass(frozen=True)
class PackageSearch:
    """Where packages are looked for, from one description: what the message of a package not found lists."""

    start: str  # the description's folder
    package_dirs: tuple[tuple[str, str], ...] = ()

    def roots(self) -> list[str]:
        """The folders searched below, in order: ROS_PACKAGE_PATH's, then the description's folder and those above."""
        roots = [p for p in os.environ.get("ROS_PACKAGE_PATH", "").split(os.pathsep) if p]
        return roots + _ancestors(os.path.abspath(self.start), SEARCH_UP + 1)

    def find(self, name: str) -> str | None:
        """The folder that claims package ``name``, or None."""
        for pkg, folder in self.package_dirs:
            if pkg == name:
                return os.path.abspath(folder)
        for prefix in (p for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p):
            share = os.path.join(prefix, "share", name)
            if _is_package(share, name):
                return share
        for root in self.roots():
            found = _search_below(root, name)
            if found is not None:
                return found
        return None

    def folder_for(self, name: str, rest: str) -> tuple[str | None, bool]:
        """The folder of package ``name`` for ``package://name/rest``: (folder, True) when a package claims the name;
        else (folder, False) for the nearest folder above the description that holds ``rest``, as yourdfpy resolves
        it; (None, False) when there is none."""
        folder = self.find(name)
        if folder is not None:
            return folder, True
        for here in _ancestors(os.path.abspath(self.start), None):
            if os.path.isfile(os.path.join(here, rest)):
                return here, False
        return None, False

    def not_found(self, description: str, what: str, name: str, rest: str | None = None) -> str:
        """One line: the package, the description, the folders searched and the flag that names the package."""
        ancestors = _ancestors(os.path.abspath(self.start), SEARCH_UP + 1)
        ros = os.environ.get("ROS_PACKAGE_PATH") or "unset"
        ament = os.environ.get("AMENT_PREFIX_PATH") or "unset"
        holds = f", and no folder above the description holds {rest}" if rest else ""
        return (f"{description}: {what}: package {name!r} not found: no package.xml naming it and no folder called "
                f"{name} in {ancestors[0]} or the {len(ancestors) - 1} folders above it (up to {ancestors[-1]}), "
                f"nor up to {SEARCH_DEPTH} folders below each, nor in ROS_PACKAGE_PATH ({ros}) or AMENT_PREFIX_PATH "
                f"({ament}){holds}; give --package {name}=DIR")


def find_package(name: str, start: str, package_dirs: tuple[tuple[str, str], ...] = ()) -> str | None:
    """The folder of ROS package ``name`` as seen from a description in ``start``, or None (see the module)."""
    return PackageSearch(start, package_dirs).find(name)


def _ancestors(folder: str, count: int | None) -> list[str]:
    """``folder`` and the folders above it, nearest first: ``count`` of them, or all up to the root."""
    out = [folder]
    while count is None or len(out) < count:
        parent = os.path.dirname(out[-1])
        if parent == out[-1]:
            break
        out.append(parent)
    return out


def _search_below(top: str, name: str) -> str | None:
    """Breadth first, each level checked whole before the next is listed, so the nearest match wins; hidden
    folders and symlinks are not entered."""
    level, seen = [top], 0
    for _ in range(SEARCH_DEPTH + 1):
        for folder in level:
            if _is_package(folder, name):
                return folder
        nxt = []
        for folder in level:
            try:
                entries = sorted(os.scandir(folder), key=lambda e: e.name)
            except OSError:
                continue
            nxt += [e.path for e in entries if not e.name.startswith(".") and e.is_dir(follow_symlinks=False)]
            seen += len(entries)
            if seen > SEARCH_ENTRIES:
                return None
        level = nxt
    return None


def _is_package(folder: str, name: str) -> bool:
    """``package.xml`` names it; without one (or without a readable ``<name>``), the folder is called ``name``."""
    if not os.path.isdir(folder):
        return False
    manifest = os.path.join(folder, "package.xml")
    if os.path.isfile(manifest) and os.path.getsize(manifest) < 1_000_000:
        try:
            declared = ET.parse(manifest).getroot().findtext("name")
        except (ET.ParseError, OSError):
            declared = None
        if declared is not None:
            return declared.strip() == name
    return os.path.basename(folder) == name
