"""Every writer against outputs it cannot or must not write: a missing or wrong kind of path, a file the user
owns, a full file system. Each ends with exit 2 and one last ``error: …`` line naming the file and the cause;
nothing the user owns changes (see :mod:`bad_cli`)."""

from __future__ import annotations

import pytest

from bad_cli import check_row, disks  # noqa: F401  (fixtures)
from conftest import minimal_urdf

OVAL = "--track oval"
# (command line, exit status, words the one error line must hold)
ROWS = [
    ("lap --save {missing_dir}/x.rrd", 2, ["does not exist"]),
    ("lap --save {dir}", 2, ["is a folder"]),
    ("lap --save /proc/line-follower-x.rrd", 2, ["cannot write"]),
    ("lap --save {user.rrd}", 2, ["was not written by"]),
    (f"lap {OVAL} --save {{free16k}}/w.rrd", 2, ["{free16k}/w.rrd", "No space left on device"]),
    ("tune --out {missing_dir}/g.json", 2, ["does not exist"]),
    ("tune --out {user.json}", 2, ["was not written by"]),
    (f"tune {OVAL} --param control.kp --max-iter 1 --held-out 0 -q -o {{full}}/g.json", 2,
     ["{full}/g.json", "No space left on device"]),
    ("align --measured-lap-time 7 --out {dir}", 2, ["is a folder"]),
    ("design --out-dir {user.json}", 2, ["is a file"]),
    ("design --out-dir {missing_dir}/study", 2, ["does not exist"]),
    (f"design {OVAL} --grid cad.S=0.05 --laps 1 --max-iter 1 --workers 1 -q --out-dir {{full}}/d", 2,
     ["{full}/d", "No space left on device"]),
    (f"sweep {OVAL} motion.mu=0.5:1:2 --seeds 1 --out-dir {{full}}/s", 2, ["{full}/s", "No space left on device"]),
    ("record --out {dir}", 2, ["is a folder"]),
    (f"record {OVAL} --out {{full}}/r.jsonl", 2, ["{full}/r.jsonl", "No space left on device"]),
    ("build -o {missing_dir}/w.xml", 2, ["does not exist"]),
    ("build -o {user.xml}", 2, ["was not written by"]),
    (f"build {OVAL} -o {{full}}/w.xml", 2, ["{full}/w", "No space left on device"]),
    ("generate --out-dir .", 2, ["current folder"]),
    ("generate --out-dir {full}/r", 2, ["{full}/r", "No space left on device"]),
    (f"convert {{robot.urdf}} --sensor-mount base:0.05,0,-0.01 {OVAL} -o {{full}}/w.xml", 2, ["{full}/w", "No space left on device"]),
]


@pytest.fixture(scope="module")
def places(tmp_path_factory):
    d = tmp_path_factory.mktemp("outputs")
    (d / "user.rrd").write_bytes(b"my own notes")
    (d / "user.json").write_text('{"mine": true}')
    (d / "user.xml").write_text("<mujoco/>")
    (d / "robot.urdf").write_text(minimal_urdf())
    return {"dir": str(d), "missing_dir": str(d / "no" / "such"),
            **{n: str(d / n) for n in ("user.rrd", "user.json", "user.xml", "robot.urdf")}}


@pytest.mark.parametrize("line, status, words", ROWS, ids=[r[0] for r in ROWS])
def test_an_output_that_cannot_be_written_is_one_last_line(capfd, places, disks, line, status, words):
    check_row(capfd, {**places, **disks.places(line)}, line, status, words,
              owned=["{user.rrd}", "{user.json}", "{user.xml}"])
