"""A track from a PNG of a dark line on a light ground.

The physical scale comes from the PNG's DPI metadata or an explicit metres-per-pixel. The centre line is
the curve midway between the line's two edges: with the dark ring's inside (the hole it encloses) and
outside known, it is the zero level of (distance to outside − distance to inside), traced with sub-pixel
accuracy by contourpy (marching squares). scipy.ndimage gives the labels, hole filling and distances.
"""

from __future__ import annotations

import math
import os

import contourpy
import numpy as np
from PIL import Image, UnidentifiedImageError
from scipy import ndimage

from mjcf.errors import MjcfError
from mjcf.track import FloorTexture, Track

INCH = 0.0254


def read_grey(path: str) -> tuple[np.ndarray, float | None]:
    """(grey levels (H, W) uint8, metres per pixel from DPI or None)."""
    try:
        with Image.open(path) as img:
            img.load()
            dpi = img.info.get("dpi")
            grey = np.asarray(img.convert("L"), dtype=np.uint8)
    except FileNotFoundError:
        raise MjcfError(f"{path}: track image not found") from None
    except (UnidentifiedImageError, OSError, ValueError) as e:
        raise MjcfError(f"{path}: unreadable track image ({e.__class__.__name__})") from None
    mpp = None
    if dpi and float(dpi[0]) > 1.0:  # PIL reports (72, 72) or (1, 1) style defaults for "no real DPI" poorly;
        mpp = INCH / float(dpi[0])  # a DPI of at least 2 is taken as meant
    return grey, mpp


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
        raise MjcfError(f"{path}: the image has no DPI metadata; give its scale (metres per pixel)")
    if not (math.isfinite(mpp) and 0 < mpp <= 0.01):
        raise MjcfError(f"{path}: metres per pixel must be in (0, 0.01], got {mpp!r}")
    lo, hi = np.percentile(grey, [1, 99])
    if hi - lo < 40:
        raise MjcfError(f"{path}: no dark line on a light ground (contrast {hi - lo:.0f} grey levels)")
    dark = grey < (lo + hi) / 2
    labels, n = ndimage.label(dark)
    if n == 0:
        raise MjcfError(f"{path}: no dark line found")
    sizes = ndimage.sum_labels(dark, labels, index=np.arange(1, n + 1))
    ring = labels == (1 + int(np.argmax(sizes)))
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
    width = line_width_m if line_width_m is not None else float(ring.sum()) * mpp * mpp / _length(xy)
    track = Track(name, xy, line_width_m=width, start_index=_straightest(xy))
    return track, FloorTexture(grey, (0.0, 0.0), mpp)


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
