"""Build hook: setuptools reads pyproject.toml; the twin's C core is declared here.

``twin._lfcore`` is a plain shared library loaded with ctypes (it has no Python module init): the
firmware (``twin/csrc/firmware``, the robot's own C) and the MuJoCo control callback (``twin/csrc/sim``).
It reads mjModel/mjData fields, so it compiles against the headers of the installed ``mujoco`` wheel;
``twin.core`` checks at load time that the runtime MuJoCo matches.
"""

import glob
import os

from setuptools import Extension, setup


def mujoco_include() -> str:
    import mujoco  # a build requirement (pyproject.toml)

    return os.path.join(os.path.dirname(mujoco.__file__), "include")


sources = sorted(glob.glob("twin/csrc/firmware/line_follower.c") + glob.glob("twin/csrc/firmware/lf_wire.c")
                 + glob.glob("twin/csrc/sim/*.c"))

setup(
    ext_modules=[
        Extension(
            "twin._lfcore",
            sources=sources,
            include_dirs=[mujoco_include(), "twin/csrc"],
            # no FMA contraction: the C must equal its Python reference bit for bit
            extra_compile_args=["-std=c99", "-O2", "-ffp-contract=off", "-Wall", "-Wextra"],
            libraries=["m"],
        )
    ]
)
