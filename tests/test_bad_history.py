"""The history database's flags against bad input and a database that cannot be reached: exit 2 and one last
``error: …`` line naming the input and what is wrong, or (a database that cannot be used during a run) one
``warning: …`` line on stderr, never on stdout, and the result stands (see :mod:`bad_cli`)."""

from __future__ import annotations

import pytest

from bad_cli import check_row
from tuner.history import History

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
]


@pytest.fixture(scope="module")
def places(tmp_path_factory):
    d = tmp_path_factory.mktemp("history")
    History(f"sqlite:///{d}/h.sqlite").close()  # an empty history database: no robot in it yet
    return {"dir": str(d)}


@pytest.mark.parametrize("line, status, words, warnings", ROWS, ids=[r[0] for r in ROWS])
def test_a_bad_history_flag_is_one_last_line(capfd, places, line, status, words, warnings):
    pytest.importorskip("psycopg") if "psycopg" in line else None
    out = check_row(capfd, places, line, status, words, warnings=warnings)
    if status == 0:
        assert "lap completed" in out  # the result stands, on stdout
