"""The history database (tuner.history): Alembic's migrations create exactly the schema, on SQLite and on a real
PostgreSQL server; a database that is not ours is refused untouched; lap, tune and align keep their runs; a
database that cannot be reached is one line and the result stands; a log and its journal give the same rows
written live or rebuilt, rebuilding twice changes nothing; history reports, charts and forecasts."""

from __future__ import annotations

import json
import os
import socket

import pytest
import sqlalchemy as sa

from pg_server import postgres  # noqa: F401  (fixture)
from tuner.history import (History, HistoryError, HistoryWriter, Journal, actions_path, forecast_failure, lap_digest,
                           log_id, log_laps, rebuild_log, trend_of)
from tuner.history import schema
from twin.cli.main import main
from twin.core.digital_twin import DigitalTwin
from twin.telemetry.wire import Boot, Event, Header, Reply, Sample, encode

# held fixed on purpose, not the tuner's answer today (the plain_gains fixture): test_act's gains, which the twin
# fails below μ ≈ 0.75, the premise of the forecast test's hand calculation; elsewhere only values in records
from reference_gains import PLAIN_HELD as PLAIN
NEW = {"control.v_max": 1.1, "control.kb": 0.2, "control.kp": 31.0, "control.ki": 0.0, "control.kd": 1.12}  # arbitrary: a second set for the records


def sqlite(tmp_path, name="h.sqlite") -> str:
    return f"sqlite:///{tmp_path / name}"


def schema_diff(url: str) -> list:
    from alembic.autogenerate import compare_metadata
    from alembic.migration import MigrationContext

    h = History(url)
    try:
        with h.engine.connect() as c:
            return compare_metadata(MigrationContext.configure(c, opts={"version_table": schema.VERSION_TABLE}),
                                    schema.metadata)
    finally:
        h.close()


def dump(url: str) -> dict:
    """Every row of every table, without ids (which differ between databases), in a stable order."""
    engine = sa.create_engine(url.replace("postgresql+psycopg", "postgresql+psycopg"))
    out = {}
    with engine.connect() as c:
        for t in schema.TABLES:
            rows = [{k: v for k, v in r._mapping.items() if k not in ("id", "run_id", "robot_id")}
                    for r in c.execute(sa.select(t))]
            out[t.name] = sorted(json.dumps(r, sort_keys=True, default=str) for r in rows)
    engine.dispose()
    return out


# --- a live session, as files: the robot's log and the twin's journal ----------------------------------------

def lap_lines(t0: float, lap_time: float, seq: int, fail: str | None = None) -> list[str]:
    rows = [encode(Sample(t0 + 0.05 * i, 3500 + 300 * (i % 3), 1, 40.0, 40.0)) for i in range(1, 40)]
    end = encode(Event(t0 + lap_time, "FAIL", reason=fail) if fail else Event(t0 + lap_time, "LAP", lap_time_s=lap_time))
    return [encode(Header(8, 0.005, 2, "r7", seq)), encode(Event(t0, "START")), *rows, end]


