"""The lap judge in C (twin/csrc/sim/lap_judge.c, the FMU's) against its Python reference (twin.core.lap.LapJudge):
fed the same trace, a real lap and laps broken on purpose, they reach the same outcome at the same record."""

from __future__ import annotations

import ctypes
import math
from ctypes import c_double, c_int32, c_int64

import numpy as np
import pytest

from twin.core import COL, DigitalTwin, LapJudge, LapLimits, run_laps
from twin.core import native as core
from twin.core.outcomes import LAP_STATUS as STATUS  # enum lf_lap_status, checked against C when the library loads
from twin.core.outcomes import Outcome

COMPLETED, OFF_TRACK, LINE_LOST, TIMEOUT, DIVERGED, WRONG_WAY = (
    Outcome.COMPLETED.value, Outcome.OFF_TRACK.value, Outcome.LINE_LOST.value, Outcome.TIMEOUT.value,
    Outcome.DIVERGED.value, Outcome.WRONG_WAY.value)


Limits, Judge = core.LapLimitsC, core.JudgeC
lib = core.lib


@pytest.fixture(scope="module")
def twin():
    return DigitalTwin()


@pytest.fixture(scope="module")
def trace(twin):
    lap = run_laps(twin, [{}], seed=0)[0]
    assert lap.completed
    return lap.trace.records


def c_judge(records: np.ndarray, length: float, limits: LapLimits) -> Judge:
    j = Judge()
    lim = Limits.of(limits)
    lib.lf_judge_start(ctypes.byref(j), length, ctypes.byref(lim))
    rows = np.ascontiguousarray(records, dtype=np.float64)
    for row in rows:
        if lib.lf_judge_feed(ctypes.byref(j), row.ctypes.data_as(ctypes.POINTER(c_double))):
            break
    return j


def py_judge(twin, records: np.ndarray, limits: LapLimits, chunk: int) -> LapJudge:
    j = LapJudge(twin.track, limits, keep_trace=False)
    for k in range(0, len(records), chunk):
        j.feed(records[k: k + chunk])
    return j


def assert_same(twin, records, limits=LapLimits(), code=None):
    c = c_judge(records, twin.track.length_m, limits)
    for chunk in (1, 37, len(records)):
        py = py_judge(twin, records, limits, chunk)
        if py.outcome is None:  # still running at the end of the trace: the same progress so far
            assert c.status == 0 and code is None and c.u_last == py.u_last
            continue
        p_code, _, t, u, energy = py.outcome
        assert STATUS[c.status] == p_code == (code or p_code)
        # progress is summed record by record in both, whatever the chunks: bit for bit
        assert (c.end_t, c.end_u, c.end_energy) == (t, u, energy)
        assert c.records == py.n and c.abs_max == py.abs_max and c.abs_sum == py.abs_sum
    return c


def test_a_real_lap(twin, trace):
    c = assert_same(twin, trace, code=COMPLETED)
    assert c.end_u == twin.track.length_m


@pytest.mark.parametrize("case", ["off_track", "jump", "line_lost", "diverged", "tie", "timeout", "wrap_start",
                                  "wrong_way", "back_a_little"])
def test_a_lap_broken_on_purpose(twin, trace, case):
    rec = trace.copy()
    k = len(rec) // 3
    limits = LapLimits()
    if case == "off_track":
        rec[k, COL["offset_m"]] = -0.2
    elif case == "jump":
        rec[k:, COL["progress_m"]] = np.mod(rec[k:, COL["progress_m"]] + 0.3, twin.track.length_m)
    elif case == "line_lost":
        rec[k:, COL["line_seen"]] = 0.0
    elif case == "diverged":
        rec[k, COL["x_m"]] = math.nan
    elif case == "tie":  # two events at one record: the one listed first wins, in both
        rec[k, COL["x_m"]] = math.nan
        rec[k, COL["offset_m"]] = 0.5
    elif case == "timeout":
        limits = LapLimits(timeout_s=4.0)
    elif case in ("wrong_way", "back_a_little"):  # from record k on the robot drives the line backwards
        length, p = twin.track.length_m, rec[:, COL["progress_m"]]
        ahead = np.concatenate([[0.0], np.cumsum(np.mod(np.diff(p[k:]) + length / 2, length) - length / 2)])
        back = 1.0 if case == "wrong_way" else 0.8 * limits.max_backtrack_m / ahead.max()  # 80 % of the limit
        rec[k:, COL["progress_m"]] = np.mod(p[k] - back * ahead, length)
    elif case == "wrap_start":  # a start just behind 0: progress unwraps below zero (the trace ends short of a lap)
        rec[:, COL["progress_m"]] = np.mod(rec[:, COL["progress_m"]] - 0.05, twin.track.length_m)
    expected = {"off_track": OFF_TRACK, "jump": OFF_TRACK, "line_lost": LINE_LOST, "diverged": DIVERGED,
                "tie": DIVERGED, "timeout": TIMEOUT, "wrap_start": None, "wrong_way": WRONG_WAY,
                "back_a_little": None}[case]
    assert_same(twin, rec, limits, expected)
