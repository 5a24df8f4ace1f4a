"""Environment partial model: a closed line-following track.

A track is a closed centre line (a dense polyline in world metres, counter-clockwise) and a line width.
It answers what the lap runner and the sensor need: the start pose, the arc-length progress of a point,
its distance from the line, and a floor texture (dark line on a light ground) at a known scale.

Built-in tracks are sequences of straights and circular arcs (exact radii); any PNG of a dark line on a
light ground is also a track, its centre line extracted from the image (:mod:`mjcf.track_image`).
"""

from __future__ import annotations

import dataclasses
import functools
import math

import numpy as np
from scipy.spatial import cKDTree

from lf_common.errors import InputTooLarge
from mjcf.errors import MjcfError

# the largest floor texture: at about 40 bytes a pixel through reading, tracing and the world, 16 MP is ≈ 0.6 GB,
# and 4 × 4 m at 1 mm per pixel (twice that at 2 mm), more than a line-follower track needs
MAX_TEXTURE_PIXELS = 16_000_000
LINE_WIDTH_M = 0.019  # 3/4" electrical tape, the usual line-follower track (Pololu, RoboGames rules)
SAMPLE_SPACING_M = 0.0005  # centre-line polyline spacing; chord error < 0.2 µm at r = 0.15 m
GROUND_GREY = 235  # reflectance of white board, 8-bit grey level
LINE_GREY = 20  # reflectance of black tape, 8-bit grey level


@dataclasses.dataclass(frozen=True)
class Pose2D:
    """x, y in [m], yaw in [rad] (0 = +x, counter-clockwise positive)."""

    x: float
    y: float
    yaw: float


