"""The twin's races run ahead by ``live`` are the ones ``history``'s first forecast asks for (issue 35: a forecast
ready within a lap): an emulated robot through ``live --db``, then ``history``: no race is run twice."""

from __future__ import annotations

import ast
import json
import os

import pytest

from live_helpers import emulator
from reference_gains import set_flags
from tuner.history import forecast_failure
from tuner.history import twin_edge as te
from tuner.history.forecast import SEEDS_LATER, SEEDS_LATER_FROM, SERVICE
from tuner.history.two_causes import ROWS
from twin.cli.main import main
from twin.core.closed_loop import run_laps
from twin.core.digital_twin import DigitalTwin

# fixed on purpose: the races of any gains will do, and these fail within the range raced (a failure model to read)
from reference_gains import PLAIN_HELD as PLAIN
LAPS = 9  # a forecast of a part that wears needs 8 timed laps


def races(cache) -> list[str]:
    folder = cache / te.RACES
    return sorted(os.listdir(folder)) if folder.is_dir() else []


def twin_laps(twin, n: int) -> list[dict]:
    """``n`` laps of ``PLAIN`` on the twin (seeds 100 onwards), as the history holds a robot's laps."""
    laps = run_laps(twin, [PLAIN] * n, seed=list(range(100, 100 + n)), keep_traces=False)
    return [{"n": k, "completed": r.completed, "gains": PLAIN, "lap_time_s": r.lap_time_s} for k, r in enumerate(laps)]


def test_live_runs_ahead_the_races_history_reads(tmp_path, capsys, monkeypatch):
    cache = tmp_path / "cache"
    monkeypatch.setenv("TWIN_CACHE_DIR", str(cache))
    emu = emulator("--track", "oval", "--tcp", 0, "--speed", 1000, "--laps", LAPS, "--json", *set_flags(PLAIN),
                   cwd=tmp_path)
    port = json.loads(emu.wait_line("stdout", lambda line: line.startswith("{"), "the emulator's link"))["link"]
    url = f"sqlite:///{tmp_path / 'h.sqlite'}"
    capsys.readouterr()
    code = main(["live", "--track", "oval", "--port", port, "--laps", str(LAPS), "--log", str(tmp_path / "live.log"),
                 "--db", url, "--json", *set_flags(PLAIN)])
    emu.wait(timeout=60)
    out, err = capsys.readouterr()
    assert code == 0, err
    assert json.loads(out)["race_ahead"]["state"] == "done", out
    ahead = races(cache)
    # one race per part that wears, the rows of both at once but the first (the first part's race alone), each part
    # again on more seeds, and no half-written entry beside them
    assert len(ahead) == 2 * len(SERVICE) + ROWS - 1
    # history, a new process with the world flags alone (the gains come from the robot's laps): it reads them
    te.forget_races()
    monkeypatch.setattr(te, "_twin_edge", lambda *a: pytest.fail("history raced the twin again"))
    assert main(["history", "--track", "oval", "--db", url, "--json"]) == 0
    [robot] = json.loads(capsys.readouterr().out)["robots"]
    assert robot["gains_in_force"] == PLAIN and races(cache) == ahead
    for address in SERVICE:
        assert robot["forecasts"][address]["laps"] > 0 and robot["forecasts"][address]["raced"] is not None
        assert robot["forecasts"][address]["evidence"]["edge_seeds"] == te.SEEDS  # (9 laps in)
    # a forecast later in the robot's life reads the races on more seeds, run ahead too
    twin = DigitalTwin(track="oval")
    seen = twin_laps(twin, SEEDS_LATER_FROM)
    for address in SERVICE:
        later = forecast_failure(twin, PLAIN, [], seen, address, now_lap=SEEDS_LATER_FROM - 1)
        assert later.evidence["edge_seeds"] == SEEDS_LATER > te.SEEDS and later.laps > 0, later.statement
    assert races(cache) == ahead


def test_only_a_value_measured_less_worn_than_the_twin_moves_the_race(tmp_path, monkeypatch):
    """The race starts a little above the twin's value: a robot measured below it finds the race run ahead; one
    measured above it is raced from its own value."""
    monkeypatch.setenv("TWIN_CACHE_DIR", str(tmp_path))
    te.forget_races()  # (races this process read before: not in this cache folder)
    twin = DigitalTwin(track="oval")
    seen = twin_laps(twin, LAPS)
    first = forecast_failure(twin, PLAIN, [], seen, "motion.mu", now_lap=LAPS - 1)
    assert first.raced is not None and first.raced[0] > twin.space.get("motion.mu"), first.statement
    assert len(races(tmp_path)) == 1
    te.forget_races()
    monkeypatch.setattr(te, "_twin_edge", lambda *a: pytest.fail("raced again"))

    def aligned(value):
        return [{"first_lap": 0, "lap": 1, "address": "motion.mu", "explained": True, "value": value,
                 "interval": [value * 0.99, value * 1.01]}]

    below = forecast_failure(twin, PLAIN, aligned(0.8), seen, "motion.mu", now_lap=LAPS - 1)
    assert below.raced == first.raced
    # another filter seed (how bench_forecast measures the Monte Carlo's own error) races nothing again: only the
    # filter's chance moves
    other = forecast_failure(twin, PLAIN, [], seen, "motion.mu", now_lap=LAPS - 1, filter_seed=1)
    assert other.raced == first.raced and other.failing_value == first.failing_value
    assert other.value_now is not None and other.band != first.band
    with pytest.raises(pytest.fail.Exception, match="raced again"):
        forecast_failure(twin, PLAIN, aligned(first.raced[0] + 0.05), seen, "motion.mu", now_lap=LAPS - 1)


