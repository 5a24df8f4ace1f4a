"""The twin as a Co-Simulation FMU for linux64 (FMI 2.0 or 3.0), self-contained: the compiled world (robot, track
texture, centre line) as MJB, the C loop's head as closed_loop.setup writes it, the FMU's library built from the C
core at export time, and MuJoCo's library beside it. Nothing in it needs Python to run.

The archive is written atomically and reproducibly (fixed member order and dates; the instantiation token is a
digest of what the FMU holds), and replaces only an FMU that this program wrote.
"""

from __future__ import annotations

import ctypes
import dataclasses
import hashlib
import os
import shutil
import tempfile
import uuid
import zipfile

import mujoco
import numpy as np

from lf_common.files import GENERATOR, atomic_path, check_output_file
from mjcf.world import FLOOR, START_KEY
from twin.core.closed_loop import check_seed, setup
from twin.core.digital_twin import DigitalTwin
from twin.core.lap import LapLimits
from twin.errors import TwinError
from twin.fmi.build import compile_library, libmujoco, model_header
from twin.fmi.description import model_description
from twin.fmi.variables import CLOSED_LOOP, KINDS, PLANT, fmu_variables

FMI_VERSIONS = (2, 3)
PLATFORM = {2: "linux64", 3: "x86_64-linux"}  # the binaries folder of each standard
IDENTIFIER = {PLANT: "line_follower_plant", CLOSED_LOOP: "line_follower_closed_loop"}
TOKEN_NAMESPACE = uuid.UUID("5f1d1c38-6c1e-4c55-8f8e-6a7b0f3c2d10")
ZIP_DATE = (1980, 1, 1, 0, 0, 0)
DESCRIPTION = {
    PLANT: "Line-following robot on its track (MuJoCo physics, DC motors, QTR-RC line sensors): motor voltages in; "
           "pose, wheel speeds, sensor readings and line position out; calibrated on the start line at the start",
    CLOSED_LOOP: "Line-following robot with its firmware in the loop on its track: lap time, status, cross-track "
                 "error, pose and motor voltages out; the gains are tunable parameters",
}


@dataclasses.dataclass(frozen=True)
class ExportedFmu:
    """What an export wrote."""

    path: str
    kind: str
    fmi_version: int
    model_identifier: str
    token: str
    variables: int
    parameters: int
    size_bytes: int

    def summary(self) -> dict:
        return dataclasses.asdict(self)


def fmu_is_ours(path: str) -> bool:
    """An FMU whose modelDescription.xml names this program as its generation tool."""
    try:
        with zipfile.ZipFile(path) as z:
            head = z.read("modelDescription.xml")[:4096]
    except (OSError, KeyError, zipfile.BadZipFile):
        return False
    return f'generationTool="{GENERATOR} '.encode() in head


def _model_bytes(model: mujoco.MjModel) -> bytes:
    buffer = np.zeros(mujoco.mj_sizeModel(model), dtype=np.uint8)
    mujoco.mj_saveModel(model, None, buffer)
    return buffer.tobytes()


def _write(folder: str, name: str, data: bytes) -> None:
    path = os.path.join(folder, *name.split("/"))
    os.makedirs(os.path.dirname(path), exist_ok=True)
    with open(path, "wb") as f:
        f.write(data)


def _zip(folder: str, target: str) -> None:
    """Every file under ``folder``, in name order, with fixed dates: the same content gives the same archive."""
    files = sorted(os.path.relpath(os.path.join(d, f), folder).replace(os.sep, "/")
                   for d, _, names in os.walk(folder) for f in names)
    with zipfile.ZipFile(target, "w") as z:
        for name in files:
            info = zipfile.ZipInfo(name, ZIP_DATE)
            info.compress_type = zipfile.ZIP_DEFLATED
            info.external_attr = (0o755 if name.startswith("binaries/") else 0o644) << 16
            with open(os.path.join(folder, name), "rb") as f:
                z.writestr(info, f.read())


