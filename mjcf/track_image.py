"""A track from a PNG of a dark line on a light ground.

The physical scale comes from the PNG's DPI metadata or an explicit metres-per-pixel, and must lie between
``MIN_METRES_PER_PIXEL`` and ``MAX_METRES_PER_PIXEL`` (0.1–10 mm: tape on a floor, photographed or drawn).
An image larger than ``mjcf.track.MAX_TEXTURE_PIXELS`` is refused from its header, before it is decoded (the
pipeline needs about 40 bytes a pixel: 23–35 measured for reading and tracing, plus the world's RGB copy).
The image must hold exactly one closed line: a second line of comparable size, or a "line" whose pixels lie
far from the centre traced through it (noise, a filled blob), is refused rather than silently half-used. The centre line is
the curve midway between the line's two edges: with the dark ring's inside (the hole it encloses) and
outside known, it is the zero level of (distance to outside − distance to inside), traced with sub-pixel
accuracy by contourpy (marching squares). scipy.ndimage gives the labels, hole filling and distances.
"""

from __future__ import annotations

import math
import os
import re

import contourpy
import numpy as np
from PIL import Image, UnidentifiedImageError
from scipy import ndimage
from scipy.spatial import cKDTree

from lf_common.errors import InputTooLarge
from lf_common.files import input_file
from mjcf.errors import MjcfError
from mjcf.track import MAX_TEXTURE_PIXELS, FloorTexture, Track

INCH = 0.0254
MIN_METRES_PER_PIXEL, MAX_METRES_PER_PIXEL = 1e-4, 0.01
OTHER_LINE_FRACTION = 0.1  # a second dark region this large against the line is another line, not a speck
WIDTH_SLACK_PX = 2.0  # a line's pixels lie within half its mean width of its centre, give or take this


def read_grey(path: str) -> tuple[np.ndarray, float | None]:
    """(grey levels (H, W) uint8, metres per pixel from DPI or None)."""
    input_file(path, "track image")  # a FIFO would block the image reader for ever
    try:
        with Image.open(path) as img:  # reads the header only: the size is known before any pixel is decoded
            w, h = img.size
            if w * h > MAX_TEXTURE_PIXELS:
                raise InputTooLarge(_too_large(path, w, h))
            img.load()
            dpi = img.info.get("dpi")
            grey = np.asarray(img.convert("L"), dtype=np.uint8)
    except Image.DecompressionBombError as e:  # refused by Pillow's own limit, before its size reached us
        pixels = [int(n) for n in re.findall(r"\d+", str(e))[:1]]
        raise InputTooLarge(_too_large(path, pixels[0] if pixels else 0, 1)) from None
    except (UnidentifiedImageError, OSError, ValueError) as e:
        raise MjcfError(f"{path}: unreadable track image ({e.__class__.__name__})") from None
    mpp = None
    if dpi and float(dpi[0]) > 1.0:  # PIL reports (72, 72) or (1, 1) style defaults for "no real DPI" poorly;
        mpp = INCH / float(dpi[0])  # a DPI of at least 2 is taken as meant
    return grey, mpp


def _too_large(path: str, w: int, h: int) -> str:
    scale = math.sqrt(MAX_TEXTURE_PIXELS / (w * h)) if w * h > MAX_TEXTURE_PIXELS else 0.5  # 0.5: size unknown
    size = f"{w}×{h} px" if h > 1 else (f"{w / 1e6:.0f} megapixels" if w else "the image")
    return (f"{path}: {size} is more than the {MAX_TEXTURE_PIXELS / 1e6:g} megapixel limit (about 40 bytes a pixel "
            f"in memory); downsample it to {int(scale * 100)} % or less and keep its scale right (the DPI metadata "
            f"scaled with it, or --metres-per-pixel)")


