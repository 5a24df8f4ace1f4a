"""Live link: the whole chain through a real pty, a robot dropping out mid-lap, restarts, and fuzzed input."""

from __future__ import annotations

import json
import random
import socket
import subprocess
import sys
import threading
import time

import pytest

from tuner.live import LapAssembler, LiveOptions, LiveTwin, replay_log
from twin.link import LinkStats
from twin.digital_twin import DigitalTwin
from twin.emulator import lap_records
from twin.wire import Event, Header, Sample, WireError, decode, encode

RUN = [sys.executable, "-m", "twin.run"]


def emulator(*args, cwd):
    return subprocess.Popen([*RUN, "emulate", *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=cwd)


def wait_for_line(proc, prefix, timeout=60):
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        line = proc.stdout.readline()
        if line.startswith(prefix):
            return line.strip()
    raise AssertionError(f"no {prefix!r} from the emulator")


def test_wire_round_trip_and_checksum():
    for rec in (Header(8, 0.005, 2), Sample(12.345, 3500, 1, 41.27, -3.5), Event(7.3, "LAP", lap_time_s=7.3)):
        assert decode(encode(rec)) == rec
    line = encode(Sample(1.0, 3500, 1, 40.0, 40.0))
    with pytest.raises(WireError, match="checksum"):
        decode(line.replace("3500", "3501"))


def test_whole_chain_through_a_pty_converges(tmp_path):
    """Emulated robot with a hidden μ → pty → live: the twin's μ ends within 5 % after a bounded number of laps."""
    link = str(tmp_path / "robot")
    emu = emulator("--set", "motion.mu=0.22", "--speed", "40", "--laps", "12", "--link", link, cwd=tmp_path)
    try:
        wait_for_line(emu, "robot emulator on")
        out = subprocess.run([*RUN, "live", "--port", link, "--log", str(tmp_path / "live.log"), "--laps", "8", "--json"],
                             capture_output=True, text=True, timeout=300, cwd=tmp_path)
    finally:
        emu.kill()
    assert out.returncode == 0, out.stderr
    summary = json.loads(out.stdout.strip().splitlines()[-1])
    assert summary["value"]["motion.mu"] == pytest.approx(0.22, rel=0.05)
    assert 1 <= len(summary["alignments"]) <= 3 and summary["laps"] == 8
    state = json.loads((tmp_path / "live.log.state.json").read_text())
    assert state["values"]["motion.mu"] == summary["value"]["motion.mu"]


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_robot_drops_mid_lap_and_nothing_received_is_lost(tmp_path):
    port, log = free_port(), tmp_path / "live.log"
    sent1, sent2 = tmp_path / "sent1.txt", tmp_path / "sent2.txt"
    live = subprocess.Popen([*RUN, "live", "--port", f"socket://127.0.0.1:{port}", "--log", str(log), "--laps", "3",
                             "--json", "--threshold", "0.5"], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, cwd=tmp_path)
    emu = emulator("--tcp", str(port), "--speed", "10", "--echo", str(sent1), cwd=tmp_path)
    try:
        wait_for_line(emu, "robot emulator on")
        t0 = time.monotonic()
        while b",LAP," not in (log.read_bytes() if log.exists() else b""):  # the first lap is in
            assert time.monotonic() - t0 < 120, "no lap reached live"
            time.sleep(0.05)
        time.sleep(0.4)  # a lap takes 13.2 s / 10: this is well inside the second one
        emu.kill()
        emu.wait()
        time.sleep(1.0)  # the link is down; live keeps retrying
        emu = emulator("--tcp", str(port), "--speed", "10", "--seed", "11", "--echo", str(sent2), cwd=tmp_path)
        wait_for_line(emu, "robot emulator on")
        out, err = live.communicate(timeout=300)
    finally:
        emu.kill()
        live.kill()
    assert live.returncode == 0, err
    summary = json.loads(out.strip().splitlines()[-1])
    assert summary["reconnects"] >= 1 and summary["laps"] == 3
    received = log.read_bytes().decode().splitlines()
    sent = sent1.read_text().splitlines() + sent2.read_text().splitlines()
    assert len(received) == summary["lines"]  # every line read is in the log
    sent_set = set(sent)
    assert sum(line not in sent_set for line in received) <= 2  # only lines cut by the drop itself
    # a restart of live resumes from the log: the laps already received are not lost
    again = subprocess.run([*RUN, "live", "--port", f"socket://127.0.0.1:{free_port()}", "--log", str(log),
                            "--duration", "1", "--json"], capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert json.loads(again.stdout.strip().splitlines()[-1])["resumed_laps"] == 3


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
    assert stats.corrupted > 50
    assert len(live.laps) == 3 and all(e["robot_lap_time_s"] == 3.0 for e in live.laps)


def test_assembler_waits_for_a_start_after_joining_mid_lap():
    a = LapAssembler()
    assert a.feed(Sample(5.0, 3500, 1, 1.0, 1.0)) is None
    assert a.feed(Event(6.0, "LAP", lap_time_s=6.0)) is None  # no start seen: not a whole lap
    a.feed(Event(6.0, "START"))
    a.feed(Sample(6.5, 3500, 1, 1.0, 1.0))
    lap = a.feed(Event(12.0, "LAP", lap_time_s=6.0))
    assert lap.lap_time_s == 6.0 and lap.t.tolist() == [0.5]


# --- nothing received is lost, nothing waits forever (issue: "Nothing lost")
def serve_lines(lines: list[bytes], pause_s: float = 0.0, hold_s: float = 30.0):
    """A TCP 'robot' that sends ``lines`` as soon as a client connects (all at once, or one per ``pause_s``);
    returns (port, thread, sent-times list)."""
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(1)
    sent: list[tuple[float, bytes]] = []

    def run():
        conn, _ = server.accept()
        with conn:
            try:
                for line in lines:
                    conn.sendall(line)
                    sent.append((time.monotonic(), line))
                    if pause_s:
                        time.sleep(pause_s)
                time.sleep(hold_s)
            except OSError:
                pass  # the reader went away: the test decides what that means
        server.close()

    t = threading.Thread(target=run, daemon=True)
    t.start()
    return server.getsockname()[1], t, sent


def samples(n: int) -> list[bytes]:
    return [encode(Sample(0.01 * i, 3500, 1, 40.0, 40.0)).encode() for i in range(n)]


def test_lines_sent_before_the_link_opens_are_all_logged(tmp_path):
    """pyserial's open() flushes its input: a robot that talks first lost 0–100 % of its first 502 lines."""
    lines = samples(502)
    port, _, _ = serve_lines(lines, hold_s=5)  # sends everything the moment live connects, before it reads
    log = tmp_path / "live.log"
    out = subprocess.run([*RUN, "live", "--track", "oval", "--port", f"socket://127.0.0.1:{port}", "--log", str(log),
                          "--duration", "3", "--json"], capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    assert log.read_bytes() == b"".join(lines)
    assert json.loads(out.stdout)["lines"] == 502


def test_a_killed_live_has_every_line_older_than_the_fsync_interval_on_disk(tmp_path):
    lines = samples(2000)
    port, _, sent = serve_lines(lines, pause_s=0.002)
    log = tmp_path / "live.log"
    live = subprocess.Popen([*RUN, "live", "--track", "oval", "--port", f"socket://127.0.0.1:{port}", "--log", str(log)],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=tmp_path)
    time.sleep(4.0)
    killed = time.monotonic()
    live.kill()
    live.wait()
    on_disk = log.read_bytes()
    old = b"".join(line for t, line in sent if t < killed - 0.5)  # FSYNC_INTERVAL_S = 0.25 s, with margin
    assert len(old) > 1000 and on_disk.startswith(old)


def test_a_line_without_end_neither_blocks_stop_nor_is_lost(tmp_path):
    junk = b"x" * 10_000_000  # 10 MB, no newline: readline() blocked for 36 s here
    port, _, _ = serve_lines([junk], hold_s=30)
    log = tmp_path / "live.log"
    t0 = time.monotonic()
    out = subprocess.run([*RUN, "live", "--track", "oval", "--port", f"socket://127.0.0.1:{port}", "--log", str(log),
                          "--duration", "2", "--json"], capture_output=True, text=True, timeout=60, cwd=tmp_path)
    assert out.returncode == 0 and time.monotonic() - t0 < 20, out.stderr
    assert log.stat().st_size >= len(junk)  # logged as received (then a newline ends it on the next start)
    assert json.loads(out.stdout)["corrupted"] >= 1


def test_restart_ends_a_cut_off_line_and_a_second_reader_is_refused(tmp_path):
    log = tmp_path / "live.log"
    good = encode(Sample(1.0, 3500, 1, 40.0, 40.0)).encode()
    log.write_bytes(good + b"$LFS,12,35")  # the process died mid-line
    dead = f"socket://127.0.0.1:{free_port()}"
    first = subprocess.Popen([*RUN, "live", "--track", "oval", "--port", dead, "--log", str(log), "--duration", "8",
                              "--retry-forever"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=tmp_path)
    try:
        t0 = time.monotonic()
        while not log.read_bytes().endswith(b"35\n") and time.monotonic() - t0 < 30:
            time.sleep(0.1)
        assert log.read_bytes() == good + b"$LFS,12,35\n"  # ended, so the next line is not glued to it
        second = subprocess.run([*RUN, "live", "--track", "oval", "--port", dead, "--log", str(log), "--duration", "1"],
                                capture_output=True, text=True, timeout=60, cwd=tmp_path)
        assert second.returncode == 2 and "locked" in second.stderr and second.stderr.count("\n") == 1
    finally:
        first.kill()
        first.wait()


def test_a_corrupt_state_file_is_set_aside_and_rebuilt_from_the_log(tmp_path):
    twin = DigitalTwin(track="oval")
    log = tmp_path / "live.log"
    log.write_text("".join(line for _, line in lap_records(twin, 7, 4, 2)))
    state = tmp_path / "live.log.state.json"
    for bad in ("{", "", '{"values": 3, "alignments": []}'):
        state.write_text(bad)
        out = subprocess.run([*RUN, "live", "--track", "oval", "--port", f"socket://127.0.0.1:{free_port()}", "--log",
                              str(log), "--retry", "0.5", "--json"], capture_output=True, text=True, timeout=120, cwd=tmp_path)
        assert out.returncode == 1 and "Traceback" not in out.stderr  # 1: the dead link, not the state
        assert "set aside" in out.stderr
        assert json.loads(state.read_text())["values"]  # rebuilt
        assert json.loads(out.stdout)["resumed_laps"] == 2
    assert len(list(tmp_path.glob("live.log.state.json.corrupt-*"))) >= 1


@pytest.mark.parametrize("port, code, needle", [
    ("/dev/ttyNOPE", 1, "giving up"),
    ("nosuch://x", 2, "not a serial device or pyserial URL"),
])
def test_a_link_that_never_opens_gives_up(tmp_path, port, code, needle):
    t0 = time.monotonic()
    out = subprocess.run([*RUN, "live", "--track", "oval", "--port", port, "--log", str(tmp_path / "l.log"),
                          "--retry", "1"], capture_output=True, text=True, timeout=60, cwd=tmp_path)
    assert out.returncode == code and needle in out.stderr and "Traceback" not in out.stderr, out.stderr
    assert time.monotonic() - t0 < 30


def test_the_tcp_emulator_stops_when_nobody_reads(tmp_path):
    emu = emulator("--track", "oval", "--tcp", "0", "--laps", "3", "--speed", "5", "--idle-timeout", "2", cwd=tmp_path)
    url = wait_for_line(emu, "robot emulator on").split()[-1]
    host, port = url.removeprefix("socket://").split(":")
    with socket.create_connection((host, int(port))) as c:
        c.recv(1000)  # a client that reads a little and leaves
    t0 = time.monotonic()
    emu.wait(timeout=60)
    assert emu.returncode == 0 and time.monotonic() - t0 < 30


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
    }
    live = LiveTwin(twin, LiveOptions(threshold=0.001, k_laps=1))
    for name, lines in cases.items():
        for line in [encode(Header(8, 0.005, 2)), *lines]:
            live.feed(decode(line))
        assert live.laps[-1]["implausible"], name
    assert live.alignments == [] and live._thread is None  # none of them started a re-alignment
