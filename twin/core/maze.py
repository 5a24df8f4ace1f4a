"""Judging a run through a line maze (:class:`mjcf.maze.Maze`) from the trace, by the physics: the run is done when
the robot's centre of rotation reaches the finish spot (its time, to the trace's step), and fails when the robot
is more than ``max_cross_track_m`` from every line of the maze (``off_track``), when the physics diverges, or after
``timeout_s``. Exploring dead ends is no failure: the cross-track error is the distance to the nearest line, any
line. The result is a :class:`twin.core.lap.LapResult`: ``lap_time_s`` the time to the finish, ``distance_m`` the
distance driven, ``track_length_m`` the maze's shortest path."""

from __future__ import annotations

import numpy as np

from mjcf.maze import Maze
from twin.core.lap import COL, LapLimits, LapResult, earliest, judged
from twin.core.outcomes import Outcome
from twin.errors import TwinError


class MazeJudge:
    """Follows one run's trace chunk by chunk (the same interface as :class:`twin.core.lap.LapJudge`)."""

    def __init__(self, maze: Maze, limits: LapLimits, keep_trace: bool = True):
        self.track, self.limits, self.keep_trace = maze, limits, keep_trace
        self.n, self.abs_sum, self.abs_max, self.driven = 0, 0.0, 0.0, 0.0
        self.last_xy: np.ndarray | None = None
        self.chunks: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
        self.outcome: tuple[Outcome, str, float, float, float] | None = None  # code, detail, time, driven, energy

    @property
    def done(self) -> bool:
        return self.outcome is not None

    def feed(self, rec: np.ndarray) -> None:
        if self.done or len(rec) == 0:
            return
        xy, t = rec[:, [COL["x_m"], COL["y_m"]]], rec[:, COL["time_s"]]
        finite = np.isfinite(xy).all(axis=1)
        dist = self.track.distance(np.where(finite[:, None], xy, 0.0))
        step = np.hypot(*np.diff(np.vstack([xy[:1] if self.last_xy is None else self.last_xy[None], xy]), axis=0).T)
        driven = self.driven + np.cumsum(np.where(finite, step, 0.0))
        lim = self.limits
        events = [
            (~finite, Outcome.DIVERGED, "the physics produced a non-finite pose"),
            (dist > lim.max_cross_track_m, Outcome.OFF_TRACK, f"more than {lim.max_cross_track_m * 100:g} cm from every "
             "line of the maze"),
            (self.track.at_finish(xy) & finite, Outcome.COMPLETED, "finish reached"),
            (t > lim.timeout_s, Outcome.TIMEOUT, f"finish not reached after {lim.timeout_s:g} s"),
        ]
        end, why = earliest(events, len(rec))
        keep = slice(0, end + 1 if why else end)
        if len(rec[keep]):
            self.n += len(rec[keep])
            self.abs_sum += float(np.sum(dist[keep]))
            self.abs_max = max(self.abs_max, float(np.max(dist[keep])))
            if self.keep_trace:
                self.chunks.append((rec[keep].copy(), driven[keep].copy(), dist[keep].copy()))
        self.driven, self.last_xy = float(driven[-1]), xy[-1].copy()
        if why is not None:
            self.outcome = (*why, float(t[end]), float(driven[end]), float(rec[end, COL["energy_j"]]))

    def fail(self, code: Outcome, detail: str, t: float, energy: float) -> None:
        if not self.done:
            self.outcome = (code, detail, t, self.driven, energy)

    def result(self, count: int, cal_min, cal_max, parameters: dict) -> LapResult:
        return judged(self, self.track.solution_m, count, cal_min, cal_max, dict(parameters))


def judge_for(track, limits: LapLimits, keep_trace: bool = True):
    """The judge of a run on ``track``: :class:`MazeJudge` for a maze, else :class:`twin.core.lap.LapJudge`."""
    from twin.core.lap import LapJudge

    return MazeJudge(track, limits, keep_trace) if isinstance(track, Maze) else LapJudge(track, limits, keep_trace)


def refuse_maze(track, what: str) -> None:
    """A maze is judged for a program that solves mazes: one line for what cannot (``what``)."""
    if isinstance(track, Maze):
        raise TwinError(f"--track {track.name}: a line maze is for a maze-solving 3pi program (--firmware FILE); "
                        f"{what} follows lines and has no maze strategy")
