"""The link to the robot (twin.telemetry.wire, twin.link) and its promises (issue 13): the wire's framing and
checksum, nothing received is lost (before the link opens, between link starts, when a robot drops, when live is
killed), nothing waits forever (lines without end, dead links, emulators nobody reads), one reader per log.

No test here waits on the clock: live is stopped by what the robot sends (a lap and ``--laps``), by a signal once
a condition holds, or by its own retry budget; processes are followed through the lines they print."""

from __future__ import annotations

import json
import logging
import os
import random
import socket
import threading
import time
import tty

import pytest

from live_helpers import (DEADLINE_S, OVAL, RUN, Pumped, emulator, free_port, live_here, live_until,  # noqa: F401
                          robots, samples, stop_lap, wait_until)
from tuner.live.live_twin import LiveOptions, LiveTwin
from tuner.live.replay import replay_log
from twin.cli.main import main
from twin.core.digital_twin import DigitalTwin
from twin.link.emulator import lap_records
from twin.link import DurableLog, LinkStats, log_lines
from twin.telemetry.laps import LapAssembler
from twin.telemetry.wire import Event, Header, LineSplitter, Sample, WireError, decode, encode

def lap_reported(n: int):
    """Matches live's line for its n-th received lap (counted from 0)."""
    return lambda line: line.startswith(f"lap {n}: robot ")


# --- the wire ---------------------------------------------------------------------------------------------

@pytest.mark.quick
def test_wire_round_trip_and_checksum():
    for rec in (Header(8, 0.005, 2), Sample(12.345, 3500, 1, 41.27, -3.5), Event(7.3, "LAP", lap_time_s=7.3)):
        assert decode(encode(rec)) == rec
    line = encode(Sample(1.0, 3500, 1, 40.0, 40.0))
    with pytest.raises(WireError, match="checksum"):
        decode(line.replace("3500", "3501"))


@pytest.mark.quick
def test_line_splitter_keeps_no_line_longer_than_a_wire_line():
    s = LineSplitter()
    good = samples(2)
    assert s.feed(good[0][:10]) == [] and s.feed(good[0][10:] + good[1]) == good
    for _ in range(160):  # 10 MB without a newline, in 64 KB reads: nothing kept, nothing reported yet
        assert s.feed(b"x" * 65536) == []
        assert len(s.pending) <= 96
    assert s.feed(b"xx\n" + good[0]) == [None, good[0]]  # the junk line ends: one corrupted line
    assert s.feed(b"$LFS,1") == [] and s.cut() and not s.cut()


@pytest.mark.quick
def test_assembler_waits_for_a_start_after_joining_mid_lap():
    a = LapAssembler()
    assert a.feed(Sample(5.0, 3500, 1, 1.0, 1.0)) is None
    assert a.feed(Event(6.0, "LAP", lap_time_s=6.0)) is None  # no start seen: not a whole lap
    a.feed(Event(6.0, "START"))
    a.feed(Sample(6.5, 3500, 1, 1.0, 1.0))
    lap = a.feed(Event(12.0, "LAP", lap_time_s=6.0))
    assert lap.lap_time_s == 6.0 and lap.t.tolist() == [0.5] and lap.implausible is None


