"""The history database's flags against bad input and a database that cannot be reached: exit 2 and one last
``error: …`` line naming the input and what is wrong, or (a database that cannot be used during a run) one
``warning: …`` line on stderr, never on stdout, and the result stands (see :mod:`bad_cli`)."""

from __future__ import annotations

import hashlib
import shutil
import sqlite3

import pytest

from bad_cli import check_row
from test_history import session_files
from tuner.history import History, HistoryError, Journal, actions_path
from twin.link import DurableLog

OVAL = "--track oval"
# (command line, exit status, words the one error line must hold, words a warning line must hold)
ROWS = [
    # --robot-id, not --robot (the robot description's flag); what the database holds instead
    ("history --db sqlite:///{dir}/h.sqlite --robot-id nobody --no-forecast", 2,
     ["--robot-id nobody: no such robot", "it holds: none"], []),
    # a backend the history does not run on: said so (it was "No module named 'MySQLdb'")
    ("history --db mysql://me@localhost/fleet", 2, ["mysql://me@localhost/fleet", "mysql is not a database"], []),
    ("lap --db mysql+pymysql://me@localhost/fleet", 2, ["mysql+pymysql://", "mysql is not a database"], []),
    # a server that cannot be reached: a warning on stderr (it went to stdout in text mode), the lap stands
    (f"lap {OVAL} --db postgresql+psycopg://me@127.0.0.1:1/fleet", 0, [], ["127.0.0.1:1", "the result stands"]),
    # a journal that is another log's: its laps are not this log's (it was taken as this log's actions)
    ("history --rebuild --log {dir}/mixed/robot.log --db sqlite:///{dir}/r1.sqlite", 2,
     ["{dir}/mixed/robot.log.actions", "belongs to another log", "its lap 0 is not lap 0 of"], []),
    # a journal with no lap yet, naming another log
    ("history --rebuild --log {dir}/named/x.log --db sqlite:///{dir}/r2.sqlite", 2,
     ["{dir}/named/x.log.actions", "is the journal of other.log, not of x.log"], []),
    # a user's SQLite file with only a view, or only a user_version: refused untouched (the schema went in beside)
    ("lap --db sqlite:///{dir}/view.sqlite", 2, ["view.sqlite", "holds view v_mine", "left as it is"], []),
    ("live --port socket://127.0.0.1:9 --db sqlite:///{dir}/version.sqlite", 2,
     ["version.sqlite", "holds user_version 7", "left as it is"], []),
    # a wait for the races that is no time span
    ("history --db sqlite:///{dir}/h.sqlite --race-wait -1", 2, ["--race-wait", "'-1' is outside [0, 900]"], []),
    # a log live is still writing (it is locked): a rebuild would miss its last laps
    ("history --rebuild --log {dir}/held.log --db sqlite:///{dir}/r3.sqlite", 2,
     ["{dir}/held.log", "live is still writing it"], []),
]
# a user's SQLite database holding one thing of theirs (statements run on a new file)
USERS_SQLITE = {"view": "CREATE VIEW v_mine AS SELECT 1 AS x", "version": "PRAGMA user_version = 7",
                "application": "PRAGMA application_id = 1234", "table": "CREATE TABLE notes (x TEXT)"}
OWNED = [*(f"{{dir}}/{name}.sqlite" for name in USERS_SQLITE), "{dir}/mixed/robot.log", "{dir}/mixed/robot.log.actions", "{dir}/named/x.log", "{dir}/named/x.log.actions",
         "{dir}/held.log"]


@pytest.fixture(scope="module")
def places(tmp_path_factory):
    d = tmp_path_factory.mktemp("history")
    History(f"sqlite:///{d}/h.sqlite").close()  # an empty history database: no robot in it yet
    for name, statement in USERS_SQLITE.items():
        with sqlite3.connect(d / f"{name}.sqlite") as c:
            c.execute(statement)
    for name in ("mine", "mixed", "named"):
        (d / name).mkdir()
    mine = session_files(str(d / "mine"))
    shutil.copy(actions_path(mine), actions_path(session_files(str(d / "mixed"), slower_s=0.5)))
    shutil.copy(mine, d / "named" / "x.log")
    Journal(actions_path(str(d / "named" / "x.log")), "other.log").close()
    shutil.copy(mine, d / "held.log")
    held = DurableLog(str(d / "held.log"))  # as a running live holds it
    yield {"dir": str(d)}
    held.close()


@pytest.mark.parametrize("line, status, words, warnings", ROWS, ids=[r[0] for r in ROWS])
def test_a_bad_history_flag_is_one_last_line(capfd, places, line, status, words, warnings):
    pytest.importorskip("psycopg") if "psycopg" in line else None
    out = check_row(capfd, places, line, status, words, owned=OWNED, warnings=warnings)
    if status == 0:
        assert "lap completed" in out  # the result stands, on stdout


@pytest.mark.parametrize("name", list(USERS_SQLITE))
def test_a_users_sqlite_file_is_refused_byte_for_byte_untouched(places, name):
    path = f"{places['dir']}/{name}.sqlite"
    before = hashlib.sha256(open(path, "rb").read()).hexdigest()
    with pytest.raises(HistoryError, match="left as it is"):
        History(f"sqlite:///{path}")
    assert hashlib.sha256(open(path, "rb").read()).hexdigest() == before
