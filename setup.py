"""Build hook: setuptools reads pyproject.toml; the twin's C core is declared here.

``twin.pil._lfavr`` (built when simavr's headers are installed) adds the processor-in-the-loop glue
(``twin/csrc/pil``), linked against libsimavr.

``twin.core._lfcore`` is a plain shared library loaded with ctypes (it has no Python module init): the
firmware (``twin/csrc/firmware``, the robot's own C) and the MuJoCo control callback (``twin/csrc/sim``).
It reads mjModel/mjData fields, so it compiles against the headers of the installed ``mujoco`` wheel;
``twin.core.native`` checks at load time that the runtime MuJoCo matches.
"""

import glob
import os

from setuptools import Extension, setup


def mujoco_include() -> str:
    import mujoco  # a build requirement (pyproject.toml)

    return os.path.join(os.path.dirname(mujoco.__file__), "include")


def simavr_present() -> bool:
    """libsimavr-dev's headers (Debian: apt-get install simavr libsimavr-dev)."""
    return any(os.path.isfile(os.path.join(d, "simavr", "sim_avr.h")) for d in ("/usr/include", "/usr/local/include"))


sources = sorted(glob.glob("twin/csrc/firmware/line_follower.c") + glob.glob("twin/csrc/firmware/lf_wire.c")
                 + glob.glob("twin/csrc/sim/*.c"))

# no FMA contraction: the C must equal its Python reference bit for bit
FLAGS = ["-std=c99", "-O2", "-ffp-contract=off", "-Wall", "-Wextra"]

# the processor-in-the-loop glue: the same core plus simavr, in its own library so the twin works without simavr
pil = [
    Extension(
        "twin.pil._lfavr",
        sources=sources + sorted(glob.glob("twin/csrc/pil/*.c")),
        include_dirs=[mujoco_include(), "twin/csrc"],
        extra_compile_args=FLAGS,
        libraries=["simavr", "m"],
        optional=True,
    )
] if simavr_present() else []

setup(
    ext_modules=[
        Extension(
            "twin.core._lfcore",
            sources=sources,
            include_dirs=[mujoco_include(), "twin/csrc"],
            extra_compile_args=FLAGS,
            libraries=["m"],
        )
    ] + pil
)