@pytest.mark.quick
def test_a_forecast_whose_race_another_process_runs_says_so_within_its_wait(tmp_path, monkeypatch):
    """history --race-wait: while another process (live's race-ahead) holds the race a forecast reads, the forecast
    answers within its wait with no number and says the race is still to come; the races after it (which that
    process runs next) are not raced here either; the rows of both at once say how many of theirs are done."""
    import fcntl
    import time

    from lf_common.cache import lock_path
    from tuner.history.forecast import LAP_TIMEOUT_S, STILL_RACING, race_range, service_direction
    from tuner.history.report import soonest
    from tuner.history.two_causes import RowsRacing, forecasts_of, race_plane
    from twin.core.lap import LapLimits

    monkeypatch.setenv("TWIN_CACHE_DIR", str(tmp_path))
    te.forget_races()
    twin = DigitalTwin(track="oval")
    seen = twin_laps(twin, LAPS)

    def hold(address):  # the race of a part that wears, as forecast_failure asks for it, held as its builder would
        direction = service_direction(twin, address, [])
        start, end = race_range(twin, address, [], direction)
        folder = te.race_folder(te.race_record(twin, PLAIN, address, start, end, direction, 0,
                                               LapLimits(timeout_s=LAP_TIMEOUT_S), te.SEEDS))
        os.makedirs(os.path.dirname(folder), exist_ok=True)
        lock = open(lock_path(folder), "w")
        fcntl.flock(lock, fcntl.LOCK_EX)
        return lock

    first, second = sorted(SERVICE)  # the order forecasts_of asks in
    held = [hold(first)]
    monkeypatch.setattr(te, "_twin_edge", lambda *a: pytest.fail("raced what another process is to race"))
    t0 = time.monotonic()
    out = forecasts_of(twin, PLAIN, [], seen, [first, second], LAPS - 1, race_wait_s=0.2)
    assert time.monotonic() - t0 < 10.0
    assert sorted(out) == [first, second]
    for address, f in out.items():
        assert f.laps_to_failure is None and f.interval is None and f.note == STILL_RACING, f
        assert f"race of {address}" in f.statement and "another process" in f.statement
    assert soonest(out.values()).note == STILL_RACING
    # both at once: its first race (the second part's alone) held too
    held.append(hold(second))
    with pytest.raises(RowsRacing) as racing:
        race_plane(twin, PLAIN, (first, second), 0, LapLimits(timeout_s=LAP_TIMEOUT_S), wait_s=0.2)
    assert (racing.value.done, racing.value.total) == (0, ROWS + 1)
    # nothing raced, nothing half written: only the holders' locks are there
    assert sorted(races(tmp_path)) == sorted(os.path.basename(h.name) for h in held)


@pytest.mark.quick
def test_a_race_is_keyed_by_the_code_it_runs_not_by_the_command_line():
    """The race's key hashes the twin's packages and the race's own modules (an edit there races again), not
    twin/cli: a command's wording changes no race, and no race runs through it (no module outside twin/cli imports
    it but the entry points)."""
    import twin
    import tuner

    root = os.path.dirname(twin.__file__)
    files = [os.path.relpath(f, root) for f in te.digest_files()]
    assert not [f for f in files if f.startswith("cli" + os.sep)]
    assert os.path.join("core", "closed_loop.py") in files and os.path.join("core", "digital_twin.py") in files
    assert any(f.endswith(os.path.join("history", "twin_edge.py")) for f in files)
    assert any(f.endswith(os.path.join("prognostics", "evidence.py")) for f in files)
    entry = {"run.py", "__main__.py"}  # the command line's own front doors
    for package in (twin, tuner):
        for r, _, names in os.walk(os.path.dirname(package.__file__)):
            if os.path.commonpath([r, os.path.join(root, "cli")]) == os.path.join(root, "cli"):
                continue
            for n in (n for n in names if n.endswith(".py") and n not in entry):
                with open(os.path.join(r, n)) as f:
                    tree = ast.parse(f.read())
                imported = [a.name for node in ast.walk(tree) if isinstance(node, ast.Import) for a in node.names]
                imported += [node.module or "" for node in ast.walk(tree) if isinstance(node, ast.ImportFrom)]
                assert not [m for m in imported if m == "twin.cli" or m.startswith("twin.cli.")], os.path.join(r, n)
