"""The twin beside the robot (tuner.live, the ``live`` command): the whole chain from an emulated robot through a
pty, restarts that resume, clean stops on Ctrl-C and SIGTERM, bad input, and the decisions: implausible laps
reported and never re-aligned on, an alignment applied and logged (the state file: tests/test_live_state.py).

The link's own promises (nothing lost, nothing waits forever) are tests/test_link.py's."""

from __future__ import annotations

import json
import logging
import os
import signal
import subprocess
import types

import pytest

import tuner.live.live_twin
from live_helpers import (DEADLINE_S, OVAL, RUN, emulator, lap_lines, live_here, robots,  # noqa: F401
                          samples, wait_until)
from tuner.live.live_twin import LiveOptions, LiveTwin
from twin.cli.main import main
from twin.core.digital_twin import DigitalTwin
from twin.link import DurableLog, log_lines
from twin.telemetry.wire import Event, Header, Sample, decode, encode


# --- the whole chain ---------------------------------------------------------------------------------------

def test_whole_chain_through_a_pty_converges_across_a_restart(tmp_path):
    """Emulated robot with a hidden μ → pty → live, stopped after 3 laps and started again: the twin's μ ends
    within 5 %, the second run resumes the first's laps and state, and the log holds every line sent, in order,
    from the very first one (written before live opened the pty) to the robot's last (which it waited for live
    to read before it left, removing its link), byte for byte (a line the stop cut is whole again in the log's
    bytes)."""
    link, sent, log = tmp_path / "robot", tmp_path / "sent.txt", tmp_path / "live.log"
    emu = emulator("--set", "motion.mu=0.22", "--speed", "40", "--laps", "5", "--link", str(link), "--echo", str(sent),
                   cwd=tmp_path)
    live = [*RUN, "live", "--port", str(link), "--log", str(log), "--json", "--retry", "10"]
    try:  # started together: live retries until the emulator has made its pty
        first = subprocess.run([*live, "--laps", "3"], capture_output=True, text=True, timeout=DEADLINE_S * 2, cwd=tmp_path)
        second = subprocess.run([*live, "--laps", "2"], capture_output=True, text=True, timeout=DEADLINE_S * 2, cwd=tmp_path)
        assert emu.wait(timeout=DEADLINE_S)[0] == 0  # its 5 laps read: it leaves by itself
    finally:
        emu.kill()
    assert first.returncode == 0 and second.returncode == 0, first.stderr + second.stderr
    s1, s2 = json.loads(first.stdout), json.loads(second.stdout)
    assert s1["laps"] == 3 and len(s1["alignments"]) >= 1
    assert s2["resumed_laps"] == 3 and s2["laps"] == 2 and 1 <= len(s2["alignments"]) <= 3
    assert s2["value"]["motion.mu"] == pytest.approx(0.22, rel=0.05)
    state = json.loads((tmp_path / "live.log.state.json").read_text())
    assert state["generator"] == "line-follower-twin" and state["values"]["motion.mu"] == s2["value"]["motion.mu"]
    received = [line.decode().strip() if line else None for line in log_lines(str(log))]  # split as received
    sent_lines = sent.read_text().splitlines()
    whole = [line for line in received if line in set(sent_lines)]
    assert received[0] == sent_lines[0]  # pyserial's flush at open would have dropped the first lines
    # every byte, in order, nothing repeated, across the restart: the log's bytes are what was sent (a line the first
    # run's stop cut in two is two pieces in the log, one each side of the break, and whole again in its bytes)
    assert log.read_bytes().decode().split() == sent.read_text().split()
    assert len(sent_lines) - len(whole) <= 1 and len(received) - len(whole) <= 2  # at most that one line cut
    assert not os.path.lexists(link)  # the emulator's link goes with it: its pty number will be someone else's


# --- stopping and bad input -------------------------------------------------------------------------

