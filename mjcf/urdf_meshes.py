"""Mesh assets of a robot description: a URDF mesh filename resolved to a file (relative, absolute, ``file://`` or
``package://``), read within size limits, converted when MuJoCo cannot read its format, and added to the MjSpec
once for each (file, scale)."""

from __future__ import annotations

import hashlib
import logging
import os
import re

import mujoco
import numpy as np
import trimesh

from lf_common.cache import cache_dir, cached_folder
from lf_common.errors import InputTooLarge, LineFollowerError
from lf_common.files import input_file
from mjcf.errors import MjcfError
from mjcf.robot_source import Description
from mjcf.ros_packages import PackageSearch

log = logging.getLogger("mjcf.urdf_to_mjcf")  # the converter speaks through one logger (the CLI prints the name)

MAX_MESH_BYTES = 64_000_000  # a mesh file larger than this is a render model, not a collision shape
MAX_MESH_FACES = 500_000  # trimesh needs ~1.5 kB a face to load and check one (a 2.6M-face OBJ took 3.9 GB)
MUJOCO_MESH_FORMATS = (".stl", ".obj", ".msh")


class MeshResolver:
    """URDF mesh filename → file: relative to the description's folder, absolute, or ``package://NAME/…`` through
    :class:`mjcf.ros_packages.PackageSearch` (``--package``, ROS's paths, the folders around the description; when
    nothing claims NAME, the folder above the description that holds the file, noted in ``notes``)."""

    def __init__(self, description: Description, package_dirs: tuple[tuple[str, str], ...], notes: list[str]):
        self.path = description.path
        self.folder = description.folder
        self.search = PackageSearch(description.folder, package_dirs)
        self.notes = notes
        self._folders: dict[str, str] = {}  # package → its folder, once found: every file of it resolves alike

    def __call__(self, fname: str) -> str:
        m = re.match(r"package://([^/]+)/(.*)", fname)
        if m:
            name, rest = m.groups()
            if name not in self._folders:
                folder, claimed = self.search.folder_for(name, rest)
                if folder is None:
                    raise MjcfError(self.search.not_found(self.path, fname, name, rest))
                if not claimed:
                    self.notes.append(f"package {name!r}: no package.xml or folder claims the name, so it is {folder}, "
                                      f"the folder above the description that holds {rest} (as yourdfpy resolves it)")
                    log.warning("%s: %s", self.path, self.notes[-1])
                self._folders[name] = folder
            return os.path.join(self._folders[name], rest)
        if fname.startswith("file://"):
            fname = fname[len("file://") :]
        return fname if os.path.isabs(fname) else os.path.join(self.folder, fname)


def load_mesh(source: str, urdf: str) -> trimesh.Trimesh:
    """A mesh file as one trimesh, within the size limits; errors name the file and what to do."""
    try:
        size = input_file(source, "mesh file").st_size
    except LineFollowerError as e:
        raise MjcfError(f"{urdf}: mesh {e}") from None
    if size > MAX_MESH_BYTES:
        raise InputTooLarge(f"{urdf}: mesh {source} is {size / 1e6:.0f} MB, more than the {MAX_MESH_BYTES / 1e6:g} MB "
                            f"limit; simplify it (e.g. decimate to under {MAX_MESH_FACES // 1000}k faces in Blender or "
                            "MeshLab): a collision shape needs far less")
    try:
        mesh = trimesh.load(source, force="mesh")
    except Exception as e:  # trimesh raises assorted errors for files it cannot parse
        raise MjcfError(f"{urdf}: mesh {source} is unreadable ({type(e).__name__})") from None
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise MjcfError(f"{urdf}: mesh {source} holds no triangles")
    if len(mesh.faces) > MAX_MESH_FACES:
        raise InputTooLarge(f"{urdf}: mesh {source} has {len(mesh.faces)} faces, more than the {MAX_MESH_FACES} limit; "
                            "simplify it (decimate in Blender or MeshLab)")
    return mesh


def scaled_vertices(mesh, resolve: MeshResolver, urdf: str) -> np.ndarray:
    """(n, 3) vertices of a URDF ``<mesh>`` element's file in its geometry's frame, its ``scale`` applied [m]."""
    m = load_mesh(resolve(mesh.filename), urdf)
    return m.vertices * (1.0 if mesh.scale is None else np.asarray(mesh.scale))


def _converted_mesh(source: str, urdf: str) -> str:
    """A mesh MuJoCo cannot read (e.g. COLLADA), converted by trimesh to an STL in the verified cache, keyed by the
    source file's content."""
    mesh = load_mesh(source, urdf)
    with open(source, "rb") as f:
        digest = hashlib.sha256(f.read()).hexdigest()[:16]
    name = os.path.basename(source) + ".stl"  # keeps the source's name: assets are saved by file name
    folder = cached_folder(os.path.join(cache_dir(), "meshes", digest),
                           lambda tmp: mesh.export(os.path.join(tmp, name), file_type="stl"), "converted mesh")
    return os.path.join(folder, name)


class MeshAssets:
    """The mesh assets one robot adds to an MjSpec, one for each (source file, scale).

    Attributes:
      files: asset name → the file MuJoCo reads (a converted copy for formats it cannot read), for saving.
    """

    def __init__(self, spec: mujoco.MjSpec, resolve: MeshResolver, urdf: str, prefix: str):
        self.spec = spec
        self.resolve = resolve
        self.urdf = urdf
        self.prefix = prefix
        self.files: dict[str, str] = {}
        self._keys: dict[str, tuple] = {}  # asset name → (URDF source file, scale), to share assets

    def add(self, link_name: str, mesh) -> str:
        """The asset name of a URDF ``<mesh>`` element of ``link_name``, added to the spec unless it already is."""
        source = self.resolve(mesh.filename)
        if not os.path.lexists(source):
            raise MjcfError(f"{self.urdf}: mesh {mesh.filename!r} of link {link_name} not found")
        scale = np.ones(3) if mesh.scale is None else np.broadcast_to(np.asarray(mesh.scale, dtype=float), (3,))
        key = (os.path.abspath(source), tuple(scale))
        for name, (src, sc) in self._keys.items():
            if (src, sc) == key:
                return name
        ext = os.path.splitext(source)[1].lower()
        if ext not in MUJOCO_MESH_FORMATS:
            source = _converted_mesh(source, self.urdf)  # e.g. COLLADA: MuJoCo reads STL/OBJ/MSH only
        else:
            load_mesh(source, self.urdf)  # the limits and a readable file, before MuJoCo reads it
        name = self.prefix + f"mesh{len(self._keys)}_{os.path.splitext(os.path.basename(source))[0]}"
        self.spec.add_mesh(name=name, file=source, scale=scale)
        self._keys[name] = key
        self.files[name] = source
        return name
