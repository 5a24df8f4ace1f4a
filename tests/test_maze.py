"""The line maze (mjcf.maze) and how a run through it is judged (twin.core.maze): Pololu's rules (a 6" grid of
3/4" lines, no loops, dead ends, a finish spot), its floor, distances to its lines, the judge's verdicts."""

from __future__ import annotations

import numpy as np
import pytest

from mjcf.maze import GRID_M, SEGMENTS, Maze, shortest_path
from mjcf.track import GROUND_GREY, LINE_GREY
from twin.core import native as core
from twin.core.lap import COL, LapLimits
from twin.core.maze import MazeJudge, judge_for, refuse_maze
from twin.errors import TwinError


@pytest.fixture(scope="module")
def maze():
    return Maze()


def test_the_maze_is_a_tree_on_a_six_inch_grid_with_dead_ends(maze):
    nodes = {n for seg in SEGMENTS for n in seg}
    assert len(SEGMENTS) == len(nodes) - 1  # connected (next line) and without loops
    assert shortest_path(SEGMENTS, (0, 0), (4, 0))[-1] == (4, 0)
    degree = {n: sum(n in seg for seg in SEGMENTS) for n in nodes}
    assert sum(d == 1 for d in degree.values()) == 7  # the start, the finish and five dead ends
    assert all(abs(a[0] - b[0]) + abs(a[1] - b[1]) == 1 for a, b in SEGMENTS)  # neighbours on the grid
    assert GRID_M == pytest.approx(0.1524) and maze.line_width_m == pytest.approx(0.019)
    assert maze.solution_m == pytest.approx(8 * GRID_M)
    start = maze.start_pose()
    assert (start.x, start.y) == (0.0, 0.0) and start.yaw == pytest.approx(np.pi / 2)


def test_distances_and_the_finish_spot(maze):
    pts = np.array([[0.0, 0.05], [0.03, 0.1], [GRID_M / 2, GRID_M / 2], [4 * GRID_M + 0.05, 0.0]])
    assert maze.distance(pts) == pytest.approx([0.0, 0.03, GRID_M / 2, 0.0])
    assert maze.at_finish(pts).tolist() == [False, False, False, True]


def test_the_floor_shows_lines_the_spot_and_ground_between(maze):
    tex = maze.rasterise(0.001)
    grey = lambda x, y: tex.grey[tuple(int(v) for v in tex.pixel_of(np.array([x, y])))]  # noqa: E731
    assert grey(0.0, 0.05) == LINE_GREY and grey(4 * GRID_M + 0.04, 0.02) == LINE_GREY  # a line, the spot
    assert grey(GRID_M / 2, GRID_M / 2) == GROUND_GREY and grey(4 * GRID_M, -0.1) == GROUND_GREY


def records(xy: np.ndarray, dt: float = 0.01) -> np.ndarray:
    rec = np.zeros((len(xy), core.RECORD_WORDS))
    rec[:, COL["time_s"]] = np.arange(len(xy)) * dt
    rec[:, COL["x_m"]], rec[:, COL["y_m"]] = xy[:, 0], xy[:, 1]
    rec[:, COL["energy_j"]] = np.arange(len(xy)) * 0.1
    return rec


def along(points, step: float = 0.005) -> np.ndarray:
    pts = [np.linspace(a, b, max(2, int(np.hypot(*np.subtract(b, a)) / step)), endpoint=False)
           for a, b in zip(points[:-1], points[1:])]
    return np.concatenate(pts + [np.array(points[-1:], dtype=float)])


def test_the_judge_ends_the_run_at_the_finish_spot(maze):
    path = np.array(shortest_path(SEGMENTS, (0, 0), (4, 0)), dtype=float) * GRID_M
    detour = [(0, 0), (0, GRID_M), (0, 3 * GRID_M), (0, GRID_M), *path[1:]]  # up a branch and back: not a failure
    judge = judge_for(maze, LapLimits(), True)
    assert isinstance(judge, MazeJudge)
    rec = records(along(detour))
    judge.feed(rec[:100])
    judge.feed(rec[100:])
    r = judge.result(5, [], [], {})
    assert r.completed and r.detail == "finish reached"
    inside = np.flatnonzero(maze.at_finish(rec[:, [COL["x_m"], COL["y_m"]]]))[0]
    assert r.lap_time_s == rec[inside, COL["time_s"]] and r.track_length_m == maze.solution_m
    assert r.distance_m == pytest.approx(4 * GRID_M + 8 * GRID_M - maze.finish_radius_m, abs=0.01)
    assert r.max_cross_track_m < 1e-9 and len(r.trace.records) == inside + 1


def test_leaving_every_line_or_running_out_of_time_fails(maze):
    off = MazeJudge(maze, LapLimits(max_cross_track_m=0.1))
    off.feed(records(along([(0, 0), (0, GRID_M / 2), (-0.2, GRID_M / 2)])))
    r = off.result(5, [], [], {})
    assert r.failure == "off_track" and "every line of the maze" in r.detail
    slow = MazeJudge(maze, LapLimits(timeout_s=0.5))
    slow.feed(records(along([(0, 0), (0, GRID_M)], step=0.001)))
    assert slow.result(5, [], [], {}).failure == "timeout"
    with pytest.raises(TwinError, match="has no maze strategy"):
        refuse_maze(maze, "the twin's controller")