@pytest.mark.quick
def test_fuzzed_lines_never_crash_and_valid_laps_survive(tmp_path):
    rng = random.Random(0)
    lap = [encode(Header(8, 0.005, 2)), encode(Event(0.0, "START"))]
    lap += [encode(Sample(0.01 * i, 3500, 1, 40.0, 41.0)) for i in range(300)]
    lap += [encode(Event(3.0, "LAP", lap_time_s=3.0))]
    lines = []
    for _ in range(3):
        for line in lap:
            lines.append(line.encode())
            r = rng.random()
            if r < 0.2:
                lines.append(bytes(rng.randrange(256) for _ in range(rng.randrange(1, 80))) + b"\n")  # noise
            elif r < 0.3:
                cut = line.encode()
                lines.append(cut[: rng.randrange(1, len(cut))] + b"\n")  # truncated
            elif r < 0.35:
                b = bytearray(line.encode())
                b[rng.randrange(1, len(b) - 4)] ^= 1 << rng.randrange(7)  # a flipped bit
                lines.append(bytes(b))
    path = tmp_path / "fuzz.log"
    path.write_bytes(b"".join(lines))
    valid = {line.encode() for line in lap}
    damaged = [raw for raw in lines if raw not in valid]
    assert len(damaged) > 50
    for raw in lines:  # a damaged line never decodes: the checksum or the framing catches it
        if raw in valid:
            assert decode(raw) is not None
        else:
            with pytest.raises(WireError):
                decode(raw)
    twin = DigitalTwin(track="oval")
    live = LiveTwin(twin, LiveOptions(threshold=10.0))
    stats = LinkStats()
    replay_log(str(path), live, stats)
    assert stats.corrupted >= len(damaged)  # (noise with a newline inside is more than one line)
    assert len(live.laps) == 3 and all(e["robot_lap_time_s"] == 3.0 for e in live.laps)


# --- nothing received is lost -------------------------------------------------------------------------------

def test_robot_drops_mid_lap_and_nothing_received_is_lost(tmp_path, capsys, robots):
    """The emulated robot is killed inside its second lap; once live has seen the link drop, a robot on the same
    port takes over."""
    port, log, sent1 = free_port(), tmp_path / "live.log", tmp_path / "sent1.txt"
    after = [line.encode() for _, line in lap_records(DigitalTwin(track="oval"), 11, 2, 3)]
    live = Pumped([*RUN, "live", *OVAL, "--port", f"socket://127.0.0.1:{port}", "--log", str(log), "--laps", "3",
                   "--json", "--threshold", "0.5"], cwd=tmp_path)
    emu = emulator(*OVAL, "--tcp", port, "--speed", 10, "--echo", sent1, cwd=tmp_path)
    try:
        emu.wait_line("stdout", lambda line: line.startswith("robot emulator on"), "the emulator's address")
        live.wait_line("stderr", lap_reported(0), "the first lap at live")
        # well inside the second lap (880 lines a lap at this speed): 20 of its lines are in the log
        wait_until(lambda: log.read_bytes().partition(b",LAP,")[2].count(b"\n") > 20, "the second lap's lines")
        emu.kill()
        live.wait_line("stderr", lambda line: "dropped" in line, "live seeing the link drop")
        second = robots([after], port=port)
        code, out, err = live.wait(timeout=DEADLINE_S)
    finally:
        emu.kill()
        live.kill()
    assert code == 0, err
    summary = json.loads(out)
    assert summary["reconnects"] >= 1 and summary["laps"] == 3
    received = [line.decode().strip() if line else None for line in log_lines(str(log))]  # split as received
    sent = sent1.read_text().splitlines() + [line.decode().strip() for _, line in second.sent]
    assert len(received) == summary["lines"]  # every line read is in the log
    sent_set = set(sent)
    whole = [line for line in received if line in sent_set]
    assert len(received) - len(whole) <= 2  # only lines cut by the drop itself
    assert whole == sent[: len(whole)]  # in order, none lost
    # a restart of live resumes from the log: the laps already received are not lost (the link is dead: it gives up)
    code, out, _ = live_here(capsys, "--port", f"socket://127.0.0.1:{free_port()}", "--log", log, "--retry", 0, "--json")
    # (every lap received counts: bytes that came with the third lap, after live had what it needed, are logged too)
    laps_in_log = sum(",LAP," in line for line in whole)
    assert laps_in_log >= 3 and code == 1 and json.loads(out)["resumed_laps"] == laps_in_log


@pytest.mark.quick
def test_lines_sent_before_the_tcp_link_opens_are_all_logged(tmp_path, capsys, robots):
    """pyserial's open() drains a socket: a robot that talks first had 0, 262 or 502 of its 502 lines logged."""
    lines = samples(502) + stop_lap()
    robot = robots([lines])  # everything the moment live connects, before it reads; the last lap stops live
    log = tmp_path / "live.log"
    code, out, err = live_here(capsys, "--port", robot.url, "--log", log, "--laps", 1, "--duration", DEADLINE_S, "--json")
    assert code == 0, err
    assert log.read_bytes() == b"".join(lines)
    assert json.loads(out)["lines"] == 504