def test_ctrl_c_and_sigterm_stop_cleanly_with_one_json_document(tmp_path, robots):
    """Two lives at once (one per signal), each signalled once it has logged all the robot sent: the log synced,
    the summary printed as the one document, 130 / 143."""
    lives = {}
    for sig in (signal.SIGINT, signal.SIGTERM):
        log = tmp_path / f"{sig.name}.log"
        log.write_text("".join(lap_lines(8.8)))  # one lap from an earlier run: "resumed" is said, on stderr
        DurableLog(str(log)).close()  # (that run's: its break index beside it)
        robot = robots([samples(20)])
        lives[sig] = log, subprocess.Popen([*RUN, "live", *OVAL, "--port", robot.url, "--log", str(log), "--json"],
                                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=tmp_path)
    try:
        for sig, (log, live) in lives.items():
            wait_until(lambda: log.read_bytes().endswith(b"".join(samples(20))), f"{sig.name}'s live logging the robot")
            live.send_signal(sig)
        for sig, (log, live) in lives.items():
            out, err = live.communicate(timeout=DEADLINE_S)
            assert live.returncode == {signal.SIGINT: 130, signal.SIGTERM: 143}[sig] and "Traceback" not in err, err
            summary = json.loads(out)  # exactly one document on stdout
            assert summary["stopped_by"] == sig.name and summary["resumed_laps"] == 1 and summary["lines"] == 20
            assert "resumed 1 laps" in err and log.read_bytes().endswith(b"".join(samples(20)))
    finally:
        for _, live in lives.values():
            live.kill()


@pytest.mark.parametrize("args, needle", [
    (["--port", "nosuch://x"], "not a serial device or pyserial URL"),
    (["--port", "socket://127.0.0.1"], "not a serial device or pyserial URL"),
    (["--port", "socket://127.0.0.1:abc"], "not a serial device or pyserial URL"),
    (["--port", "{file}"], "not a serial device"),
    (["--port", "loop://", "--replay", "{file}"], "not both"),
    (["--port", "loop://", "--duration", "nan"], "outside"),
    (["--port", "loop://", "--retry", "inf"], "outside"),
    (["--port", "socket://127.0.0.1:9", "--log", "{tmp}"], "is a folder"),
    (["--port", "socket://127.0.0.1:9", "--state", "{tmp}"], "is a folder"),
    (["--port", "socket://127.0.0.1:9", "--state", "{tmp}/no/such.json"], "does not exist"),
])
def test_bad_live_input_is_one_line_and_exit_2(tmp_path, capsys, args, needle):
    (tmp_path / "file").write_text("not a device")
    fill = {"file": str(tmp_path / "file"), "tmp": str(tmp_path)}
    code, _, err = live_here(capsys, *[a.format(**fill) for a in args], *([] if "--log" in args else ["--log", tmp_path / "l.log"]))
    assert code == 2 and err.count("\n") == 1 and err.startswith("error: ") and needle in err, err


# --- state and re-alignment -----------------------------------------------------------------------------------

@pytest.mark.quick
def test_implausible_wire_laps_are_reported_and_never_realigned(monkeypatch):
    """Six implausible laps, each far off the twin's 8.78 s: none starts a re-alignment; a plausible 8.8 s lap
    after them does (0.2 % off, above the 0.1 % threshold). The aligner is a stand-in that notes what it is asked."""
    asked = []
    monkeypatch.setattr(tuner.live.live_twin, "align_lap_time", lambda twin, measured, address, bounds, seed, limits=None, interval=True: (
        asked.append(measured), types.SimpleNamespace(explained=False, value=None, message="stand-in"))[1])
    twin = DigitalTwin(track="oval")  # 4.9 m
    good = [encode(Event(0.0, "START"))] + [encode(Sample(0.05 * i, 3500, 1, 40.0, 40.0)) for i in range(1, 100)]
    cases = {
        "1 ms": [encode(Event(0.0, "START")), encode(Event(0.001, "LAP", lap_time_s=0.001))],
        "10000 s": [encode(Event(0.0, "START")), encode(Event(10000.0, "LAP", lap_time_s=10000.0))],
        "span": good + [encode(Event(5.0, "LAP", lap_time_s=9.0))],
        "position": [encode(Event(0.0, "START")), encode(Sample(1.0, 9000, 1, 40.0, 40.0)),
                     encode(Event(5.0, "LAP", lap_time_s=5.0))],
        "order": [encode(Event(0.0, "START")), encode(Sample(2.0, 3500, 1, 40.0, 40.0)),
                  encode(Sample(1.0, 3500, 1, 40.0, 40.0)), encode(Event(5.0, "LAP", lap_time_s=5.0))],
        "LAP before its samples": [encode(Event(0.0, "START")), encode(Sample(6.0, 3500, 1, 40.0, 40.0)),
                                   encode(Event(5.0, "LAP", lap_time_s=5.0))],
    }
    live = LiveTwin(twin, LiveOptions(threshold=0.001, k_laps=1))
    for name, lines in cases.items():
        for line in [encode(Header(8, 0.005, 2)), *lines]:
            live.feed(decode(line))
        assert live.laps[-1]["implausible"], name
    assert live.alignments == [] and live._thread is None  # none of them started a re-alignment
    for line in lap_lines(8.8, t0=20000.0):  # a plausible lap is judged as usual: within tolerance of its span
        live.feed(decode(line))
    live.finish()  # (the alignment thread is done before the test ends)
    assert live.laps[-1]["implausible"] is None and asked == [8.8] and len(live.alignments) == 1


