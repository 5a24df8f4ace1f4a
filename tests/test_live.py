"""Live link: the whole chain through a real pty, a robot dropping out mid-lap, restarts, fuzzed input; and the
link's promises (issue 13): nothing received is lost (before the link opens, between link starts, when killed),
nothing waits forever (lines without end, dead links, emulators nobody reads), one reader per log, implausible laps
never re-aligned on (the state file: test_live_state.py)."""

from __future__ import annotations

import json
import logging
import os
import random
import signal
import socket
import subprocess
import sys
import threading
import time
import tty
import types

import pytest

import tuner.live.live_twin
from tuner.live.live_twin import LiveOptions, LiveTwin
from tuner.live.replay import replay_log
from twin.telemetry.laps import LapAssembler
from twin.cli.main import main
from twin.core.digital_twin import DigitalTwin
from twin.link.emulator import lap_records
from twin.link import DurableLog, LinkStats, log_lines
from twin.telemetry.wire import Event, Header, LineSplitter, Sample, WireError, decode, encode

RUN = [sys.executable, "-m", "twin.run"]
OVAL = ["--track", "oval"]


def emulator(*args, cwd):
    return subprocess.Popen([*RUN, "emulate", *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=cwd)


def wait_for_line(proc, prefix, timeout=60):
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        line = proc.stdout.readline()
        if line.startswith(prefix):
            return line.strip()
    raise AssertionError(f"no {prefix!r} from the emulator")


def live_here(capsys, *args) -> tuple[int, str, str]:
    """``live`` run in this process: (exit code, stdout, stderr)."""
    capsys.readouterr()
    code = main(["live", *OVAL, *map(str, args)])
    out, err = capsys.readouterr()
    return code, out, err


def samples(n: int, first: int = 0) -> list[bytes]:
    return [encode(Sample(0.01 * i, 3500, 1, 40.0, 40.0)).encode() for i in range(first, first + n)]


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def serve(connections: list[list[bytes]], pause_s: float = 0.0, hold_s: float = 30.0, port: int = 0):
    """A TCP 'robot': for each connection in turn, send its lines as soon as the client connects (all at once,
    or one per ``pause_s``), then hold it open ``hold_s`` (the last one) or hang up (the others).
    Returns (port, [(send time, line)])."""
    server = socket.socket()
    server.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    server.bind(("127.0.0.1", port))
    server.listen(1)
    server.settimeout(60)
    sent: list[tuple[float, bytes]] = []

    def run():
        with server:
            for i, lines in enumerate(connections):
                try:
                    conn, _ = server.accept()
                except OSError:
                    return
                with conn:
                    try:
                        for line in lines:
                            conn.sendall(line)
                            sent.append((time.monotonic(), line))
                            if pause_s:
                                time.sleep(pause_s)
                        if i == len(connections) - 1:
                            time.sleep(hold_s)
                    except OSError:
                        pass  # the reader went away: the test decides what that means

    threading.Thread(target=run, daemon=True).start()
    return server.getsockname()[1], sent


def lap_lines(lap_time_s: float, t0: float = 0.0) -> list[str]:
    """One whole wire lap of ``lap_time_s`` with a sample every 0.05 s."""
    rows = [encode(Sample(t0 + 0.05 * i, 3500, 1, 40.0, 40.0)) for i in range(1, int(lap_time_s / 0.05))]
    return [encode(Header(8, 0.005, 2)), encode(Event(t0, "START")), *rows,
            encode(Event(t0 + lap_time_s, "LAP", lap_time_s=lap_time_s))]


# --- the wire ---------------------------------------------------------------------------------------------

def test_wire_round_trip_and_checksum():
    for rec in (Header(8, 0.005, 2), Sample(12.345, 3500, 1, 41.27, -3.5), Event(7.3, "LAP", lap_time_s=7.3)):
        assert decode(encode(rec)) == rec
    line = encode(Sample(1.0, 3500, 1, 40.0, 40.0))
    with pytest.raises(WireError, match="checksum"):
        decode(line.replace("3500", "3501"))


def test_line_splitter_keeps_no_line_longer_than_a_wire_line():
    s = LineSplitter()
    good = samples(2)
    assert s.feed(good[0][:10]) == [] and s.feed(good[0][10:] + good[1]) == good
    for _ in range(160):  # 10 MB without a newline, in 64 KB reads: nothing kept, nothing reported yet
        assert s.feed(b"x" * 65536) == []
        assert len(s.pending) <= 96
    assert s.feed(b"xx\n" + good[0]) == [None, good[0]]  # the junk line ends: one corrupted line
    assert s.feed(b"$LFS,1") == [] and s.cut() and not s.cut()


# --- the whole chain ---------------------------------------------------------------------------------------

def test_whole_chain_through_a_pty_converges_across_a_restart(tmp_path):
    """Emulated robot with a hidden μ → pty → live, stopped after 3 laps and started again: the twin's μ ends
    within 5 %, the second run resumes the first's laps and state, and the log holds every line sent, in order,
    from the very first one (written before live opened the pty) to the robot's last (which it waited for live
    to read before it left, removing its link)."""
    link, sent, log = tmp_path / "robot", tmp_path / "sent.txt", tmp_path / "live.log"
    emu = emulator("--set", "motion.mu=0.22", "--speed", "40", "--laps", "5", "--link", str(link), "--echo", str(sent),
                   cwd=tmp_path)
    live = [*RUN, "live", "--port", str(link), "--log", str(log), "--json", "--retry", "10"]
    try:  # started together: live retries until the emulator has made its pty
        first = subprocess.run([*live, "--laps", "3"], capture_output=True, text=True, timeout=300, cwd=tmp_path)
        second = subprocess.run([*live, "--laps", "2"], capture_output=True, text=True, timeout=300, cwd=tmp_path)
        assert emu.wait(timeout=30) == 0  # its 5 laps read: it leaves by itself
    finally:
        emu.kill()
        emu.wait()
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
    assert whole == sent_lines  # nothing lost or repeated across the restart, up to the last LAP
    assert len(received) - len(whole) <= 2  # at most a line cut by the stop itself
    assert not os.path.lexists(link)  # the emulator's link goes with it: its pty number will be someone else's


def test_robot_drops_mid_lap_and_nothing_received_is_lost(tmp_path, capsys):
    """The emulated robot is killed inside its second lap; a robot on the same port takes over after a second."""
    port, log, sent1 = free_port(), tmp_path / "live.log", tmp_path / "sent1.txt"
    after = [line.encode() for _, line in lap_records(DigitalTwin(track="oval"), 11, 2, 3)]
    live = subprocess.Popen([*RUN, "live", *OVAL, "--port", f"socket://127.0.0.1:{port}", "--log", str(log), "--laps",
                             "3", "--json", "--threshold", "0.5"], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, cwd=tmp_path)
    emu = emulator(*OVAL, "--tcp", str(port), "--speed", "10", "--echo", str(sent1), cwd=tmp_path)
    try:
        wait_for_line(emu, "robot emulator on")
        t0 = time.monotonic()
        while b",LAP," not in (log.read_bytes() if log.exists() else b""):  # the first lap is in
            assert time.monotonic() - t0 < 120, "no lap reached live"
            time.sleep(0.05)
        time.sleep(0.4)  # a lap takes 8.8 s / 10: this is well inside the second one
        emu.kill()
        emu.wait()
        time.sleep(1.0)  # the link is down; live keeps retrying
        _, sent2 = serve([after], port=port, hold_s=60)
        out, err = live.communicate(timeout=300)
    finally:
        emu.kill()
        live.kill()
    assert live.returncode == 0, err
    summary = json.loads(out)
    assert summary["reconnects"] >= 1 and summary["laps"] == 3
    received = [line.decode().strip() if line else None for line in log_lines(str(log))]  # split as received
    sent = sent1.read_text().splitlines() + [line.decode().strip() for _, line in sent2]
    assert len(received) == summary["lines"]  # every line read is in the log
    sent_set = set(sent)
    whole = [line for line in received if line in sent_set]
    assert len(received) - len(whole) <= 2  # only lines cut by the drop itself
    assert whole == sent[: len(whole)]  # in order, none lost
    # a restart of live resumes from the log: the laps already received are not lost
    code, out, _ = live_here(capsys, "--port", f"socket://127.0.0.1:{free_port()}", "--log", log, "--duration", 1, "--json")
    # (every lap received counts: bytes that came with the third lap, after live had what it needed, are logged too)
    laps_in_log = sum(",LAP," in line for line in whole)
    assert laps_in_log >= 3 and code == 0 and json.loads(out)["resumed_laps"] == laps_in_log


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


def test_assembler_waits_for_a_start_after_joining_mid_lap():
    a = LapAssembler()
    assert a.feed(Sample(5.0, 3500, 1, 1.0, 1.0)) is None
    assert a.feed(Event(6.0, "LAP", lap_time_s=6.0)) is None  # no start seen: not a whole lap
    a.feed(Event(6.0, "START"))
    a.feed(Sample(6.5, 3500, 1, 1.0, 1.0))
    lap = a.feed(Event(12.0, "LAP", lap_time_s=6.0))
    assert lap.lap_time_s == 6.0 and lap.t.tolist() == [0.5] and lap.implausible is None


# --- nothing received is lost -------------------------------------------------------------------------------

def test_lines_sent_before_the_tcp_link_opens_are_all_logged(tmp_path, capsys):
    """pyserial's open() drains a socket: a robot that talks first had 0, 262 or 502 of its 502 lines logged."""
    lines = samples(502)
    port, _ = serve([lines], hold_s=3)  # everything the moment live connects, before it reads
    log = tmp_path / "live.log"
    code, out, err = live_here(capsys, "--port", f"socket://127.0.0.1:{port}", "--log", log, "--duration", 1.5, "--json")
    assert code == 0, err
    assert log.read_bytes() == b"".join(lines)
    assert json.loads(out)["lines"] == 502


def test_a_pty_keeps_what_was_sent_before_and_between_link_starts(tmp_path, capsys):
    """pyserial's open() flushes a tty's input: over a pty, 1,350 lines were lost across two link starts."""
    master, slave = os.openpty()  # we play the robot, holding the slave open as the emulator does
    tty.setraw(slave)
    before, between = samples(120), samples(120, first=120)  # 3.5 KB each: within any pty's 4 KB input buffer
    log = tmp_path / "live.log"
    try:
        os.write(master, b"".join(before))
        code, _, err = live_here(capsys, "--port", os.ttyname(slave), "--log", log, "--duration", 1)
        assert code == 0, err
        os.write(master, b"".join(between))  # while no link is open
        code, _, err = live_here(capsys, "--port", os.ttyname(slave), "--log", log, "--duration", 1)
        assert code == 0, err
    finally:
        os.close(master)
        os.close(slave)
    assert log.read_bytes() == b"".join(before + between)


def test_a_killed_live_has_every_line_it_read_on_disk(tmp_path):
    """The log is written unbuffered as bytes arrive (and fsynced every 0.25 s): SIGKILL kept 413 of 502 lines."""
    lines = samples(2000)
    port, sent = serve([lines], pause_s=0.002)
    log = tmp_path / "live.log"
    live = subprocess.Popen([*RUN, "live", *OVAL, "--port", f"socket://127.0.0.1:{port}", "--log", str(log)],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=tmp_path)
    t0 = time.monotonic()
    while not log.exists() or log.stat().st_size < 3000:  # the link is up: let it run a little longer
        assert time.monotonic() - t0 < 60
        time.sleep(0.05)
    time.sleep(0.5)
    killed = time.monotonic()
    live.kill()
    live.wait()
    on_disk = log.read_bytes()
    everything = b"".join(lines)
    old = b"".join(line for t, line in sent if t < killed - 0.3)  # reads return within 0.1 s: margin for the scheduler
    assert len(old) > 1000 and on_disk.startswith(old) and everything.startswith(on_disk)


def test_a_link_that_ends_mid_line_leaves_that_line_alone_in_the_log(tmp_path, capsys):
    good, cut, after = *samples(2), encode(Header(8, 0.005, 2)).encode()
    port, _ = serve([[good, cut[:12]], [after]], hold_s=3)  # hangs up mid-line, then takes the next connection
    log = tmp_path / "live.log"
    code, out, err = live_here(capsys, "--port", f"socket://127.0.0.1:{port}", "--log", log, "--duration", 2, "--json")
    assert code == 0, err
    assert log.read_bytes() == good + cut[:12] + after  # what came, nothing added
    assert list(log_lines(str(log))) == [good, None, after]  # the header is not glued to the cut line
    summary = json.loads(out)
    assert summary["lines"] == 3 and summary["corrupted"] == 1 and summary["reconnects"] >= 1


def test_restart_ends_a_cut_off_line_and_a_second_reader_is_refused(tmp_path, capsys):
    log = tmp_path / "live.log"
    good = encode(Sample(1.0, 3500, 1, 40.0, 40.0)).encode()
    log.write_bytes(good + b"$LFS,12,35")  # the process died mid-line
    held = DurableLog(str(log))  # as a running live holds it
    try:
        assert log.read_bytes() == good + b"$LFS,12,35"  # marked beside the log, nothing added to it
        code, _, err = live_here(capsys, "--port", f"socket://127.0.0.1:{free_port()}", "--log", log, "--duration", 1)
        assert code == 2 and err.count("\n") == 1 and err.startswith(f"error: {log}: another process") and "locked" in err
    finally:
        held.close()
    assert log.read_bytes() == good + b"$LFS,12,35"  # the refused process wrote nothing


# --- nothing waits forever ----------------------------------------------------------------------------------

def test_a_line_without_end_neither_blocks_stop_nor_is_lost(tmp_path, capsys):
    junk = b"x" * 10_000_000  # 10 MB, no newline: readline() blocked for 36 s here
    port, _ = serve([[junk]], hold_s=30)
    log = tmp_path / "live.log"
    t0 = time.monotonic()
    code, out, err = live_here(capsys, "--port", f"socket://127.0.0.1:{port}", "--log", log, "--duration", 2, "--json")
    assert code == 0 and time.monotonic() - t0 < 10, err
    assert log.read_bytes() == junk  # logged as received (its end at the stop is marked beside the log)
    assert json.loads(out)["corrupted"] == 1


@pytest.mark.parametrize("port", ["/dev/ttyNOPE", "socket://127.0.0.1:{dead}", "socket://127.0.0.1:{hangs_up}"])
def test_a_link_that_stays_down_gives_up(tmp_path, capsys, port):
    """A port that never opens, an emulator that has exited, a server that hangs up at once: exit 1 after --retry."""
    dead, hangs_up = free_port(), serve([[]] * 100, hold_s=0)[0]
    t0 = time.monotonic()
    code, out, err = live_here(capsys, "--port", port.format(dead=dead, hangs_up=hangs_up), "--log", tmp_path / "l.log",
                               "--retry", 1, "--json")
    assert code == 1 and "giving up" in err and "Traceback" not in err, err
    assert json.loads(out)["gave_up"] and time.monotonic() - t0 < 15


def test_retry_forever_never_gives_up(tmp_path, capsys):
    code, out, err = live_here(capsys, "--port", f"socket://127.0.0.1:{free_port()}", "--log", tmp_path / "l.log",
                               "--retry", 0, "--retry-forever", "--duration", 1.5, "--json")
    summary = json.loads(out)
    assert code == 0 and summary["gave_up"] is None and summary["reconnects"] >= 3, err


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
    emu = emulator(*OVAL, "--tcp", "0", "--laps", "3", "--speed", "5", "--idle-timeout", "1", cwd=tmp_path)
    url = wait_for_line(emu, "robot emulator on").split()[-1]
    host, port = url.removeprefix("socket://").split(":")
    with socket.create_connection((host, int(port))) as c:
        c.recv(1000)  # a client that reads a little and leaves
    t0 = time.monotonic()
    emu.wait(timeout=60)
    assert emu.returncode == 0 and time.monotonic() - t0 < 20
    assert "robot emulator stops" in emu.stdout.read()


def test_ctrl_c_and_sigterm_stop_cleanly_with_one_json_document(tmp_path):
    """Two lives at once (one per signal): the log synced, the summary printed as the one document, 130 / 143."""
    lives = {}
    for sig in (signal.SIGINT, signal.SIGTERM):
        log = tmp_path / f"{sig.name}.log"
        log.write_text("".join(lap_lines(8.8)))  # one lap from an earlier run: "resumed" is said, on stderr
        port, _ = serve([samples(20)], hold_s=60)
        lives[sig] = log, subprocess.Popen([*RUN, "live", *OVAL, "--port", f"socket://127.0.0.1:{port}", "--log", str(log),
                                            "--json"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=tmp_path)
    size, t0 = (tmp_path / "SIGINT.log").stat().st_size, time.monotonic()
    for sig, (log, live) in lives.items():
        while log.stat().st_size == size:  # the link is up and logging
            assert time.monotonic() - t0 < 60
            time.sleep(0.05)
        live.send_signal(sig)
    for sig, (log, live) in lives.items():
        out, err = live.communicate(timeout=30)
        assert live.returncode == {signal.SIGINT: 130, signal.SIGTERM: 143}[sig] and "Traceback" not in err, err
        summary = json.loads(out)  # exactly one document on stdout
        assert summary["stopped_by"] == sig.name and summary["resumed_laps"] == 1 and summary["lines"] == 20
        assert "resumed 1 laps" in err and log.read_bytes().endswith(b"".join(samples(20)))


# --- state and re-alignment -----------------------------------------------------------------------------------

def test_implausible_wire_laps_are_reported_and_never_realigned():
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
    assert live.laps[-1]["implausible"] is None


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


def test_a_successful_alignment_is_info_not_warning(monkeypatch, caplog):
    monkeypatch.setattr(tuner.live.live_twin, "align_lap_time", lambda twin, measured, address, bounds, seed: types.SimpleNamespace(
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
