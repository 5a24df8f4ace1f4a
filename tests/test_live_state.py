"""The live state file: only a file that carries the twin's state header is ever touched. A damaged one is copied
aside (never moved) and rebuilt from the log; anything else (a user's file, one it cannot read) is refused in one
line and left exactly as it was (``live --state user.json`` renamed the user's file to ``.corrupt-<time>``)."""

from __future__ import annotations

import json
import logging

import pytest

from lf_common.errors import OutputError
from tuner.live import LiveOptions, LiveTwin, resume
from tuner.live.state import state_is_ours, write_state
from twin.cli.main import main
from twin.core.digital_twin import DigitalTwin
from twin.link import DurableLog
from twin.link.emulator import lap_records

HEADER = '{\n  "generator": "line-follower-twin",\n  "kind": "live state"'
DAMAGED = {  # each carries the header
    "truncated": HEADER + ',\n  "values": {"motion.m',
    "wrong shape": HEADER + ',\n  "values": 3, "alignments": []}',
    "NaN": HEADER + ',\n  "values": {"motion.mu": NaN}, "alignments": []}',
    "unknown address": HEADER + ',\n  "values": {"motion.nope": 1}, "alignments": []}',
}
NOT_OURS = {
    "user's": "my precious\n",
    "empty": "",
    "truncated before the header": '{\n  "generator": "line-',
    "another of ours": '{\n  "generator": "line-follower-twin",\n  "gains": {"control.kp": 3}\n}\n',
}


@pytest.fixture(scope="module")
def twin():
    return DigitalTwin(track="oval")


@pytest.fixture
def log(tmp_path, twin):
    path = tmp_path / "live.log"
    path.write_text("".join(line for _, line in lap_records(twin, 7, 4, 2)))
    DurableLog(str(path)).close()  # a log of live's: its break index beside it
    return path


@pytest.mark.parametrize("name", list(NOT_OURS))
def test_a_file_without_the_state_header_is_refused_untouched(tmp_path, twin, name):
    state = tmp_path / "state.json"
    state.write_text(NOT_OURS[name])
    with pytest.raises(OutputError, match="was not written by") as e:
        LiveTwin(twin, LiveOptions(), str(state))
    assert str(state) in str(e.value) and "\n" not in str(e.value)
    assert state.read_text() == NOT_OURS[name] and sorted(p.name for p in tmp_path.iterdir()) == ["state.json"]


def test_a_damaged_state_of_ours_is_copied_aside_and_rebuilt(tmp_path, twin, log, caplog):
    state = tmp_path / "live.log.state.json"
    for name, text in DAMAGED.items():
        state.write_text(text)
        live = LiveTwin(twin, LiveOptions(), str(state))
        assert live.rebuild_from_log, name
        assert state.read_text() == text, name  # copied, not moved: still there until the rebuilt state replaces it
        assert resume(live, str(log)) == 2
        assert json.loads(state.read_text())["values"]["motion.mu"] == pytest.approx(0.9), name  # rebuilt
    aside = sorted(tmp_path.glob("live.log.state.json.corrupt-*"))
    assert sorted(p.read_text() for p in aside) == sorted(DAMAGED.values())  # every one kept, none overwritten
    warned = [r for r in caplog.records if "set aside" in r.message and r.levelno == logging.WARNING]
    assert len(warned) == len(DAMAGED)


def test_the_state_written_carries_its_header_and_is_read_back(tmp_path, twin):
    state = tmp_path / "s.json"
    write_state(str(state), {"motion.mu": 0.5}, [])
    assert state.read_text().startswith(HEADER) and state_is_ours(str(state))
    live = LiveTwin(twin.clone(), LiveOptions(), str(state))
    assert live.twin.space.get("motion.mu") == 0.5 and not live.rebuild_from_log
    legacy = tmp_path / "legacy.json"  # written before the header had its kind: still ours when whole
    legacy.write_text('{"generator": "line-follower-twin", "values": {"motion.mu": 0.6}, "alignments": []}')
    assert LiveTwin(twin.clone(), LiveOptions(), str(legacy)).twin.space.get("motion.mu") == 0.6


def test_the_command_warns_rebuilds_and_goes_on(tmp_path, log, capsys):
    state = tmp_path / "live.log.state.json"
    state.write_text(DAMAGED["truncated"])
    capsys.readouterr()
    code = main(["live", "--track", "oval", "--port", "socket://127.0.0.1:9", "--log", str(log), "--retry", "0.3",
                 "--json"])
    out, err = capsys.readouterr()
    assert code == 1 and "Traceback" not in err and "set aside" in err, err  # (the dead link gives up: exit 1)
    assert json.loads(out)["resumed_laps"] == 2 and json.loads(state.read_text())["values"]