@pytest.mark.quick
def test_implausible_laps_are_in_the_json_and_on_stderr(tmp_path, capsys):
    log = tmp_path / "session.log"
    log.write_text("".join(lap_lines(8.8) + lap_lines(0.001, t0=10.0)))
    capsys.readouterr()
    assert main(["live", *OVAL, "--replay", str(log), "--threshold", "0.5", "--json"]) == 0
    out, err = capsys.readouterr()
    summary = json.loads(out)
    assert summary["laps"] == 2 and summary["implausible_laps"] == 1 and summary["alignments"] == []
    assert summary["implausible"][0]["lap"] == 1 and "faster than" in summary["implausible"][0]["why"]
    assert "implausible, ignored" in err and "1 implausible" in err


@pytest.mark.quick
def test_a_successful_alignment_is_info_not_warning(monkeypatch, caplog):
    monkeypatch.setattr(tuner.live.live_twin, "align_lap_time", lambda twin, measured, address, bounds, seed, limits=None, interval=True: types.SimpleNamespace(
        explained=True, value=0.5, message="explained"))
    twin = DigitalTwin(track="oval")
    live = LiveTwin(twin, LiveOptions(threshold=1e-6, k_laps=1))
    caplog.set_level(logging.INFO, logger="tuner.live.live_twin")
    for line in lap_lines(9.5):
        live.feed(decode(line))
    live.finish()
    assert twin.space.get("motion.mu") == 0.5
    aligned = [r for r in caplog.records if r.message.startswith("aligned motion.mu")]
    assert len(aligned) == 1 and aligned[0].levelno == logging.INFO
    assert not [r for r in caplog.records if r.levelno >= logging.WARNING]


@pytest.mark.quick
def test_an_alignment_is_stamped_with_the_laps_it_measured_not_when_it_arrived(monkeypatch):
    """k_laps = 2: laps 0 and 1 disagree and start an alignment on their mean; its result is held back until lap 2
    has been counted. It must say it measured laps 0 to 1 (the count when it arrived is 3)."""
    import threading

    release = threading.Event()

    def slow(twin, measured, address, bounds, seed, limits=None, interval=True):
        release.wait(30)
        return types.SimpleNamespace(explained=True, value=0.7, message="stand-in", consistent=(0.69, 0.71))

    monkeypatch.setattr(tuner.live.live_twin, "align_lap_time", slow)
    live = LiveTwin(DigitalTwin(track="oval"), LiveOptions(threshold=1e-6, k_laps=2))
    for k, lap_time in enumerate((9.5, 9.6, 9.7)):
        for line in lap_lines(lap_time, t0=20.0 * k):
            live.feed(decode(line))
    release.set()
    live.finish()
    (a,) = live.alignments
    assert (a["first_lap"], a["lap"], a["measured_lap_time_s"]) == (0, 1, pytest.approx(9.55))
    assert len(live.laps) == 3


def test_an_estimate_from_failed_laps_is_no_evidence_for_the_trend():
    from tuner.history import trend_of

    measured = [{"lap": lap, "address": "motion.mu", "explained": True, "value": 0.9 - 0.01 * lap,
                 "interval": [0.89 - 0.01 * lap, 0.91 - 0.01 * lap]} for lap in (0, 10)]
    estimate = {"lap": 20, "address": "motion.mu", "explained": True, "value": 0.2, "interval": None,
                "from_failures": True}
    stored = {**estimate, "from_failures": None, "estimated": True}  # as the history database gives it back
    alone = trend_of(measured, "motion.mu")
    assert alone.slope == pytest.approx(-0.01)  # two points: the line through them
    assert trend_of(measured + [estimate], "motion.mu") == alone == trend_of(measured + [stored], "motion.mu")