def session_files(folder, start: float = 1000.0, mu: float = 0.8, slower_s: float = 0.0) -> str:
    """A log of 6 laps (a change of gains in force from lap 3, one failed lap; each lap ``slower_s`` slower than
    7.0, 7.1, …) and its journal, its session begun at ``start`` [s since the epoch], grip aligned to ``mu`` on laps
    0 to 1; the log's path."""
    log = os.path.join(folder, "robot.log")
    lines = [encode(Header(8, 0.005, 2, "r7", 0)), encode(Boot(0.0, "STORED", 3, 0))]
    t = 0.0
    for k, (lap, seq, fail) in enumerate([(7.0, 0, None), (7.1, 0, None), (7.2, 0, "off_track"), (7.3, 9, None),
                                          (7.31, 9, None), (7.32, 9, None)]):
        lap += slower_s
        lines += lap_lines(t, lap, seq, fail)
        if k == 2:
            lines.append(encode(Reply(9, "ACK")))
        t += lap + 0.01
    with open(log, "w") as f:
        f.writelines(lines)
    digests = [lap_digest(lap) for lap in log_laps(log)]  # as live journals each lap
    j = Journal(actions_path(log), "robot.log")
    records = [{"kind": "session", "time": start, "lap": 0, "act": True, "address": "motion.mu", "gains": PLAIN,
                "pitch_m": 0.009525}]
    for k in range(6):
        gains = PLAIN if k < 3 else NEW
        records.append({"kind": "lap", "lap": k, "time": start + 7 * k, "robot": "r7", "gains_seq": 0 if k < 3 else 9,
                        "robot_lap_time_s": None if k == 2 else 7 + 0.1 * k, "twin_lap_time_s": 7.0,
                        "discrepancy": 0.01, "value": {"motion.mu": 0.8}, "gains": gains, "implausible": None,
                        "digest": digests[k]})
        if k == 1:
            records.append({"kind": "alignment", "first_lap": 0, "lap": 1, "time": start + 10, "address": "motion.mu",
                            "robot": "r7", "explained": True, "value": mu, "before": 0.9, "interval": [mu - 0.01, mu + 0.01],
                            "measured_lap_time_s": 7.05, "message": "ok", "reason": "slower"})
        if k == 2:
            change = {"robot": "r7", "lap": 3, "time": start + 20, "seq": 9, "change": "retune", "gains": NEW,
                      "previous": PLAIN, "previous_seq": 0, "reason": "aligned", "predicted_lap_time_s": 7.3,
                      "aligned": {"motion.mu": 0.8}, "decided_lap": 3}
            for kind in ("decide", "send", "ack", "in_force"):
                records.append({"kind": kind, **change, "outcome": kind})
        if k == 4:
            records.append({"kind": "confirm", **change, "lap": 5, "outcome": "as predicted"})
    for r in records:
        j.write(r)
    j.close()
    return log


def online(url: str, log: str) -> None:
    """The rows the live twin writes as the session goes: the same records, in the same order."""
    from tuner.history import read_journal

    laps = {lap.index: lap for lap in log_laps(log)}
    writer = HistoryWriter(url, log, print, log_id(log))
    for index, r in read_journal(actions_path(log)):
        if r["kind"] == "lap":
            writer.lap(laps[r["lap"]], r)
        else:
            writer.journal_record(r, index)
    writer.close()
    assert writer.failed is None, writer.failed


# --- tests ------------------------------------------------------------------------------------------------------

@pytest.mark.quick
def test_migrations_create_exactly_the_schema_and_a_foreign_database_is_left_alone(tmp_path):
    url = sqlite(tmp_path)
    assert schema_diff(url) == [] and schema_diff(url) == []  # created, then already at the head
    foreign = tmp_path / "mine.sqlite"
    engine = sa.create_engine(f"sqlite:///{foreign}")
    with engine.begin() as c:
        c.execute(sa.text("CREATE TABLE notes (x TEXT)"))
    engine.dispose()
    text = tmp_path / "notes.txt"
    text.write_text("my notes\n" * 100)
    for path in (foreign, text):
        before = path.read_bytes()
        with pytest.raises(HistoryError, match="left as it is|not a database"):
            History(f"sqlite:///{path}")
        assert path.read_bytes() == before


def test_a_log_gives_the_same_rows_live_and_rebuilt_and_rebuilding_twice_changes_nothing(tmp_path):
    log = session_files(str(tmp_path))
    live_url, rebuilt_url = sqlite(tmp_path, "live.sqlite"), sqlite(tmp_path, "rebuilt.sqlite")
    online(live_url, log)
    h = History(rebuilt_url)
    first = rebuild_log(h, log)
    once = dump(rebuilt_url)
    rebuild_log(h, log)
    h.close()
    assert first["laps"] == 6 and once == dump(rebuilt_url) == dump(live_url)
    laps = [json.loads(r) for r in once["lf_laps"]]
    assert sorted((r["lap"], r["completed"], r["failure"], r["gains_seq"]) for r in laps) == [
        (0, True, None, 0), (1, True, None, 0), (2, False, "off_track", 0), (3, True, None, 9), (4, True, None, 9),
        (5, True, None, 9)]
    assert all(r["xte_max_m"] > 0 for r in laps)
    change = json.loads(once["lf_gain_changes"][0])
    assert (change["seq"], change["status"], change["first_lap"], change["predicted_lap_time_s"]) == (9, "confirmed", 3, 7.3)
    # the database missed the session (it was down): a rebuild fills it in, and history reports it
    code = main(["history", "--db", live_url, "--json", "--no-forecast", "--out-dir", str(tmp_path / "charts")])
    assert code == 0 and os.path.getsize(tmp_path / "charts" / "history_r7.png") > 10_000


