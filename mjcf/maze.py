"""A line maze as Pololu builds them for the 3pi (``--track maze``): lines of 3/4" tape on a square grid, with dead
ends, no loops, and a large black spot at the finish.

Pololu, "Building Line Following and Line Maze Courses" (https://www.pololu.com/docs/0J22), section 4: the
segments lie on a grid (3" on a single posterboard; "our favorite maze is an 8'x8' course, using a 6" grid"), the
lines are 3/4" electrical tape, and a maze without loops can be solved by the "left hand on the wall" strategy;
the 3pi's maze solver (libpololu-avr, examples_templates/3pi-mazesolver) stops where its three middle sensors all
see black, a spot wider than the line. This maze uses the 6" grid, 18 nodes and 17 segments (a tree: no loops) with
five dead ends, the start at a dead end and the finish spot (12 cm across) at another.

A :class:`Maze` is a :class:`mjcf.track.Track` whose centre line runs from the start to the finish and back (the
twin's C core needs a closed line; the way there is the maze's shortest path), whose floor shows every segment and
the spot, and which answers how far a point is from the nearest line (:meth:`Maze.distance`) and whether it is on
the finish spot (:meth:`Maze.at_finish`).
"""

from __future__ import annotations

import collections
import math

import numpy as np

from mjcf.errors import MjcfError
from mjcf.track import GROUND_GREY, LINE_GREY, LINE_WIDTH_M, SAMPLE_SPACING_M, FloorTexture, Track

GRID_M = 6 * 0.0254  # Pololu's favourite maze: a 6" grid
FINISH_DIAMETER_M = 0.12
# (x, y) grid nodes of each segment; start at (0, 0) heading north, finish at (4, 0)
SEGMENTS = (
    ((0, 0), (0, 1)), ((0, 1), (1, 1)), ((1, 1), (2, 1)), ((0, 1), (0, 2)), ((0, 2), (0, 3)), ((0, 3), (1, 3)),
    ((1, 1), (1, 2)), ((2, 1), (2, 0)), ((2, 1), (2, 2)), ((2, 2), (2, 3)), ((2, 3), (3, 3)), ((3, 3), (4, 3)),
    ((2, 2), (3, 2)), ((3, 2), (3, 1)), ((3, 1), (4, 1)), ((4, 1), (4, 0)), ((3, 1), (3, 0)),
)
START, FINISH = (0, 0), (4, 0)


def shortest_path(segments, start, finish) -> list:
    """The nodes from ``start`` to ``finish`` (breadth first: in a maze without loops, the only path)."""
    links = collections.defaultdict(list)
    for a, b in segments:
        links[a].append(b)
        links[b].append(a)
    came = {start: None}
    todo = collections.deque([start])
    while todo:
        node = todo.popleft()
        for nxt in links[node]:
            if nxt not in came:
                came[nxt] = node
                todo.append(nxt)
    if finish not in came:
        raise MjcfError(f"maze: no path from {start} to {finish}")
    path = [finish]
    while path[-1] != start:
        path.append(came[path[-1]])
    return path[::-1]


def _dense(a: np.ndarray, b: np.ndarray, endpoint: bool = False) -> np.ndarray:
    n = max(1, int(math.ceil(np.hypot(*(b - a)) / SAMPLE_SPACING_M)))
    f = np.linspace(0.0, 1.0, n + 1 if endpoint else n, endpoint=endpoint)[:, None]
    return a + f * (b - a)


class Maze(Track):
    """A line maze on a grid (module docstring); lengths in [m]."""

    def __init__(self, name: str = "maze", segments=SEGMENTS, start=START, finish=FINISH, grid_m: float = GRID_M,
                 line_width_m: float = LINE_WIDTH_M, finish_diameter_m: float = FINISH_DIAMETER_M):
        self.segments_xy = np.array([[a, b] for a, b in segments], dtype=float) * grid_m  # (n, 2 ends, 2)
        path = np.array(shortest_path(segments, start, finish), dtype=float) * grid_m
        there = np.concatenate([_dense(a, b) for a, b in zip(path[:-1], path[1:])] + [path[-1:]])
        back = there[-2:0:-1]  # the way back, ending one sample before the start (the line closes on it)
        super().__init__(name, np.concatenate([there, back]), line_width_m=line_width_m)
        self.solution_m = float(np.sum(np.hypot(*(path[1:] - path[:-1]).T)))
        self.finish_xy = path[-1]
        self.finish_radius_m = finish_diameter_m / 2

    def __repr__(self) -> str:
        return f"Maze({self.name!r}, {len(self.segments_xy)} segments, shortest path {self.solution_m:.3f} m)"

    def distance(self, xy: np.ndarray) -> np.ndarray:
        """Distance [m] from each point (..., 2) to the nearest line of the maze (0 on the finish spot)."""
        xy = np.asarray(xy, dtype=float)
        a, b = self.segments_xy[:, 0], self.segments_xy[:, 1]
        d = b - a
        p = xy[..., None, :] - a
        t = np.clip(np.sum(p * d, axis=-1) / np.sum(d * d, axis=-1), 0.0, 1.0)
        lines = np.min(np.hypot(*np.moveaxis(p - t[..., None] * d, -1, 0)), axis=-1)
        return np.where(self.at_finish(xy), 0.0, lines)

    def at_finish(self, xy: np.ndarray) -> np.ndarray:
        """Whether each point (..., 2) lies on the finish spot."""
        xy = np.asarray(xy, dtype=float)
        return np.hypot(*np.moveaxis(xy - self.finish_xy, -1, 0)) <= self.finish_radius_m

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        pts = self.segments_xy.reshape(-1, 2)
        r = self.finish_radius_m
        return np.minimum(pts.min(axis=0), self.finish_xy - r), np.maximum(pts.max(axis=0), self.finish_xy + r)

    def _dense_centre(self) -> np.ndarray:  # what the floor shows: every segment
        return np.concatenate([_dense(a, b, endpoint=True) for a, b in self.segments_xy])

    def rasterise(self, metres_per_pixel: float = 0.001, margin_m: float = 0.3) -> FloorTexture:
        """The segments as :meth:`Track.rasterise` draws a line, and the finish spot, anti-aliased over one pixel."""
        tex = super().rasterise(metres_per_pixel, margin_m)
        h, w = tex.grey.shape
        r0, c0 = tex.pixel_of(self.finish_xy + self.finish_radius_m + metres_per_pixel)
        r1, c1 = tex.pixel_of(self.finish_xy - self.finish_radius_m - metres_per_pixel)
        rr, cc = np.mgrid[max(0, int(r0)): min(h, int(r1) + 1), max(0, int(c1)): min(w, int(c0) + 1)]
        x = tex.origin_xy[0] + (cc + 0.5) * metres_per_pixel
        y = tex.origin_xy[1] + (h - rr - 0.5) * metres_per_pixel
        dist = np.hypot(x - self.finish_xy[0], y - self.finish_xy[1])
        cover = np.clip((self.finish_radius_m - dist) / metres_per_pixel + 0.5, 0.0, 1.0)
        spot = np.round(GROUND_GREY - cover * (GROUND_GREY - LINE_GREY)).astype(np.uint8)
        tex.grey[rr, cc] = np.minimum(tex.grey[rr, cc], spot)
        return tex


def maze_track(line_width_m: float = LINE_WIDTH_M) -> Maze:
    """The built-in maze (module docstring)."""
    return Maze(line_width_m=line_width_m)