@pytest.mark.quick
def test_a_pty_keeps_what_was_sent_before_and_between_link_starts(tmp_path, capsys):
    """pyserial's open() flushes a tty's input: over a pty, 1,350 lines were lost across two link starts."""
    master, slave = os.openpty()  # we play the robot, holding the slave open as the emulator does
    tty.setraw(slave)
    # 3.6 KB each, within any pty's 4 KB input buffer; each ends with a lap, which stops live (--laps 1)
    before, between = samples(120) + stop_lap(1000.0), samples(120, first=120) + stop_lap(2000.0)
    log = tmp_path / "live.log"
    try:
        os.write(master, b"".join(before))
        code, _, err = live_here(capsys, "--port", os.ttyname(slave), "--log", log, "--laps", 1, "--duration", DEADLINE_S)
        assert code == 0, err
        os.write(master, b"".join(between))  # while no link is open
        code, out, err = live_here(capsys, "--port", os.ttyname(slave), "--log", log, "--laps", 1, "--duration", DEADLINE_S)
        assert code == 0 and "resumed 1 laps" in out, err
    finally:
        os.close(master)
        os.close(slave)
    assert log.read_bytes() == b"".join(before + between)


def test_a_killed_live_has_every_line_it_read_on_disk(tmp_path, robots):
    """The log is written unbuffered as bytes arrive: with a buffered log, SIGKILL kept 413 of 502 lines. The robot
    sends bursts of 20 KB, each ending in a lap, and waits after each until live reports that lap: live has then
    read every byte sent. Killed right after the second, live must have all of them on disk."""
    bursts = [samples(700) + stop_lap(100.0), samples(700, first=700) + stop_lap(200.0)]
    read = [threading.Event(), threading.Event()]
    robot = robots([[*bursts[0], read[0], *bursts[1], read[1]]])
    log = tmp_path / "live.log"
    live = Pumped([*RUN, "live", *OVAL, "--port", robot.url, "--log", str(log), "--json"], cwd=tmp_path)
    try:
        for n in range(2):
            live.wait_line("stderr", lap_reported(n), f"lap {n} at live")
            read[n].set()
    finally:
        live.kill()  # SIGKILL: no chance to flush anything
    assert log.read_bytes() == b"".join(bursts[0] + bursts[1])


@pytest.mark.quick
def test_a_link_that_ends_mid_line_leaves_that_line_alone_in_the_log(tmp_path, capsys, robots):
    good, cut, after = *samples(2), encode(Header(8, 0.005, 2)).encode()
    robot = robots([[good, cut[:12]], [after, *stop_lap()]])  # hangs up mid-line, then takes the next connection
    log = tmp_path / "live.log"
    code, out, err = live_here(capsys, "--port", robot.url, "--log", log, "--laps", 1, "--duration", DEADLINE_S, "--json")
    assert code == 0, err
    assert log.read_bytes() == good + cut[:12] + after + b"".join(stop_lap())  # what came, nothing added
    assert list(log_lines(str(log)))[:3] == [good, None, after]  # the header is not glued to the cut line
    summary = json.loads(out)
    assert summary["lines"] == 5 and summary["corrupted"] == 1 and summary["reconnects"] >= 1


@pytest.mark.quick
def test_restart_ends_a_cut_off_line_and_a_second_reader_is_refused(tmp_path, capsys):
    log = tmp_path / "live.log"
    good = encode(Sample(1.0, 3500, 1, 40.0, 40.0)).encode()
    log.write_bytes(good + b"$LFS,12,35")  # the process died mid-line
    held = DurableLog(str(log))  # as a running live holds it
    try:
        assert log.read_bytes() == good + b"$LFS,12,35"  # marked beside the log, nothing added to it
        code, _, err = live_here(capsys, "--port", f"socket://127.0.0.1:{free_port()}", "--log", log, "--retry", 0)
        assert code == 2 and err.count("\n") == 1 and err.startswith(f"error: {log}: another process") and "locked" in err
    finally:
        held.close()
    assert log.read_bytes() == good + b"$LFS,12,35"  # the refused process wrote nothing


