"""Bad tracks (``--track NAME|PNG``, ``--metres-per-pixel``), one row each: exit 2, one ``error: …`` line naming the
input and the fault, no traceback, in time (:mod:`bad_input`). A new fault of this family is a new row."""

from __future__ import annotations

import numpy as np
import pytest
from PIL import Image

from bad_input import BadFiles, check_bad_input, check_in_fresh_process
from conftest import minimal_urdf


def _save(files: BadFiles, name: str, grey: np.ndarray, **info) -> None:
    Image.fromarray(grey).save(files.folder / name, **info)
    files.paths[name] = str(files.folder / name)


def _ring(shape=(400, 400), centres=((200, 200),)) -> np.ndarray:
    grey = np.full(shape, 255, np.uint8)
    yy, xx = np.mgrid[: shape[0], : shape[1]]
    for cy, cx in centres:
        r = np.hypot(yy - cy, xx - cx)
        grey[(r > 150) & (r < 160)] = 0
    return grey


@pytest.fixture(scope="module")
def files(tmp_path_factory) -> BadFiles:
    f = BadFiles(tmp_path_factory.mktemp("bad_tracks"))
    f.put("mini.urdf", minimal_urdf())
    f.put("not_a_png.png", b"not a png at all")
    _save(f, "white.png", np.full((400, 400), 255, np.uint8), dpi=(254, 254))
    _save(f, "dpi_1e8.png", _ring(), dpi=(1e8, 1e8))
    _save(f, "no_dpi.png", _ring())
    _save(f, "noise.png", (np.random.default_rng(0).random((400, 400)) > 0.5).astype(np.uint8) * 255, dpi=(254, 254))
    _save(f, "two_loops.png", _ring((400, 800), ((200, 200), (200, 600))), dpi=(254, 254))
    Image.new("1", (20000, 20000), 1).save(f.folder / "huge.png", dpi=(254, 254))  # 20000² pixels, a small file
    f.paths["huge.png"] = str(f.folder / "huge.png")
    return f


# (command line with {name} placeholders, text the one error line must contain)
CASES = [
    ("lap --track nowhere", "track 'nowhere': unknown track"),
    ("lap --track {missing_dir}/t.png", "{missing_dir}/t.png: no such track image"),
    ("lap --track {dir}/", "is a folder, not a regular file"),
    ("lap --track {not_a_png.png}", "unreadable track image"),
    ("lap --track {white.png}", "{white.png}: no dark line"),
    ("lap --track {dpi_1e8.png}", "{dpi_1e8.png}: a scale of"),
    ("lap --track {no_dpi.png}", "{no_dpi.png}: the image has no DPI metadata; give its scale with --metres-per-pixel M"),
    ("convert {mini.urdf} -o {dir}/w.xml --track {no_dpi.png}", "give its scale with --metres-per-pixel M"),
    ("lap --track {no_dpi.png} --metres-per-pixel 1e-300", "{no_dpi.png}: a scale of 1e-300 m per pixel is not a track's"),
    ("lap --track {no_dpi.png} --metres-per-pixel nan", "--metres-per-pixel: 'nan' is outside"),
    ("lap --track {noise.png}", "{noise.png}"),
    ("lap --track {two_loops.png}", "{two_loops.png}: holds 2 separate dark lines"),
    ("tune --track {two_loops.png}", "{two_loops.png}: holds 2 separate dark lines"),
    ("lap --track {huge.png}", "{huge.png}: 400 megapixels is more than the 16 megapixel limit"),
]


@pytest.mark.parametrize("row, needle", CASES, ids=[c[0] for c in CASES])
def test_bad_track_is_one_line_and_exit_2(files, row, needle, capsys):
    check_bad_input(row, needle, files, capsys)


def test_a_fresh_process_never_shows_a_traceback(files):
    check_in_fresh_process(["lap", "--track", files["huge.png"]])
