"""The link's commands (``live``, ``emulate``) against bad input and outputs they cannot write: exit 2 and one last
``error: …`` line naming the input and what is wrong; nothing the user owns changes, is moved or set aside (see
:mod:`bad_cli`). A log that cannot be written stops ``live`` cleanly: its summary first, the error last."""

from __future__ import annotations

import json
import os

import pytest

from bad_cli import check_row, disks, talker  # noqa: F401  (fixtures)
from twin.cli.main import main

OVAL = "--track oval"
ROBOT = "socket://127.0.0.1:{talker}"
# (command line, exit status, words the one error line must hold)
ROWS = [
    ("emulate --tcp 99999", 2, ["outside"]),
    ("emulate --speed 1e-300", 2, ["outside"]),
    ("emulate --speed nan", 2, ["outside"]),
    (f"emulate {OVAL} --laps 1 --speed 100 --idle-timeout 5 --echo /dev/full", 2,
     ["/dev/full", "No space left on device"]),
    ("live --duration nan --port loop://", 2, ["outside"]),
    ("live --act --retune-deadline 0 --port loop://", 2, ["--retune-deadline", "outside"]),
    ("live --act --retune-deadline inf --port loop://", 2, ["--retune-deadline", "outside"]),
    ("live", 2, ["--port"]),
    ("live --replay {missing_dir}/log", 2, ["no such"]),
    # loop:// never carries a robot's line: it reopened forever
    (f"live {OVAL} --port loop:// --log {{dir}}/loop.log --retry 1", 2, ["loop://", "loopback"]),
    # a file the twin did not write is no state of its own: refused, left where it is (it was renamed aside)
    (f"live {OVAL} --port {ROBOT} --log {{dir}}/a.log --state {{user.json}} --duration 1", 2,
     ["{user.json}", "not written by"]),
    (f"live {OVAL} --port {ROBOT} --log {{dir}}/b.log --state {{empty.json}} --duration 1", 2,
     ["{empty.json}", "not written by"]),
    (f"live {OVAL} --port {ROBOT} --log {{dir}} --duration 1", 2, ["is a folder"]),
    (f"live {OVAL} --port {ROBOT} --log /dev/full --duration 1", 2, ["/dev/full", "not a regular file"]),
    (f"live {OVAL} --port {ROBOT} --log {{full}}/l.log --duration 5", 2, ["{full}/l.log", "No space left on device"]),
    (f"live {OVAL} --port {ROBOT} --log {{free16k}}/l.log --duration 10 --json", 2,
     ["{free16k}/l.log", "No space left on device", "stopped reading"]),
]


@pytest.fixture(scope="module")
def places(tmp_path_factory, talker):
    d = tmp_path_factory.mktemp("link")
    (d / "user.json").write_text("my precious\n")
    (d / "empty.json").write_text("")
    return {"dir": str(d), "missing_dir": str(d / "no" / "such"), "user.json": str(d / "user.json"),
            "empty.json": str(d / "empty.json"), "talker": str(talker)}


@pytest.mark.parametrize("line, status, words", ROWS, ids=[r[0] for r in ROWS])
def test_bad_link_input_is_one_last_line(capfd, places, disks, line, status, words):
    out = check_row(capfd, {**places, **disks.places(line)}, line, status, words, owned=["{user.json}", "{empty.json}"])
    if "--json" in line and line.startswith("live"):  # stopped cleanly: the summary, with what was read
        summary = json.loads(out)
        assert "No space left on device" in summary["log_error"] and summary["log"].endswith("l.log")


# (command line, exit status, files that must not be left behind): a link that never opened received nothing
NOTHING_LEFT = [
    (f"live {OVAL} --port {{dir}}/no-robot --log {{dir}}/never.log --retry 1", 1,
     ["{dir}/never.log", "{dir}/never.log.breaks", "{dir}/never.log.actions"]),
    (f"live {OVAL} --port {{dir}}/no-robot --log {{dir}}/never2.log --retry 1 --json", 1,
     ["{dir}/never2.log", "{dir}/never2.log.breaks", "{dir}/never2.log.actions"]),
]


@pytest.mark.parametrize("line, status, absent", NOTHING_LEFT, ids=[r[0] for r in NOTHING_LEFT])
def test_a_link_that_never_opens_leaves_no_files(capfd, places, line, status, absent):
    out = check_row(capfd, places, line, status, [])
    left = [f for f in (a.format(**places) for a in absent) if os.path.exists(f)]
    assert not left, f"left behind: {left}"
    if "--json" in line:
        assert json.loads(out)["log"] is None


def test_live_help_offers_only_links_a_robot_can_reach(capsys):
    assert main(["live", "--help"]) == 0
    assert "loop://" not in capsys.readouterr().out  # it listed loop://, which never reads a line