# --- nothing waits forever ----------------------------------------------------------------------------------

@pytest.mark.quick
def test_a_line_without_end_neither_blocks_stop_nor_is_lost(tmp_path, capsys, robots):
    """10 MB without a newline (readline() blocked for 36 s here): all of it logged, then SIGTERM stops live at
    once (a read returns within 0.1 s, newline or not) and the line is ended in the log."""
    junk = b"x" * 10_000_000
    robot = robots([[junk]])
    log = tmp_path / "live.log"
    code, out, err, stopping_s = live_until(capsys, lambda: log.exists() and log.stat().st_size >= len(junk),
                                            "--port", robot.url, "--log", log, "--json")
    assert code == 143 and stopping_s < 10, err
    assert log.read_bytes() == junk  # logged as received (its end at the stop is marked beside the log)
    summary = json.loads(out)
    assert summary["corrupted"] == 1 and summary["lines"] == 1 and summary["stopped_by"] == "SIGTERM"


@pytest.mark.parametrize("port", ["/dev/ttyNOPE", "socket://127.0.0.1:{dead}", "socket://127.0.0.1:{hangs_up}"])
def test_a_link_that_stays_down_gives_up(tmp_path, capsys, robots, port):
    """A port that never opens, an emulator that has exited, a server that hangs up at once: exit 1 after --retry."""
    dead, hangs_up = free_port(), robots([[]] * 100).port
    t0 = time.monotonic()
    code, out, err = live_here(capsys, "--port", port.format(dead=dead, hangs_up=hangs_up), "--log", tmp_path / "l.log",
                               "--retry", 0.5, "--json")
    assert code == 1 and "giving up" in err and "Traceback" not in err, err
    assert json.loads(out)["gave_up"] and time.monotonic() - t0 < 15


def test_retry_forever_never_gives_up(tmp_path, capsys):
    """With no retry budget (--retry 0) the first failed open gives up; --retry-forever keeps reopening: stopped
    (SIGTERM) once it has retried three times."""
    retries: list[logging.LogRecord] = []
    counter = logging.Handler()
    counter.emit = lambda record: retries.append(record) if "retrying" in record.getMessage() else None
    reader = logging.getLogger("twin.link.reader")
    level = reader.level
    reader.addHandler(counter)
    reader.setLevel(logging.INFO)
    try:
        code, out, err, _ = live_until(capsys, lambda: len(retries) >= 3, "--port", f"socket://127.0.0.1:{free_port()}",
                                       "--log", tmp_path / "l.log", "--retry", 0, "--retry-forever", "--json")
    finally:
        reader.removeHandler(counter)
        reader.setLevel(level)
    summary = json.loads(out)
    assert code == 143 and summary["gave_up"] is None and summary["reconnects"] >= 3, err


# --- the emulator -------------------------------------------------------------------------------------------

