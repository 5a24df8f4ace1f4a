"""Where the line sensor array sits on a described robot: ``--sensor-mount``, ``--sensor-link``, a link named
*sensor*, or the root link's origin; moved ahead of the axle when the design sets S; rays pointing down."""

from __future__ import annotations

import mujoco
import numpy as np

from mjcf.errors import MjcfError
from mjcf.urdf_parse import UrdfTree, pos_quat

SENSOR_DOWN = (0.0, 1.0, 0.0, 0.0)  # quaternion: half a turn about x, so a site's z axis (its ray) points down


def sensor_mount(tree: UrdfTree, axle: np.ndarray) -> tuple[str, np.ndarray, np.ndarray]:
    """(link, position in the link's frame, quaternion in the link's frame) of the line array: ``--sensor-mount``,
    else a link named *sensor* (``--sensor-link``), else the root link's origin; moved to ``sensor_ahead`` ahead of
    the axle (``axle``: its centre in the root frame [m]) when that is set. The array's rays point down and its row
    runs along y, in the root frame."""
    config, path = tree.config, tree.path
    if config.sensor_mount is not None:
        link, offset = config.sensor_mount
        if link not in tree.links:
            raise MjcfError(f"{path}: sensor mount link {link!r} not in the URDF (links: {', '.join(sorted(tree.links))})")
        pos = np.asarray(offset, dtype=float)
    elif config.sensor_link is not None:
        if config.sensor_link not in tree.links:
            raise MjcfError(f"{path}: sensor link {config.sensor_link!r} not in the URDF")
        link, pos = config.sensor_link, np.zeros(3)
    else:
        named = [n for n in tree.links if "sensor" in n.lower() and ("line" in n.lower() or "ir" in n.lower()
                                                                    or "reflect" in n.lower() or "qtr" in n.lower())]
        named = named or [n for n in tree.links if "sensor" in n.lower()]
        link, pos = (named[0] if len(named) == 1 else tree.root), np.zeros(3)
        if link == tree.root:
            tree.notes.append("no sensor link found by name: the line array mounts on the root link's origin "
                              "(--sensor-mount LINK:X,Y,Z places it)")
    T = tree.link_T[link]
    if config.sensor_ahead is not None:  # S given: on the root, S ahead of the axle centre, at the mount's height
        at = T[:3, :3] @ pos + T[:3, 3]
        return tree.root, np.array([axle[0] + config.sensor_ahead, at[1], at[2]]), np.asarray(SENSOR_DOWN)
    # rays down in the root frame, whatever the link's orientation: q_link⁻¹ ⊗ q_down
    q_link = pos_quat(T)[1]
    q_inv, quat = np.zeros(4), np.zeros(4)
    mujoco.mju_negQuat(q_inv, q_link)
    mujoco.mju_mulQuat(quat, q_inv, np.asarray(SENSOR_DOWN))
    return link, pos, quat
