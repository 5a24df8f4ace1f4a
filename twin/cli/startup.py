"""While modules load, Ctrl-C must neither leave a traceback nor break a half-imported library, so it ends the
process at once with status 130: in the first instant of every ``python -m`` entry, and wherever a command loads
the libraries. The command line layer itself loads none (``--help`` and a refused flag take an instant); a command
loads them (about 2 s of CPU: MuJoCo, SciPy, rerun, …) as it starts its work, inside :func:`loading`
(``tests/test_architecture.py`` checks that every such import is). Imports nothing but the standard library's
basics."""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading


def _leave(signum, frame) -> None:
    os.write(2, b"interrupted\n")
    os._exit(130)


@contextlib.contextmanager
def loading():
    """Ctrl-C ends the process at once inside this block (nothing may be written in it, only modules loaded: a
    KeyboardInterrupt inside an extension module's import can turn into an ImportError the library swallows, and the
    Ctrl-C would be lost); a failed import is one ``error:`` line, exit 2.

    MuJoCo's OpenGL rendering is turned off unless the user chose a backend (``MUJOCO_GL``): nothing here renders
    with it (views are rerun's), and with it on, importing MuJoCo imports pyGLFW, which starts a Python child to
    probe the GLFW library's version; a Ctrl-C that ends us then leaves that child a broken pipe and a traceback."""
    os.environ.setdefault("MUJOCO_GL", "disable")
    # only the main thread may set a signal's handler; a worker (live --act's re-tune showing its progress) loads
    # without the guard, the main thread's own Ctrl-C handling standing
    main = threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGINT, _leave) if main else None
    try:
        yield
    except ImportError as e:  # a stale or missing build of the C core, or a missing dependency
        print(f"error: cannot start: {e}", file=sys.stderr)
        sys.exit(2)
    finally:
        if main:
            signal.signal(signal.SIGINT, previous)