def _mujoco_licences() -> dict[str, bytes]:
    """MuJoCo's licence files from its wheel, for the FMU's documentation/licenses."""
    out = {}
    for dist in mujoco.__path__:
        site = os.path.dirname(dist)
        for folder in sorted(os.listdir(site)):
            if folder.startswith(("mujoco-", "mujoco_core-")) and folder.endswith(".dist-info"):
                lic = os.path.join(site, folder, "licenses")
                for name in sorted(os.listdir(lic)) if os.path.isdir(lic) else ():
                    with open(os.path.join(lic, name), "rb") as f:
                        out.setdefault(f"documentation/licenses/MuJoCo-{name}", f.read())
    return out


def export_fmu(twin: DigitalTwin, path: str, kind: str = CLOSED_LOOP, fmi_version: int = 2, seed: int = 0,
               limits: LapLimits = LapLimits()) -> ExportedFmu:
    """Write the twin, with its current values as the FMU's start values, as a Co-Simulation FMU at ``path``.

    Args:
      twin: the robot on its track.
      path: the .fmu to write (a new file, or an FMU this program wrote).
      kind: ``plant`` (voltages in) or ``closed-loop`` (the firmware drives).
      fmi_version: 2 or 3.
      seed: the sensor-noise seed's start value (the same seed as ``lap --seed`` gives the same lap).
      limits: the lap judge's thresholds; ``timeout_s`` is the start of the ``lap_timeout`` parameter.
    """
    if kind not in KINDS:
        raise TwinError(f"--kind {kind!r}: choose plant or closed-loop")
    if fmi_version not in FMI_VERSIONS:
        raise TwinError(f"--fmi {fmi_version!r}: choose 2 or 3")
    check_seed(seed)
    check_output_file(path, fmu_is_ours, "FMU")
    model = twin.model()
    params = twin.control_params()
    row = np.zeros(model.nuserdata)
    sim = setup(row, model, twin, params, twin.sensor_model(), seed, twin.physics())
    head = ctypes.string_at(ctypes.addressof(sim), ctypes.sizeof(sim))
    table = fmu_variables(twin, kind, fmi_version, seed, limits.timeout_s)
    mjb = _model_bytes(model)
    digest = hashlib.sha256(mjb + head + repr((kind, fmi_version, table)).encode()).hexdigest()
    token = "{" + str(uuid.uuid5(TOKEN_NAMESPACE, digest)) + "}"
    identifier = IDENTIFIER[kind]
    ids = {"start_key": model.key(START_KEY).id, "floor_geom": model.geom(FLOOR).id,
           "tyre_geoms": [model.geom(g).id for g in twin.info.tyre_geoms],
           "caster_geoms": [model.geom(g).id for g in twin.info.caster_geoms]}
    if not 1 <= len(ids["tyre_geoms"]) <= 8:
        raise TwinError(f"fmu: the robot has {len(ids['tyre_geoms'])} tyre geoms; the FMU takes 1 to 8")
    if len(ids["caster_geoms"]) > 8:
        raise TwinError(f"fmu: the robot has {len(ids['caster_geoms'])} caster geoms; the FMU takes up to 8")
    xml = model_description(table, fmi_version, identifier, token, DESCRIPTION[kind], limits.timeout_s,
                            params.dt_s, dependency_free=kind == PLANT)
    with tempfile.TemporaryDirectory(prefix="twin-fmu-") as work:
        tree = os.path.join(work, "fmu")
        binaries = os.path.join(tree, "binaries", PLATFORM[fmi_version])
        os.makedirs(binaries)
        compile_library(model_header(table, kind, token, ids, limits, seed), fmi_version,
                        os.path.join(binaries, identifier + ".so"), work)
        shutil.copyfile(libmujoco(), os.path.join(binaries, os.path.basename(libmujoco())))
        for name, data in {"modelDescription.xml": xml, "resources/twin.mjb": mjb, "resources/head.bin": head,
                           **_mujoco_licences()}.items():
            _write(tree, name, data)
        with atomic_path(path, fmu_is_ours, "FMU") as tmp:
            _zip(tree, tmp)
    return ExportedFmu(os.path.abspath(path), kind, fmi_version, identifier, token, len(table),
                       sum(v.causality == "parameter" for v in table), os.path.getsize(path))
