"""The rerun viewer: found next to the running interpreter, started only where there is a display.

``rerun-sdk`` installs the ``rerun`` executable beside the Python that has it (a venv's ``bin/``), which is not
on ``PATH`` unless the venv is activated: that folder is searched first, then ``PATH``.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys

from lf_common.files import input_file, rrd_is_ours
from twin.errors import TwinError

VIEWER_PORT = 9876  # rerun's default gRPC port: a viewer already listening there is reused


def viewer_executable() -> str:
    """Path of the ``rerun`` viewer executable."""
    here = os.path.join(os.path.dirname(sys.executable), "rerun")
    for candidate in (here, here + ".exe", shutil.which("rerun")):
        if candidate and os.path.isfile(candidate) and os.access(candidate, os.X_OK):
            return candidate
    raise TwinError("rerun viewer: no 'rerun' executable beside this Python or on PATH (pip install rerun-sdk)")


def has_display() -> bool:
    """Whether a window can open here (on Linux and BSD: an X11 or Wayland display is set)."""
    return not sys.platform.startswith(("linux", "freebsd", "openbsd")) or bool(
        os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def require_display(saved: str | None = None) -> None:
    """Refuse to start a window where none can open; ``saved``: the recording already written."""
    if has_display():
        return
    where = f"{saved} is saved: open it" if saved else "use --save FILE.rrd and open it"
    raise TwinError(f"rerun viewer: no display here (DISPLAY and WAYLAND_DISPLAY are unset); {where} where there is one, "
                    "or serve it to a browser with: rerun --serve-web FILE.rrd")


def check_recording(path: str) -> None:
    """A file that rerun can open: exists and starts with the .rrd magic bytes."""
    input_file(path, "recording")
    try:
        with open(path, "rb") as f:
            magic = f.read(4)
    except OSError as e:
        raise TwinError(f"{path}: cannot read the recording ({e.strerror or e})") from None
    if magic != b"RRF2":
        raise TwinError(f"{path}: not a rerun recording (.rrd)")


def open_files(paths: list[str]) -> str:
    """Open saved recordings in a new viewer window; returns the viewer's path."""
    for p in paths:
        check_recording(p)
    require_display()
    exe = viewer_executable()
    try:
        subprocess.Popen([exe, *paths], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    except OSError as e:
        raise TwinError(f"rerun viewer: cannot start {exe} ({e.strerror or e})") from None
    return exe


def spawn_for_stream() -> str:
    """Start (or reuse) a viewer listening for a live stream; returns the URL to stream to."""
    import rerun as rr

    require_display()
    rr.spawn(port=VIEWER_PORT, connect=False, executable_path=viewer_executable())
    return f"rerun+http://127.0.0.1:{VIEWER_PORT}/proxy"


__all__ = ["check_recording", "has_display", "open_files", "require_display", "rrd_is_ours", "spawn_for_stream", "viewer_executable"]
