"""The link's commands (``live``, ``emulate``) against bad input and outputs they cannot write: exit 2 and one last
``error: …`` line naming the input and what is wrong; nothing the user owns changes, is moved or set aside (see
:mod:`bad_cli`). A log that cannot be written stops ``live`` cleanly: its summary first, the error last."""

from __future__ import annotations

import json
import os

import pytest

from bad_cli import SmallDisks, check_row, disks, fill, talker  # noqa: F401  (fixtures)
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
    # a file of the user's that happens to be as long as the image (60 bytes) is not the robot's EEPROM
    (f"emulate {OVAL} --laps 1 --speed 100 --idle-timeout 5 --eeprom {{sixty.bin}}", 2,
     ["{sixty.bin}", "not this robot's EEPROM image", "neither of its 2 slots"]),
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
    # a --log that exists and was not written by live: refused like --state, never appended to
    (f"live {OVAL} --port {ROBOT} --log {{notes.txt}} --duration 1", 2,
     ["{notes.txt}", "is not a telemetry log of", "left as it is"]),
    (f"live {OVAL} --port {ROBOT} --log {{empty.log}} --duration 1", 2, ["{empty.log}", "is not a telemetry log of"]),
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
    (d / "notes.txt").write_text("my notes\n")
    (d / "empty.log").write_text("")
    (d / "sixty.bin").write_bytes(b"my calibration: 3500 3620 3710 3800 3910 4020 4100 4180\n".ljust(60, b"."))
    return {"dir": str(d), "missing_dir": str(d / "no" / "such"), "user.json": str(d / "user.json"),
            "empty.json": str(d / "empty.json"), "notes.txt": str(d / "notes.txt"), "empty.log": str(d / "empty.log"),
            "sixty.bin": str(d / "sixty.bin"), "talker": str(talker)}


USERS = ["{user.json}", "{empty.json}", "{notes.txt}", "{empty.log}", "{sixty.bin}"]


@pytest.mark.parametrize("line, status, words", ROWS, ids=[r[0] for r in ROWS])
def test_bad_link_input_is_one_last_line(capfd, places, disks, line, status, words):
    out = check_row(capfd, {**places, **disks.places(line)}, line, status, words, owned=USERS)
    if "--json" in line and line.startswith("live"):  # stopped cleanly: the summary, with what was read
        summary = json.loads(out)
        assert "No space left on device" in summary["log_error"] and summary["log"].endswith("l.log")


# a disk full when live starts, or while it runs: (command line, the disk)
FULL_DISKS = [
    (f"live {OVAL} --port {ROBOT} --log {{full}}/l.log --duration 5", "{full}"),
    (f"live {OVAL} --port {ROBOT} --log {{free16k}}/l.log --duration 10", "{free16k}"),
]


@pytest.mark.parametrize("line, disk", FULL_DISKS, ids=[r[0] for r in FULL_DISKS])
def test_a_full_disk_leaves_nothing_that_blocks_the_next_run(capfd, places, tmp_path, line, disk):
    """The run stops on the full disk (exit 2); it leaves no empty file (an empty <log>.breaks was left, which
    every later run refused as a stranger's), and once there is room again the next live on the same --log
    starts (here on a link that never opens: exit 1, no error)."""
    own = SmallDisks(str(tmp_path))
    try:
        p = {**places, **own.places(line)}
        check_row(capfd, p, line, 2, ["l.log", "No space left on device"])
        folder = fill(disk, p)
        left = {n: os.path.getsize(os.path.join(folder, n)) for n in os.listdir(folder) if n != ".filler"}
        assert all(left.values()), f"empty files left: {left}"
        os.remove(os.path.join(folder, ".filler"))
        check_row(capfd, p, f"live {OVAL} --port {{dir}}/no-robot --log {disk}/l.log --retry 0", 1, [])
    finally:
        own.close()


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