def track_from_png(path: str, metres_per_pixel: float | None = None, line_width_m: float | None = None) -> tuple[Track, FloorTexture]:
    """Read a track image; returns the track (centre line in metres, origin at the image's lower-left) and its texture.

    Args:
      path: PNG (or any Pillow-readable) image of one closed dark line on a light ground.
      metres_per_pixel: the image's scale in [m]; required when the file has no DPI metadata.
      line_width_m: the line's width in [m]; measured from the image when None.
    """
    grey, mpp_dpi = read_grey(path)
    mpp = metres_per_pixel if metres_per_pixel is not None else mpp_dpi
    name = os.path.splitext(os.path.basename(path))[0]
    if mpp is None:
        raise MjcfError(f"{path}: the image has no DPI metadata; give its scale with --metres-per-pixel M "
                        "(e.g. 0.001 for 1 mm a pixel)")
    if not (math.isfinite(mpp) and MIN_METRES_PER_PIXEL * (1 - 1e-9) <= mpp <= MAX_METRES_PER_PIXEL * (1 + 1e-9)):
        raise MjcfError(f"{path}: a scale of {mpp!r} m per pixel is not a track's (expected {MIN_METRES_PER_PIXEL * 1000:g}–"
                        f"{MAX_METRES_PER_PIXEL * 1000:g} mm per pixel); check the DPI metadata or --metres-per-pixel")
    lo, hi = np.percentile(grey, [1, 99])
    if hi - lo < 40:
        raise MjcfError(f"{path}: no dark line on a light ground (contrast {hi - lo:.0f} grey levels)")
    dark = grey < (lo + hi) / 2
    labels, n = ndimage.label(dark)
    if n == 0:
        raise MjcfError(f"{path}: no dark line found")
    sizes = ndimage.sum_labels(dark, labels, index=np.arange(1, n + 1))
    order = np.argsort(sizes)[::-1]
    if n > 1 and sizes[order[1]] > OTHER_LINE_FRACTION * sizes[order[0]]:
        others = int(np.sum(sizes > OTHER_LINE_FRACTION * sizes[order[0]])) - 1
        raise MjcfError(f"{path}: holds {others + 1} separate dark lines or regions of comparable size; a track is one "
                        "closed line (crop or paint out the others)")
    ring = labels == (1 + int(order[0]))
    filled = ndimage.binary_fill_holes(ring)
    inside = filled & ~ring
    if inside.sum() < 100:
        raise MjcfError(f"{path}: the line does not close on itself (no enclosed area)")
    # keep the largest enclosed region: small holes are specks in the tape, not the track's inside
    ilab, ni = ndimage.label(inside)
    isz = ndimage.sum_labels(inside, ilab, index=np.arange(1, ni + 1))
    inside = ilab == (1 + int(np.argmax(isz)))
    outside = ~filled
    d_in = ndimage.distance_transform_edt(~inside)
    d_out = ndimage.distance_transform_edt(~outside)
    field = d_out - d_in  # > 0 nearer the inside, 0 midway across the line
    lines = contourpy.contour_generator(z=field, line_type=contourpy.LineType.Separate).lines(0.0)
    if not lines:
        raise MjcfError(f"{path}: could not trace the line's centre")
    rc = max(lines, key=len)  # (col, row) pixel coordinates, pixel centres at integers
    if np.hypot(*(rc[0] - rc[-1])) < 1e-9:
        rc = rc[:-1]
    h = grey.shape[0]
    xy = np.stack([(rc[:, 0] + 0.5) * mpp, (h - rc[:, 1] - 0.5) * mpp], axis=1)
    xy = _resample(xy, spacing=min(0.001, mpp))
    _check_single_line(path, ring, rc, h)
    width = line_width_m if line_width_m is not None else float(ring.sum()) * mpp * mpp / _length(xy)
    track = Track(name, xy, line_width_m=width, start_index=_straightest(xy))
    return track, FloorTexture(grey, (0.0, 0.0), mpp)


def _check_single_line(path: str, ring: np.ndarray, centre_rc: np.ndarray, h: int) -> None:
    """The dark region must be a line around its traced centre: its pixels within about half its mean width."""
    length_px = float(np.sum(np.hypot(*(np.roll(centre_rc, -1, axis=0) - centre_rc).T)))
    half_width = float(ring.sum()) / max(length_px, 1.0) / 2
    rows, cols = np.nonzero(ring)
    distance, _ = cKDTree(np.column_stack([centre_rc[:, 1], centre_rc[:, 0]])).query(np.column_stack([rows, cols]))
    far = float(np.percentile(distance, 99))
    if far > 2 * half_width + WIDTH_SLACK_PX:
        raise MjcfError(f"{path}: the dark region is not one line of even width (1 % of it lies {far:.0f} px from its "
                        f"centre, against a half width of {half_width:.1f} px): noise, a filled shape or branches")


def _length(xy: np.ndarray) -> float:
    return float(np.sum(np.hypot(*(np.roll(xy, -1, axis=0) - xy).T)))


def _resample(xy: np.ndarray, spacing: float) -> np.ndarray:
    """Resample a closed polyline at (nearly) even arc-length spacing."""
    seg = np.hypot(*(np.roll(xy, -1, axis=0) - xy).T)
    keep = seg > 0
    xy, seg = xy[keep], seg[keep]
    s = np.concatenate([[0.0], np.cumsum(seg)])
    n = max(16, int(s[-1] / spacing))
    t = np.linspace(0.0, s[-1], n, endpoint=False)
    closed = np.vstack([xy, xy[:1]])
    return np.stack([np.interp(t, s, closed[:, 0]), np.interp(t, s, closed[:, 1])], axis=1)


def _straightest(xy: np.ndarray, window_m: float = 0.1) -> int:
    """Index of the point with the least heading change over ±window_m: the start line goes there."""
    d = np.roll(xy, -1, axis=0) - xy
    heading = np.unwrap(np.arctan2(d[:, 1], d[:, 0]))
    spacing = _length(xy) / len(xy)
    k = max(1, int(window_m / spacing))
    total = heading[-1] - heading[0] + (np.arctan2(*d[0][::-1]) - np.arctan2(*d[-1][::-1]))
    ext = np.concatenate([heading[-k:] - total, heading, heading[:k] + total])
    change = np.abs(ext[2 * k :] - ext[: -2 * k])
    return int(np.argmin(change))
