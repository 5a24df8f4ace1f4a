"""A recording in rerun's web viewer, in headless Chromium: served by the installed ``rerun``, screenshotted.

Used by the web-viewer test and by ``docs/make_figures.py``. The viewer draws with WebGL; headless Chromium has
no GPU here, so it renders with SwiftShader (ANGLE's software Vulkan), which must be allowed explicitly.
Needs Debian's ``chromium`` and Playwright's Python package (the ``test`` extra), pointed at that browser:
Playwright's own browser download is not used.
"""

from __future__ import annotations

import contextlib
import ctypes
import hashlib
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
from typing import Iterator

from twin.errors import TwinError
from twin.viz.viewer import check_recording, viewer_executable

CHROMIUM_ARGS = ("--no-sandbox", "--use-gl=angle", "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
                 "--ignore-gpu-blocklist")
# Waits are for conditions (a port answers, a frame is drawn, a screenshot is taken), each bounded so nothing
# hangs; the bounds are for a busy machine (two cores shared with other work), where SwiftShader draws a
# 3200×2000 frame in software: a fixed 30 s (Playwright's default) was not always enough for one screenshot.
SERVER_START_S = 120.0  # [s] for `rerun --serve-web` to answer on its port
BROWSER_TIMEOUT_S = 300.0  # [s] to start the browser, load the page, draw a frame, take one screenshot


def chromium_executable() -> str | None:
    """The system Chromium (Debian: ``chromium``), or None."""
    return shutil.which("chromium") or shutil.which("chromium-browser")


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _server_executable() -> str:
    """rerun's own binary (rerun-sdk ships it in ``rerun_cli``), else the ``rerun`` launcher."""
    try:
        import rerun_cli  # the binary's package, installed with rerun-sdk

        binary = os.path.join(os.path.dirname(rerun_cli.__file__), "rerun")
        if os.path.isfile(binary) and os.access(binary, os.X_OK):
            return binary
    except ImportError:
        pass
    return viewer_executable()


def _die_with_parent() -> None:
    """In the server's process, before it runs: be killed when the thread that started it ends, however this
    process dies (Linux's PR_SET_PDEATHSIG; elsewhere nothing)."""
    if sys.platform.startswith("linux"):
        ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGKILL)  # 1: PR_SET_PDEATHSIG


@contextlib.contextmanager
def served(recording: str) -> Iterator[str]:
    """Serve ``recording`` with ``rerun --serve-web``; yields the URL that opens it in the web viewer."""
    check_recording(recording)
    web, grpc = free_port(), free_port()
    # a session of its own: the venv's `rerun` is a Python launcher that runs the binary as its child, and killing
    # the launcher alone would leave the server running. The binary itself, where rerun-sdk ships it, is started
    # directly and told to die with this process: a test killed at its time limit left servers running for hours
    server = subprocess.Popen([_server_executable(), "--serve-web", recording, "--web-viewer-port", str(web),
                               "--port", str(grpc)], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                              start_new_session=True, preexec_fn=_die_with_parent)
    try:
        deadline = time.monotonic() + SERVER_START_S
        while True:  # up when its web port answers
            with socket.socket() as s:
                if s.connect_ex(("127.0.0.1", web)) == 0:
                    break
            if server.poll() is not None or time.monotonic() > deadline:
                raise TwinError(f"{recording}: rerun --serve-web did not start within {SERVER_START_S:g} s")
            time.sleep(0.2)
        yield f"http://127.0.0.1:{web}/?url=rerun%2Bhttp%3A%2F%2F127.0.0.1%3A{grpc}%2Fproxy"
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(server.pid, signal.SIGKILL)
        server.wait()


@contextlib.contextmanager
def headless_chromium() -> Iterator[object]:
    """A Playwright ``Browser`` on the system Chromium, with software WebGL."""
    executable = chromium_executable()
    if not executable:
        raise TwinError("web viewer: no chromium on PATH (Debian: apt-get install chromium)")
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        raise TwinError("web viewer: the playwright package is missing (pip install -e '.[test]')") from None
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=executable, args=list(CHROMIUM_ARGS),
                                    timeout=BROWSER_TIMEOUT_S * 1000)
        try:
            yield browser
        finally:
            browser.close()


def next_frame(page) -> None:
    """Wait until the page has drawn its next animation frame (the viewer has had its turn to render)."""
    page.wait_for_function("() => true", polling="raf", timeout=BROWSER_TIMEOUT_S * 1000)


def screenshot(page, png: str) -> bytes:
    """A screenshot of ``page`` to ``png`` (and its bytes), waiting as long as a busy machine needs."""
    return page.screenshot(path=png, timeout=BROWSER_TIMEOUT_S * 1000)


def screenshot_when_settled(page, png: str, min_wait_s: float = 6.0, timeout_s: float = 60.0,
                            every_s: float = 2.0) -> bool:
    """Screenshot ``page`` to ``png`` until two consecutive shots are identical (the viewer has loaded the
    recording and stopped animating), at least ``min_wait_s`` after the call. Returns whether it settled within
    ``timeout_s`` (the last shot is kept either way)."""
    start, last = time.monotonic(), None
    while True:
        time.sleep(every_s)
        digest = hashlib.sha256(screenshot(page, png)).digest()
        now = time.monotonic() - start
        if digest == last and now >= min_wait_s:
            return True
        if now >= timeout_s:
            return False
        last = digest