def test_lap_and_align_keep_their_runs_and_an_unreachable_database_is_one_line(tmp_path, capsys):
    url = sqlite(tmp_path)
    assert main(["lap", "--track", "oval", "--db", url, "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["history"]["run"].startswith("lap:")
    assert main(["align", "--track", "oval", "--measured-lap-time", "9.0", "--db", url]) in (0, 1)
    rows = dump(url)
    lap = json.loads(rows["lf_laps"][0])
    assert lap["energy_j"] > 0 and lap["completed"] and lap["gains"]["control.kp"] == 15
    assert len(rows["lf_alignments"]) == 1 and len(rows["lf_runs"]) == 2
    with socket.socket() as s:  # a port nobody listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    capsys.readouterr()
    assert main(["lap", "--track", "oval", "--db", f"postgresql://twin@127.0.0.1:{port}/none"]) == 0
    said = capsys.readouterr()
    assert sum("warning:" in line and "history database" in line for line in said.err.splitlines()) == 1
    assert "warning:" not in said.out  # stdout keeps the answer alone
    assert "lap completed" in said.out
    for bad in (["history", "--db", sqlite(tmp_path, "missing.sqlite")], ["history", "--log", "x.log"],
                ["lap", "--db", "not a url"], ["lap", "--db", f"sqlite:///{tmp_path}/no/such/folder.sqlite"]):
        assert main(bad) == 2
        assert capsys.readouterr().err.strip().startswith("error:")


def test_the_same_migrations_and_rows_on_postgresql(tmp_path, postgres):  # noqa: F811
    url = postgres.database()
    assert schema_diff(url) == []
    log = session_files(str(tmp_path))
    h = History(url)
    rebuild_log(h, log)
    rebuild_log(h, log)
    h.close()
    lite = sqlite(tmp_path)
    online(lite, log)
    assert dump(url) == dump(lite)
    online(url, log)  # live rows over rebuilt ones: replaced, not doubled
    assert dump(url) == dump(lite)


def test_the_forecast_filters_the_evidence_and_races_the_gains_on_the_twin():
    """Grip aligned exactly on a straight line, 0.9 − 0.005·lap (laps 4-5, 14-15, 24-25), every lap finished on the
    plain gains: the twin fails them somewhere below μ ≈ 0.75 (test_act's premise), gradually (a lap fails more
    often the lower μ is). The straight line reaches the value where half the twin's laps fail (0.775 − edge)/0.005
    laps after lap 25: that lies inside the stated 90 % interval, and the median comes no later (a first failure
    comes before half the laps fail); the advice and the statement come from that distribution."""
    twin = DigitalTwin()
    twin.model()
    alignments = [{"first_lap": lap - 1, "lap": lap, "address": "motion.mu", "explained": True,
                   "value": 0.9 - 0.005 * (lap - 0.5), "interval": [0.9 - 0.005 * lap - 0.005, 0.9 - 0.005 * lap + 0.005]}
                  for lap in (5, 15, 25)]
    laps = [{"n": n, "completed": True, "gains": PLAIN} for n in range(26)]
    f = forecast_failure(twin, PLAIN, alignments, laps, "motion.mu", now_lap=25)
    assert f.failing_value is not None and 0.55 < f.failing_value < 0.775
    straight = (0.775 - f.failing_value) / 0.005
    lo, hi = f.interval
    assert lo <= straight <= (hi if hi is not None else float("inf")) and 0 < f.laps_to_failure <= straight + 1
    assert f.quantiles["5"] == lo and f.quantiles["95"] == hi and f.quantiles["50"] == f.laps_to_failure
    up = f"{hi:.0f}" if hi is not None else "more than 1000"
    said = f"the gains in force stop finishing in about {f.laps_to_failure:.0f} laps (90 % between {lo:.0f} and {up})"
    s, c = f.shapes["straight"], f.shapes["speeding_up"]  # where both shapes hold futures, both are said
    assert f.statement in (said, f"{said}; the laps cannot tell yet whether the wear speeds up: at its pace, about "
                           f"{s['median']:.0f} laps ({s['share']:.0%} of the futures); speeding up, about "
                           f"{c['median']:.0f} ({c['share']:.0%})")
    # the laps carry no lap time here: the alignments are the evidence
    assert f.evidence == dict(alignments=3, laps=26, failed=0, timed_laps=0, edge_seeds=5, observed_laps=0,
                              features=[], alignments_used=3, last_read_lap=25, carried_on=False)
    assert any("replace the tyres" in a for a in f.advice)
    again = forecast_failure(twin, PLAIN, alignments[::-1], laps, "motion.mu", now_lap=25)
    assert again == f  # bit for bit, whatever the order the evidence comes in
    one = forecast_failure(twin, PLAIN, alignments[:1], laps, "motion.mu", now_lap=25)
    assert one.laps_to_failure is None and one.interval is None and "too little evidence" in one.statement
    assert one.laps == 0  # nothing raced on too little evidence


def test_a_race_is_kept_in_the_cache_and_read_back_bit_for_bit_by_a_new_process(monkeypatch, tmp_path):
    """The twin's race of the gains (the forecast's failure and observation models) is kept as a verified cache
    entry: a process that has forgotten it (a new ``history``) reads it back equal, bit for bit, without racing the
    twin; other gains are another race; an entry that holds another race's record is refused by name."""
    import numpy as np

    from lf_common.errors import LineFollowerError
    from lf_common.files import write_manifest
    from tuner.history import twin_edge as te
    from twin.core.lap import LapLimits

    monkeypatch.setenv("TWIN_CACHE_DIR", str(tmp_path))
    twin = DigitalTwin(track="oval")
    ask = ("motion.mu", 0.9, 0.3, -1.0, 0, LapLimits(timeout_s=30.0), 2)
    te.forget_races()
    first = te.twin_edge(twin, PLAIN, *ask)
    assert first.failure is not None and first.observation is not None and first.laps > 0
    te.forget_races()
    monkeypatch.setattr(te, "_twin_edge", lambda *a: pytest.fail("raced again"))
    again = te.twin_edge(twin, PLAIN, *ask)
    assert again.failure == first.failure and again.laps == first.laps and again.raced == first.raced
    for name in ("values", "means", "covariances"):
        assert np.array_equal(getattr(again.observation, name), getattr(first.observation, name))
    with pytest.raises(pytest.fail.Exception, match="raced again"):
        te.twin_edge(twin, {**PLAIN, "control.kp": PLAIN["control.kp"] * 1.1}, *ask)
    [entry] = [e for e in (tmp_path / te.RACES).iterdir()]
    doc = json.loads((entry / "race.json").read_text())
    doc["record"]["seed"] = 99
    (entry / "race.json").write_text(json.dumps(doc))
    write_manifest(str(entry))  # a consistent entry, made by hand, of another race
    te.forget_races()
    with pytest.raises(LineFollowerError, match="holds another race"):
        te.twin_edge(twin, PLAIN, *ask)


def test_a_rebuild_gives_the_same_history_whatever_the_order_the_logs_arrive_in(tmp_path):
    """Three runs of robot r7 (grip aligned 0.8, 0.75, 0.7 on each run's laps 0-1), rebuilt in two orders and twice:
    the same alignments, in the order of the laps they measured (run k's laps 0-1 are laps 6k to 6k+1 of its life),
    and the same trend, bit for bit."""
    from tuner.history.report import report

    logs = []
    for k, mu in enumerate((0.8, 0.75, 0.7)):
        folder = tmp_path / f"run{k}"
        folder.mkdir()
        logs.append(session_files(str(folder), start=1000.0 + 100 * k, mu=mu))
    entries = []
    for name, order in (("a", logs), ("b", logs[::-1]), ("c", [logs[1], logs[0], logs[2], logs[0]])):
        h = History(sqlite(tmp_path, f"{name}.sqlite"))
        for log in order:
            rebuild_log(h, log)
        entries.append(report(h, None))
        h.close()
    assert entries[0] == entries[1] == entries[2]
    (robot,) = entries[0]
    assert [(a["first_lap"], a["lap"], a["value"]) for a in robot["alignments"]] == [
        (0, 1, 0.8), (6, 7, 0.75), (12, 13, 0.7)]
    assert robot["trends"]["motion.mu"]["slope"] == pytest.approx(-0.05 / 6)


def test_bad_history_input_is_one_line_and_no_number(tmp_path, capsys):
    """An empty history and a database of another program: one error line, exit 2. One alignment: the forecast
    says there is too little evidence and gives no number (nothing is raced)."""
    empty = sqlite(tmp_path, "empty.sqlite")
    History(empty).close()
    foreign = tmp_path / "theirs.sqlite"
    engine = sa.create_engine(f"sqlite:///{foreign}")
    with engine.begin() as c:
        c.execute(sa.text("CREATE TABLE orders (id INTEGER)"))
    engine.dispose()
    for url in (empty, f"sqlite:///{foreign}"):
        capsys.readouterr()
        assert main(["history", "--db", url, "--json"]) == 2
        out, err = capsys.readouterr()
        assert out == "" and err.count("\n") == 1 and err.startswith("error: --db"), err
    one = sqlite(tmp_path, "one.sqlite")
    h = History(one)
    rebuild_log(h, session_files(str(tmp_path)))
    h.close()
    capsys.readouterr()
    assert main(["history", "--db", one, "--json"]) == 0
    robot = json.loads(capsys.readouterr().out)["robots"][0]
    f = robot["forecast"]
    # the aligned parameter and every part that wears; a few laps: no feature beside the lap time to tell them apart
    assert robot["causes_tracked"] == ["motion.mu", "motor.supply_voltage"]
    assert "cannot tell them apart" in robot["causes_note"]
    assert f["laps_to_failure"] is None and f["interval"] is None and f["quantiles"] is None and f["laps"] == 0
    assert f["statement"].startswith("too little evidence") and not any(ch.isdigit() for ch in f["statement"].split(":")[0])


def test_a_copy_of_a_log_and_its_journal_is_the_same_life_not_a_second_one(tmp_path):
    """The original and a copy of it (log and journal, under another name in another folder) rebuilt into one
    database give the rows of the original alone: the same laps, alignment, change and events, once (each was
    there twice, and the trend of μ halved)."""
    import shutil

    (tmp_path / "a").mkdir()
    (tmp_path / "backup").mkdir()
    log = session_files(str(tmp_path / "a"))
    copy = str(tmp_path / "backup" / "robot-copy.log")
    shutil.copy(log, copy)
    shutil.copy(actions_path(log), actions_path(copy))
    alone, both = sqlite(tmp_path, "alone.sqlite"), sqlite(tmp_path, "both.sqlite")
    h = History(alone)
    rebuild_log(h, log)
    h.close()
    h = History(both)
    for path in (log, copy, log, copy):
        rebuild_log(h, path)
    h.close()
    once, twice = dump(alone), dump(both)
    assert len(once["lf_laps"]) == 6 and len(once["lf_gain_changes"]) == 1 and len(once["lf_alignments"]) == 1
    for table in ("lf_robots", "lf_laps", "lf_alignments", "lf_gain_changes", "lf_events"):
        assert twice[table] == once[table], table
    assert len(twice["lf_runs"]) == len(once["lf_runs"]) == 1  # (its log_path: the copy's, rebuilt last)


def test_a_log_live_is_writing_is_refused_for_rebuild_and_one_a_killed_live_left_is_not(tmp_path):
    """A log held by a running live (its lock) is refused and nothing is written; once that process is killed
    (SIGKILL: no clean-up of any marker), the lock is gone with it and the log rebuilds."""
    import subprocess
    import sys

    from twin.errors import TwinError

    log = session_files(str(tmp_path))
    holder = subprocess.Popen([sys.executable, "-c", "import sys, time\nfrom twin.link import DurableLog\n"
                               "held = DurableLog(sys.argv[1])\nprint('held', flush=True)\ntime.sleep(300)", log],
                              stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        h = History(sqlite(tmp_path))
        with pytest.raises(TwinError, match="live is still writing it"):
            rebuild_log(h, log)
        assert dump(h.url)["lf_laps"] == []
    finally:
        holder.kill()
        holder.wait(timeout=60)
    assert rebuild_log(h, log)["laps"] == 6 and len(dump(h.url)["lf_laps"]) == 6
    h.close()


# a process that opens a history database once told to go (the file named by argv[2] exists)
OPENER = """import os, sys, time
from tuner.history import History, HistoryError
print("ready", flush=True)
while not os.path.exists(sys.argv[2]):
    time.sleep(0.001)
try:
    History(sys.argv[1]).close()
    print("ok")
except HistoryError as e:
    print(e)
"""


@pytest.mark.parametrize("backend", ["sqlite", "postgresql"])
def test_processes_creating_one_new_database_at_once_all_get_it(tmp_path, backend, request):
    """4 processes let go together (each polls for one file every millisecond) onto a database nobody has created
    yet, 5 rounds: every one opens it (one creates it, the others wait and use it) and the schema is exactly the
    newest (the losers were told it was "not a history database of this program", or that a table already
    existed)."""
    import subprocess
    import sys

    for r in range(5):
        url = sqlite(tmp_path, f"race{r}.sqlite") if backend == "sqlite" else request.getfixturevalue("postgres").database()
        go = tmp_path / f"go{r}"
        procs = [subprocess.Popen([sys.executable, "-c", OPENER, url, str(go)], stdout=subprocess.PIPE,
                                  stderr=subprocess.PIPE, text=True) for _ in range(4)]
        try:
            assert [p.stdout.readline().strip() for p in procs] == ["ready"] * 4
            go.touch()
            said = [p.communicate(timeout=120) for p in procs]
        finally:
            for p in procs:
                p.kill()
        assert [out.strip() for out, _ in said] == ["ok"] * 4, (r, said)
        assert schema_diff(url) == []


def test_a_live_session_rebuilds_into_the_rows_live_wrote_and_its_copy_adds_none(tmp_path, capsys):
    """An emulated robot's 3 laps through live --db: its journal carries each lap's digest, which the log's laps
    have (the journal is accepted as the log's own), and history --rebuild of a copy of the log, then of the log,
    gives exactly the rows live wrote."""
    import shutil

    from live_helpers import emulator

    emu = emulator("--track", "oval", "--tcp", 0, "--speed", 1000, "--laps", 3, "--json", cwd=tmp_path)
    port = json.loads(emu.wait_line("stdout", lambda line: line.startswith("{"), "the emulator's link"))["link"]
    log, live_url, rebuilt_url = str(tmp_path / "live.log"), sqlite(tmp_path, "live.sqlite"), sqlite(tmp_path, "r.sqlite")
    capsys.readouterr()
    code = main(["live", "--track", "oval", "--port", port, "--laps", "3", "--log", log, "--db", live_url, "--json",
                 "--no-race-ahead"])  # (test_race_ahead.py runs them)
    emu.wait(timeout=60)
    assert code == 0, capsys.readouterr().err
    from tuner.history import read_journal

    journaled = {r["lap"]: r["digest"] for _, r in read_journal(actions_path(log)) if r["kind"] == "lap"}
    assert len(journaled) == 3 and journaled == {lap.index: lap_digest(lap) for lap in log_laps(log)}
    (tmp_path / "copy").mkdir()
    copy = str(tmp_path / "copy" / "live.log")
    for f in (log, actions_path(log)):
        shutil.copy(f, tmp_path / "copy")
    capsys.readouterr()
    assert main(["history", "--rebuild", "--log", copy, "--log", log, "--db", rebuilt_url, "-q"]) == 0
    assert dump(rebuilt_url) == dump(live_url) and len(dump(live_url)["lf_laps"]) == 3  # (the runs' log_path: the last)
