"""Live link: the whole chain through a real pty, a robot dropping out mid-lap, restarts, and fuzzed input."""

from __future__ import annotations

import json
import random
import socket
import subprocess
import sys
import time

import pytest

from tuner.live import LapAssembler, LinkStats, LiveOptions, LiveTwin, replay_log
from twin.digital_twin import DigitalTwin
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
    for raw in lines:  # decode either works or says why
        try:
            decode(raw)
        except WireError:
            pass
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
