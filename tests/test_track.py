"""Environment model: built-in tracks, projection, rasterisation and PNG tracks."""

import math

import numpy as np
import pytest
from PIL import Image

from mjcf import MjcfError
from mjcf.track import BUILTIN_SEGMENTS, GROUND_GREY, LINE_GREY, Track, builtin, centre_from_segments
from mjcf.track_image import track_from_png

pytestmark = pytest.mark.quick  # the whole module is in the quick tier (tests/test_tiers.py)


@pytest.mark.parametrize("name", list(BUILTIN_SEGMENTS))
def test_builtin_tracks_close_and_are_counter_clockwise(name):
    t = builtin(name)
    gap = np.hypot(*(t.centre[0] - t.centre[-1]))
    assert gap < 0.001  # the polyline's last point is one sample before the first
    turn = np.sum(np.diff(np.unwrap(np.arctan2(*np.diff(t.centre, axis=0).T[::-1]))))
    assert turn == pytest.approx(2 * math.pi, abs=0.01)


def test_default_track_length_and_radii():
    t = builtin("default")
    assert 5.0 <= t.length_m <= 8.0
    radii = [seg[1] for seg in BUILTIN_SEGMENTS["default"][1] if seg[0] == "A"]
    assert min(radii) == 0.15 and max(radii) == 0.5


def test_segments_that_do_not_close_are_refused():
    with pytest.raises(MjcfError, match="do not close"):
        centre_from_segments("open", [("S", 1.0), ("A", 0.5, 180), ("S", 0.9), ("A", 0.5, 180)])


def test_projection_on_a_circle_is_exact():
    t = builtin("circle")  # centre (0, 0.5), r = 0.5, starting at the origin heading +x
    phi = 0.7
    p = np.array([[0.6 * math.sin(phi), 0.5 - 0.6 * math.cos(phi)]])  # 0.1 m outside the line
    s, d = t.project(p)
    assert s[0] == pytest.approx(0.5 * phi, abs=2e-5)  # 0.5 mm chords: arc length good to ~10 µm
    assert d[0] == pytest.approx(0.1, abs=1e-6)
    assert t.signed_offset(p)[0] == pytest.approx(-0.1, abs=1e-6)  # outside a CCW loop is right of it


def test_start_pose_is_on_the_line_heading_along_it():
    pose = builtin("default").start_pose()
    assert (pose.x, pose.y, pose.yaw) == pytest.approx((0.3, 0.0, 0.0), abs=1e-9)


def test_raster_has_the_line_width_at_one_mm_per_pixel():
    t = builtin("oval")
    tex = t.rasterise(metres_per_pixel=0.001)
    assert tex.metres_per_pixel <= 0.001
    # a column across the first straight (y = 0 at x = 0.6): dark over 19 pixels
    _, col = tex.pixel_of(np.array([0.6, 0.0]))
    row, _ = tex.pixel_of(np.array([0.6, 0.0]))
    column = tex.grey[int(row) - 40 : int(row) + 40, int(col)].astype(float)  # the bottom straight only
    darkness = (GROUND_GREY - column) / (GROUND_GREY - LINE_GREY)
    width_px = darkness[darkness > 0.02].sum()  # coverage-weighted
    assert width_px == pytest.approx(19.0, abs=0.6)
    row, col = tex.pixel_of(np.array([0.6, 0.05]))
    assert tex.grey[int(row), int(col)] == GROUND_GREY


def test_png_round_trip_recovers_the_centre_line(tmp_path):
    t = builtin("default")
    tex = t.rasterise(0.001)
    path = tmp_path / "track.png"
    Image.fromarray(tex.grey).save(path, dpi=(25.4, 25.4))  # 1 mm per pixel
    t2, tex2 = track_from_png(str(path))
    assert tex2.metres_per_pixel == pytest.approx(0.001)
    _, dev = t.project(t2.centre + np.array(tex.origin_xy))
    assert dev.max() < 0.001  # within a pixel
    assert t2.length_m == pytest.approx(t.length_m, rel=0.005)
    assert t2.line_width_m == pytest.approx(0.019, abs=0.0015)


def test_png_without_dpi_needs_a_scale(tmp_path):
    grey = np.full((200, 200), 230, np.uint8)
    yy, xx = np.mgrid[:200, :200]
    r = np.hypot(yy - 100, xx - 100)
    grey[(r > 60) & (r < 70)] = 20
    path = tmp_path / "ring.png"
    Image.fromarray(grey).save(path)
    with pytest.raises(MjcfError, match="no DPI metadata"):
        track_from_png(str(path))
    t, _ = track_from_png(str(path), metres_per_pixel=0.002)
    assert t.length_m == pytest.approx(2 * math.pi * 65 * 0.002, rel=0.01)


def test_unreadable_and_open_line_images_are_refused(tmp_path):
    bad = tmp_path / "bad.png"
    bad.write_bytes(b"not a png")
    with pytest.raises(MjcfError, match="unreadable track image"):
        track_from_png(str(bad), metres_per_pixel=0.001)
    grey = np.full((100, 300), 230, np.uint8)
    grey[45:55, 20:280] = 20  # a straight stripe: no closed line
    open_line = tmp_path / "open.png"
    Image.fromarray(grey).save(open_line)
    with pytest.raises(MjcfError, match="does not close"):
        track_from_png(str(open_line), metres_per_pixel=0.001)


def test_track_rejects_bad_width():
    with pytest.raises(MjcfError, match="line width"):
        Track("x", builtin("circle").centre, line_width_m=float("nan"))


def test_a_track_with_specks_and_a_speckled_tape_is_still_one_line(tmp_path):
    """Dust on the floor and holes in the tape are not other lines: a ring with both traces as before."""
    n = 400
    yy, xx = np.mgrid[:n, :n]
    r = np.hypot(yy - n / 2, xx - n / 2)
    img = np.full((n, n), 240, np.uint8)
    img[(r > 150) & (r < 160)] = 20
    rng = np.random.default_rng(1)
    for y, x in rng.integers(20, n - 20, size=(30, 2)):
        img[y:y + 2, x:x + 2] = 20  # 2×2 px specks of dust
    img[(r > 154) & (r < 156) & (xx > 300)] = 240  # a scratch along the tape
    path = tmp_path / "specks.png"
    Image.fromarray(img).save(path, dpi=(25.4, 25.4))  # 1 mm per pixel
    track, _ = track_from_png(str(path))
    radius_m = np.hypot(*(track.centre - track.centre.mean(axis=0)).T)
    assert np.allclose(radius_m, 0.155, atol=0.002)  # 155 px × 1 mm, by construction
