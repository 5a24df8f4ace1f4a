"""The first instant of every ``python -m`` entry: while the libraries load (about a second: MuJoCo, SciPy,
rerun), Ctrl-C must neither leave a traceback nor break a half-imported library, so it ends the process at once
(nothing has been written yet) with status 130. Imports nothing but the standard library's basics."""

from __future__ import annotations

import contextlib
import os
import signal
import sys


def _leave(signum, frame) -> None:
    os.write(2, b"interrupted\n")
    os._exit(130)


@contextlib.contextmanager
def loading():
    """Ctrl-C ends the process at once inside this block; a failed import is one ``error:`` line, exit 2.

    MuJoCo's OpenGL rendering is turned off unless the user chose a backend (``MUJOCO_GL``): nothing here renders
    with it (views are rerun's), and with it on, importing MuJoCo imports pyGLFW, which starts a Python child to
    probe the GLFW library's version; a Ctrl-C that ends us then leaves that child a broken pipe and a traceback."""
    os.environ.setdefault("MUJOCO_GL", "disable")
    previous = signal.signal(signal.SIGINT, _leave)
    try:
        yield
    except ImportError as e:  # a stale or missing build of the C core, or a missing dependency
        print(f"error: cannot start: {e}", file=sys.stderr)
        sys.exit(2)
    finally:
        signal.signal(signal.SIGINT, previous)