@dataclasses.dataclass(frozen=True)
class FloorTexture:
    """A grey-level image of the floor and where it lies in the world.

    Attributes:
      grey: (H, W) uint8, row 0 at the top (largest y).
      origin_xy: world (x, y) in [m] of the image's lower-left corner.
      metres_per_pixel: pixel pitch in [m].
    """

    grey: np.ndarray
    origin_xy: tuple[float, float]
    metres_per_pixel: float

    @property
    def size_m(self) -> tuple[float, float]:
        h, w = self.grey.shape
        return w * self.metres_per_pixel, h * self.metres_per_pixel

    def pixel_of(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(row, col) float pixel coordinates of world points (..., 2); pixel centres are at .5."""
        xy = np.asarray(xy, dtype=float)
        col = (xy[..., 0] - self.origin_xy[0]) / self.metres_per_pixel
        row = self.grey.shape[0] - (xy[..., 1] - self.origin_xy[1]) / self.metres_per_pixel
        return row, col


class Track:
    """A closed centre line of width ``line_width_m``.

    Args:
      name: a short name for logs and file names.
      centre: (N, 2) closed polyline in [m], first point not repeated, dense (≤ 2 mm spacing).
      line_width_m: width of the dark line in [m].
      start_index: index into ``centre`` of the start/finish line.
    """

    def __init__(self, name: str, centre: np.ndarray, line_width_m: float = LINE_WIDTH_M, start_index: int = 0):
        centre = np.asarray(centre, dtype=float)
        if centre.ndim != 2 or centre.shape[1] != 2 or len(centre) < 16:
            raise MjcfError(f"track {name}: centre line must be (N>=16, 2), got {centre.shape}")
        if not np.all(np.isfinite(centre)):
            raise MjcfError(f"track {name}: centre line has non-finite points")
        if not (math.isfinite(line_width_m) and 0.002 <= line_width_m <= 0.1):
            raise MjcfError(f"track {name}: line width must be in [0.002, 0.1] m, got {line_width_m!r}")
        # orient counter-clockwise (shoelace area > 0) so "left of the line" is the inside
        area = 0.5 * np.sum(centre[:, 0] * np.roll(centre[:, 1], -1) - np.roll(centre[:, 0], -1) * centre[:, 1])
        if area < 0:
            centre = centre[::-1]
            start_index = len(centre) - 1 - start_index
        self.name = name
        self.centre = np.roll(centre, -start_index, axis=0)  # the start is vertex 0
        self.line_width_m = float(line_width_m)
        seg = np.roll(self.centre, -1, axis=0) - self.centre
        self._seg = seg
        self._seg_len = np.hypot(seg[:, 0], seg[:, 1])
        if np.any(self._seg_len == 0):
            raise MjcfError(f"track {name}: centre line has repeated points")
        self.arc_length = np.concatenate([[0.0], np.cumsum(self._seg_len)])  # (N+1,), [m]
        self.length_m = float(self.arc_length[-1])
        self._tree = cKDTree(self.centre)

    def __repr__(self) -> str:
        return f"Track({self.name!r}, length={self.length_m:.3f} m, width={self.line_width_m * 1000:.0f} mm)"

    def start_pose(self) -> Pose2D:
        """Pose on the start line, heading along the track."""
        d = self._seg[0]
        return Pose2D(float(self.centre[0, 0]), float(self.centre[0, 1]), math.atan2(d[1], d[0]))

    def _segment_of(self, s: np.ndarray) -> np.ndarray:
        """Index of the segment holding arc length ``s`` (already wrapped to [0, length))."""
        return np.clip(np.searchsorted(self.arc_length, s, side="right") - 1, 0, len(self.centre) - 1)

    def point_at(self, s: np.ndarray) -> np.ndarray:
        """Centre-line points (..., 2) at arc lengths ``s`` in [m] (wrapped to the lap)."""
        s = np.mod(np.asarray(s, dtype=float), self.length_m)
        i = self._segment_of(s)
        f = (s - self.arc_length[i]) / self._seg_len[i]
        return self.centre[i] + f[..., None] * self._seg[i]

    def project(self, xy: np.ndarray, window: int = 8) -> tuple[np.ndarray, np.ndarray]:
        """Arc-length progress in [0, length) and unsigned distance from the centre line, both in [m].

        The nearest vertex is found with a k-d tree, then the exact nearest point on the segments
        ``window`` vertices either side of it.
        """
        xy = np.atleast_2d(np.asarray(xy, dtype=float))
        _, idx = self._tree.query(xy)
        n = len(self.centre)
        cand = (idx[:, None] + np.arange(-window, window)[None, :]) % n  # (M, 2w)
        a = self.centre[cand]
        d = self._seg[cand]
        t = np.clip(np.einsum("mkj,mkj->mk", xy[:, None, :] - a, d) / self._seg_len[cand] ** 2, 0.0, 1.0)
        p = a + t[..., None] * d
        dist = np.hypot(*(xy[:, None, :] - p).transpose(2, 0, 1))
        k = np.argmin(dist, axis=1)
        rows = np.arange(len(xy))
        s = self.arc_length[cand[rows, k]] + t[rows, k] * self._seg_len[cand[rows, k]]
        return np.mod(s, self.length_m), dist[rows, k]

    def locate(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Arc-length progress in [0, length) and signed distance from the centre line (+ on the left), in [m]."""
        xy = np.atleast_2d(np.asarray(xy, dtype=float))
        s, dist = self.project(xy)
        p = self.point_at(s)
        d = self._seg[self._segment_of(s)]
        cross = d[:, 0] * (xy[:, 1] - p[:, 1]) - d[:, 1] * (xy[:, 0] - p[:, 0])
        return s, np.where(cross >= 0, dist, -dist)

    def signed_offset(self, xy: np.ndarray) -> np.ndarray:
        """Distance from the centre line in [m], positive on the left (inside of a CCW track)."""
        return self.locate(xy)[1]

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """(min_xy, max_xy) of the centre line in [m]."""
        return self.centre.min(axis=0), self.centre.max(axis=0)

    def rasterise(self, metres_per_pixel: float = 0.001, margin_m: float = 0.3) -> FloorTexture:
        """A floor texture of the track: the dark line, anti-aliased over one pixel, on a light ground.

        Only pixels near the line are measured: a k-d tree of the centre line answers each one's distance.
        """
        if not (0 < metres_per_pixel <= 0.001):
            raise MjcfError(f"track {self.name}: texture resolution must be at most 1 mm per pixel")
        lo, hi = self.bounds()
        lo = lo - margin_m
        hi = hi + margin_m
        w = int(math.ceil((hi[0] - lo[0]) / metres_per_pixel))
        h = int(math.ceil((hi[1] - lo[1]) / metres_per_pixel))
        if w * h > MAX_TEXTURE_PIXELS:
            raise InputTooLarge(
                f"track {self.name}: its floor at {metres_per_pixel * 1000:g} mm per pixel is {w}×{h} px, more than the "
                f"{MAX_TEXTURE_PIXELS / 1e6:g} megapixel limit; use a coarser environment.texture_resolution (at least "
                f"{metres_per_pixel * math.sqrt(w * h / MAX_TEXTURE_PIXELS) * 1000:.2f} mm)")
        grey = np.full((h, w), GROUND_GREY, dtype=np.uint8)
        tex = FloorTexture(grey, (float(lo[0]), float(lo[1])), metres_per_pixel)
        half = self.line_width_m / 2
        reach = half + 2 * metres_per_pixel
        dense = self._dense_centre()
        tree = cKDTree(dense)
        # candidate pixels: boxes around 5 cm chunks of the centre line
        rows, cols = [], []
        chunk = max(1, int(0.05 / SAMPLE_SPACING_M))
        for k in range(0, len(dense), chunk):
            part = dense[k : k + chunk + 1]
            r0, c0 = tex.pixel_of(part.min(axis=0) - reach)
            r1, c1 = tex.pixel_of(part.max(axis=0) + reach)
            rr, cc = np.mgrid[max(0, int(r1)) : min(h, int(r0) + 1), max(0, int(c0)) : min(w, int(c1) + 1)]
            rows.append(rr.ravel())
            cols.append(cc.ravel())
        flat = np.unique(np.concatenate(rows) * w + np.concatenate(cols))
        r, c = np.divmod(flat, w)
        x = lo[0] + (c + 0.5) * metres_per_pixel
        y = lo[1] + (h - r - 0.5) * metres_per_pixel
        dist, _ = tree.query(np.stack([x, y], axis=1), distance_upper_bound=reach)
        near = np.isfinite(dist)
        # coverage of the pixel by the line, linear over one pixel across the edge
        cover = np.clip((half - dist[near]) / metres_per_pixel + 0.5, 0.0, 1.0)
        grey[r[near], c[near]] = np.round(GROUND_GREY - cover * (GROUND_GREY - LINE_GREY)).astype(np.uint8)
        return tex

    def _dense_centre(self) -> np.ndarray:
        n = max(len(self.centre), int(math.ceil(self.length_m / SAMPLE_SPACING_M)))
        return self.point_at(np.linspace(0.0, self.length_m, n, endpoint=False))


# ---------------------------------------------------------------------------------------------------------
# Built-in tracks: straights ("S", length_m) and arcs ("A", radius_m, angle_deg, + = left turn)


def centre_from_segments(name: str, segments: list[tuple], spacing: float = SAMPLE_SPACING_M) -> np.ndarray:
    """Walk straights and arcs from (0, 0) heading +x; the walk must close on itself (1 µm, 1e-6 rad)."""
    pts = []
    p = np.zeros(2)
    heading = 0.0
    for seg in segments:
        if seg[0] == "S":
            length = seg[1]
            n = max(1, int(round(length / spacing)))
            u = np.array([math.cos(heading), math.sin(heading)])
            pts.append(p + np.outer(np.arange(n) / n * length, u))
            p = p + length * u
        elif seg[0] == "A":
            r, angle = seg[1], math.radians(seg[2])
            side = math.copysign(1.0, angle)
            c = p + side * r * np.array([-math.sin(heading), math.cos(heading)])
            n = max(2, int(round(r * abs(angle) / spacing)))
            th = heading + np.arange(n) / n * angle
            pts.append(c - side * r * np.stack([-np.sin(th), np.cos(th)], axis=1))
            heading += angle
            p = c - side * r * np.array([-math.sin(heading), math.cos(heading)])
        else:
            raise MjcfError(f"track {name}: unknown segment {seg!r}")
    turn = math.remainder(heading, 2 * math.pi)
    if np.hypot(*p) > 1e-6 or abs(turn) > 1e-6:
        raise MjcfError(f"track {name}: segments do not close (end at {p.round(6)}, heading {math.degrees(heading):.3f}°)")
    return np.concatenate(pts)


BUILTIN_SEGMENTS: dict[str, tuple[str, list[tuple]]] = {
    # ~6.3 m: a long straight, sweepers of 0.5/0.4/0.35 m, a 0.15 m S-bend and a 0.2 m hairpin
    "default": (
        "Mixed circuit, 0.15–0.5 m radii",
        [
            ("S", 0.6), ("A", 0.5, 90), ("S", 0.3), ("A", 0.25, 90), ("A", 0.15, -90), ("A", 0.15, 90),
            ("S", 0.25), ("A", 0.3, 90), ("S", 0.75), ("A", 0.2, -180), ("S", 0.1), ("A", 0.35, 180),
            ("A", 0.4, 90), ("S", 0.7),
        ],
    ),
    "oval": ("Oval, 1.2 m straights, 0.4 m radius", [("S", 1.2), ("A", 0.4, 180), ("S", 1.2), ("A", 0.4, 180)]),
    "circle": ("Circle of 0.5 m radius", [("A", 0.5, 360)]),
    "chicane": (
        "Square-ish loop with 0.15 m corners and two S-bends",
        [
            ("S", 0.5), ("A", 0.15, 45), ("A", 0.15, -45), ("S", 0.2), ("A", 0.15, -45), ("A", 0.15, 45),
            ("S", 0.5), ("A", 0.15, 90), ("S", 0.8), ("A", 0.15, 90), ("S", 0.5), ("A", 0.15, 45),
            ("A", 0.15, -45), ("S", 0.2), ("A", 0.15, -45), ("A", 0.15, 45), ("S", 0.5), ("A", 0.15, 90),
            ("S", 0.8), ("A", 0.15, 90),
        ],
    ),
}


@functools.lru_cache(maxsize=16)
def builtin(name: str) -> Track:
    """A built-in track by name (see ``BUILTIN_SEGMENTS``)."""
    if name not in BUILTIN_SEGMENTS:
        raise MjcfError(f"track {name!r}: unknown track; built-in tracks are {', '.join(BUILTIN_SEGMENTS)}")
    _, segments = BUILTIN_SEGMENTS[name]
    centre = centre_from_segments(name, segments)
    # start in the middle of the first straight, so the start line is not on a curve
    first = segments[0]
    start = int(round(first[1] / 2 / SAMPLE_SPACING_M)) if first[0] == "S" else 0
    return Track(name, centre, start_index=start)