@pytest.mark.parametrize("args, needle", [
    (["--tcp", "99999"], "outside"),
    (["--speed", "1e-300"], "outside"),
    (["--speed", "nan"], "outside"),
    (["--idle-timeout", "nan"], "outside"),
    (["--link", "{mine}"], "not a link this emulator made"),
    (["--link", "{elsewhere}"], "not one this emulator made"),
    (["--link", "{tmp}/no/such/robot"], "does not exist"),
    (["--echo", "{tmp}"], "is a folder"),
    (["--echo", "{tmp}/no/such.txt"], "does not exist"),
])
def test_bad_emulate_input_is_one_line_and_exit_2(tmp_path, capsys, args, needle):
    mine, elsewhere = tmp_path / "notes.txt", tmp_path / "elsewhere"
    mine.write_text("my notes")
    elsewhere.symlink_to(mine)
    fill = {"mine": str(mine), "elsewhere": str(elsewhere), "tmp": str(tmp_path)}
    capsys.readouterr()
    assert main(["emulate", *OVAL, *[a.format(**fill) for a in args]]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("error: ") and needle in err, err
    assert mine.read_text() == "my notes" and elsewhere.is_symlink()  # nothing of the user's replaced


def test_the_tcp_emulator_stops_when_nobody_reads(tmp_path):
    """--laps 3 stayed running for 10 minutes after its only client left: now --idle-timeout after it left."""
    emu = emulator(*OVAL, "--tcp", 0, "--laps", 3, "--speed", 5, "--idle-timeout", 1, cwd=tmp_path)
    try:
        url = emu.wait_line("stdout", lambda line: line.startswith("robot emulator on"), "the emulator's address")
        host, port = url.split()[-1].removeprefix("socket://").split(":")
        with socket.create_connection((host, int(port))) as c:
            c.recv(1000)  # a client that reads a little and leaves
        t0 = time.monotonic()
        code, out, _ = emu.wait(timeout=60)
    finally:
        emu.kill()
    assert code == 0 and time.monotonic() - t0 < 20
    assert "robot emulator stops" in out


@pytest.mark.quick
def test_a_robot_in_lockstep_waits_on_while_the_twin_gives_signs_of_life():
    """Lockstep, idle timeout 0.3 s: the twin sends a keep-alive every 0.1 s for 1 s, then a command. The robot
    echoes each keep-alive and waits on (before, it quit 0.3 s after its lap: a keep-alive was no command); once
    the signs of life stop, it quits 0.3 s after the last one."""
    from twin.link.emulator import CommandPort, NoReader
    from twin.link.robot_end import RobotEnd
    from twin.telemetry.wire import Command, KeepAlive

    def twin(lines: list[tuple[float, bytes]]):
        t0 = time.monotonic()

        def receive(timeout: float) -> bytes:
            time.sleep(timeout)
            due = [line for t, line in lines if t <= time.monotonic() - t0]
            del lines[:len(due)]
            return b"".join(due)

        return receive

    gains = {"control.v_max": 1.0, "control.kb": 0.1, "control.kp": 30.0, "control.ki": 0.0, "control.kd": 1.0}
    alive = [(0.1 * k, encode(KeepAlive(k)).encode()) for k in range(1, 11)]
    port = CommandPort(twin([*alive, (1.1, encode(Command(1, "GET")).encode())]), RobotEnd("r7", gains, {}), True, 0.3)
    answers: list[str] = []
    t0 = time.monotonic()
    port.await_command(answers.append)
    assert time.monotonic() - t0 >= 1.0 and answers[-1].startswith("$LFR,1,GAINS")
    assert [decode(a) for a in answers[:-1]] == [KeepAlive(k) for k in range(1, 11)]
    port = CommandPort(twin(alive[:5]), RobotEnd("r7", gains, {}), True, 0.3)
    t0 = time.monotonic()
    with pytest.raises(NoReader, match="no sign of life from the twin for 0.3 s"):
        port.await_command(answers.append)
    # the last sign of life at 0.5 s, the limit 0.3 s after it; the upper bound leaves a loaded machine 3 s of room
    assert 0.5 + 0.3 <= time.monotonic() - t0 < 0.5 + 0.3 + 3.0


@pytest.mark.quick
def test_a_robot_too_flat_to_calibrate_sends_start_then_fail_and_the_next_lap():
    """A battery so flat the calibration turn falls short ends its lap before the first control tick (no trace):
    the emulated robot sends START and FAIL for it (it used to crash) and goes on to its next lap."""
    from twin.link.emulator import Drift

    twin = DigitalTwin(track="oval")
    drift = Drift.parse("motor.supply_voltage=3.0:3.0@2", twin)
    lines = [decode(line) for _, line in lap_records(twin, 3, 5, 2, drifts=[drift])]
    events = [(r.event, r.reason) for r in lines if isinstance(r, Event)]
    assert [k for k, _ in events] == ["START", "FAIL", "START", "FAIL"]
    assert all(reason == "calibration" for _, reason in events[1::2]), events
    assert not any(isinstance(r, Sample) for r in lines)
