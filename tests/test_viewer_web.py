"""Each kind of recording (lap, tuning, alignment, design, live) opened in rerun's web viewer, served by the
installed rerun, in headless Chromium: no viewer error in the console, and every panel of its blueprint shown.

The viewer draws into a WebGL canvas (egui): panel titles are not in the page's DOM, so they are read from a
screenshot with Tesseract OCR. Needs Debian's ``chromium`` and ``tesseract-ocr`` (``.ci/run`` installs both)
and Playwright's Python package (the ``test`` extra), pointed at the system browser (see
:mod:`twin.viz.web_viewer`). Skipped where they are missing, except in CI (``CI`` set), where that is a failure.
"""

from __future__ import annotations

import difflib
import os
import re
import shutil
import subprocess
import sys
import time

import pytest

from lf_common.cache import cached_folder
from twin.core.digital_twin import DigitalTwin
from twin.link.emulator import lap_records
from twin.viz.viewer import viewer_executable
from twin.viz.web_viewer import BROWSER_TIMEOUT_S, chromium_executable, headless_chromium, next_frame, screenshot, served

TESSERACT = shutil.which("tesseract")
RERUN = viewer_executable()
HAVE_TOOLS = bool(chromium_executable() and TESSERACT)
if not HAVE_TOOLS and not os.environ.get("CI"):
    pytest.skip("needs chromium and tesseract-ocr (CI installs them)", allow_module_level=True)

if os.environ.get("CI"):
    import playwright.sync_api  # noqa: F401  (in CI a missing package fails instead of skipping)
else:
    pytest.importorskip("playwright.sync_api")
RUN = [sys.executable, "-m", "twin.run"]
PANELS_BUDGET_S = 900.0  # [s] at most, to see a recording's panels; done as soon as they are all seen
# console errors that are the network, not the viewer: no internet here (fonts, the welcome screen's examples)
OFFLINE = re.compile(r"ERR_NAME_NOT_RESOLVED|ERR_INTERNET_DISCONNECTED|Failed to fetch|Failed to load examples")
# (recording, panels its blueprint declares)
PANELS = {
    "lap": ["track", "line angle e [rad]", "speed v [m/s]", "turn rate ω [rad/s]", "motor voltage [V]", "energy drawn [J]", "calibrated readings", "cross-track error [m]"],
    "tune": ["cost (lap time, failures penalised) [s]", "parameters (fraction of their bounds)", "best lap"],
    "align": ["motion.mu", "lap time [s]"],
    "design": ["lap times", "Pareto"],
    "live": ["lap time [s]", "discrepancy, robot vs twin", "left wheel speed [rad/s]", "line position (readLine)"],
}


KINDS = ("lap", "tune", "align", "design", "live")


@pytest.fixture(scope="session")
def recordings(run_folder):
    """One small recording of each kind, made by the project's own commands, once for the run: both pytest processes
    run this module's tests (worksteal), and the second waits for the first's and reads them (a cache entry in the
    run's folder: lf_common.cache, whose lock makes them once)."""

    def make(d: str) -> None:
        log = os.path.join(d, "robot.log")
        with open(log, "w") as f:
            f.write("".join(line for _, line in lap_records(DigitalTwin(track="oval"), 7, 4, 2)))
        oval = ["--track", "oval"]
        commands = {
            "lap": ["lap", *oval],
            "tune": ["tune", *oval, "--max-iter", "1", "--param", "control.kp", "--held-out", "0", "-q"],
            "align": ["align", *oval, "--measured-lap-time", "9"],
            "design": ["design", *oval, "--grid", "cad.S=0.05,0.07", "--laps", "1", "--max-iter", "1", "--workers",
                       "1", "--out-dir", os.path.join(d, "study"), "-q"],
            "live": ["live", *oval, "--replay", log],
        }
        assert tuple(commands) == KINDS
        for kind, args in commands.items():
            path = os.path.join(d, f"{kind}.rrd")
            r = subprocess.run([*RUN, *args, "--save", path], capture_output=True, text=True, timeout=900)
            assert r.returncode in (0, 1) and os.path.isfile(path), (kind, r.stderr)

    d = cached_folder(str(run_folder / "viewer-recordings"), make, "the viewer test's recordings")
    return {kind: os.path.join(d, f"{kind}.rrd") for kind in KINDS}


def test_every_recording_is_valid_for_rerun(recordings):
    for kind, path in recordings.items():
        r = subprocess.run([RERUN, "rrd", "verify", path], capture_output=True, text=True, timeout=BROWSER_TIMEOUT_S)
        assert r.returncode == 0, (kind, r.stdout, r.stderr)


def ocr_words(png: str) -> list[str]:
    text = subprocess.run([TESSERACT, png, "-"], capture_output=True, text=True, timeout=BROWSER_TIMEOUT_S).stdout
    return re.findall(r"[a-z][a-z.\-]+", text.lower())


def panel_shown(name: str, words: list[str]) -> bool:
    """Every word of 4+ letters in the panel's title is in the screenshot's text (OCR: close matches count)."""
    wanted = [w for w in re.findall(r"[a-z][a-z.\-]+", name.lower()) if len(w) >= 4] or [name.lower()]
    return all(difflib.get_close_matches(w, words, n=1, cutoff=0.75) for w in wanted)


def show(page, path: str, shot: str, panels: list[str], budget_s: float = PANELS_BUDGET_S) -> tuple[list[str], list[str]]:
    """Serve one recording to the web viewer, load it, and read the screen until every panel is seen (at most
    ``budget_s``). Each round waits for conditions, not for a fixed time: the viewer's canvas, then a frame drawn
    since the last look, then the screenshot (each bounded by ``BROWSER_TIMEOUT_S``). Returns (the words read
    last, the console errors)."""
    errors: list[str] = []
    page.on("console", lambda m: errors.append(m.text) if m.type == "error" and not OFFLINE.search(m.text) else None)
    with served(path) as url:
        page.goto(url, timeout=BROWSER_TIMEOUT_S * 1000)
        page.wait_for_selector("canvas", state="visible", timeout=BROWSER_TIMEOUT_S * 1000)
        deadline = time.monotonic() + budget_s
        words: list[str] = []
        while time.monotonic() < deadline:
            next_frame(page)
            screenshot(page, shot)
            words = ocr_words(shot)
            if all(panel_shown(name, words) for name in panels):
                break
        return words, list(errors)  # (taken while the server runs: its end breaks the page's open stream)


@pytest.fixture(scope="module")
def browser():
    with headless_chromium() as b:
        yield b


@pytest.mark.parametrize("kind", list(PANELS))
def test_the_web_viewer_shows_every_panel_without_errors(browser, recordings, kind, tmp_path):
    page = browser.new_page(viewport={"width": 1600, "height": 1000}, device_scale_factor=2)
    page.set_default_timeout(BROWSER_TIMEOUT_S * 1000)  # any wait not bounded below: a busy machine's bound
    try:
        words, errors = show(page, recordings[kind], str(tmp_path / f"{kind}.png"), PANELS[kind])
    finally:
        page.close()
    assert not errors, errors[:5]
    missing = [name for name in PANELS[kind] if not panel_shown(name, words)]
    assert not missing, f"{kind}: panels not seen: {missing}; read: {' '.join(words)[:600]}"
