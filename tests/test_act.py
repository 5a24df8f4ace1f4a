"""``live --act`` end to end against ``emulate`` at speed (lockstep: the robot waits after each lap for the twin's
command, so decisions land on the lap they were taken): a robot whose tyre grip drifts down keeps finishing its
laps with ``--act`` where plain ``live`` sees failures, and the robot's own record (``--echo``) and the history
database agree lap for lap; a corrupted EEPROM image boots on the last good set and the twin says so; a
deliberately bad tune is rolled back; a robot that refuses (NAK) or stays silent keeps its gains; the twin's
keep-alives keep a robot through a re-tune longer than its idle timeout; a robot's hang-up after its last lap is
no dropped link; SIGTERM during a re-tune sends nothing; a STORE never answered is reported not stored everywhere
(the actor's side of these: :mod:`test_act_transaction`).

The bad tune, the NAK and the silence do not need a real re-tuning (the re-tuning itself is exercised by the drift
test): there ``tuner.live.act.retune_gains`` is a stand-in that returns the gains it is given at once."""

from __future__ import annotations

import json
import os
import signal
import time

import pytest
import sqlalchemy as sa

import tuner.live.act
from live_helpers import RUN, Pumped, emulator
from tuner.history import actions_path, log_laps, read_journal, schema
from tuner.live import ActOptions, Actor
from tuner.live.retune import Retune
from twin.cli.main import main
from twin.core.digital_twin import DigitalTwin
from twin.link.robot_end import SLOT_SIZE, read_stored
from twin.telemetry.wire import Header, Reply, gains_to_wire

# gains tuned plainly for the robot as built (μ = 0.9) by an earlier tuner, held fixed on purpose, not the tuner's
# answer today (the plain_gains fixture): the scenario is built on where they fail, somewhere below μ ≈ 0.75 (today's
# answer holds to about 0.67, and would move whenever the tuner does); the test asserts that premise (plain sees
# failures)
from reference_gains import PLAIN_HELD as PLAIN
GAINS = [w for a, v in PLAIN.items() for w in ("--set", f"{a}={v}")]
WEAR = "motion.mu=0.84:0.6"  # the grip's wear (emulate --drift, without its laps)
DRIFT = f"{WEAR}@16"  # plain gains fail from about lap 7 on
LAPS = 12


def link(emu: Pumped) -> str:
    return json.loads(emu.wait_line("stdout", lambda line: line.startswith("{"), "the emulator's link"))["link"]


def robot(tmp_path, *args) -> Pumped:
    return emulator("--tcp", 0, "--speed", 1000, "--json", *GAINS, *args, cwd=tmp_path)


def echoed_laps(path) -> list[tuple[int, float | None]]:
    """(gains in force, lap time or None for a failed lap) of each lap the robot sent, from its own record."""
    return [(lap.gains_seq, lap.lap_time_s) for lap in log_laps(str(path))]


def live_json(capsys, *args) -> tuple[int, dict, str]:
    capsys.readouterr()
    code = main(["live", *GAINS, "--json", *map(str, args)])
    out, err = capsys.readouterr()
    return code, json.loads(out), err


def journaled(log) -> list[dict]:
    """What the twin did, as kept beside ``log`` (commands too)."""
    return [a for _, a in read_journal(actions_path(str(log)))]


def kinds(doc: dict) -> list[str]:
    return [a["kind"] for a in doc["actions"] if a["kind"] != "command"]


def test_acting_keeps_a_drifting_robot_finishing_where_watching_sees_failures(tmp_path, capsys):
    plain_dir, act_dir = tmp_path / "plain", tmp_path / "act"
    plain_dir.mkdir()
    act_dir.mkdir()
    common = ["--laps", LAPS, "--drift", DRIFT, "--echo", "echo.txt"]
    plain_robot = robot(plain_dir, *common)
    act_robot = robot(act_dir, *common, "--lockstep", "--eeprom", "eeprom.bin")
    db = f"sqlite:///{act_dir / 'history.sqlite'}"
    plain = Pumped([*RUN, "live", "--port", link(plain_robot), *GAINS, "--laps", str(LAPS), "--json"], cwd=plain_dir)
    acting = Pumped([*RUN, "live", "--port", link(act_robot), *GAINS, "--laps", str(LAPS), "--json", "--act",
                     "--act-every", "3", "--db", db, "--retune-deadline", "600", "--no-race-ahead"],
                    cwd=act_dir)  # (lockstep: it waits)
    results = {}
    for name, live, emu in (("plain", plain, plain_robot), ("act", acting, act_robot)):
        code, out, err = live.wait(timeout=400)
        assert code == 0, err[-3000:]
        emu.wait(timeout=60)
        results[name] = json.loads(out), echoed_laps((plain_dir if name == "plain" else act_dir) / "echo.txt")
    plain_doc, plain_laps = results["plain"]
    act_doc, act_laps = results["act"]
    assert len(plain_laps) == len(act_laps) == LAPS
    assert sum(t is None for _, t in plain_laps) >= 2, plain_laps  # the aged robot loses the line with its gains
    assert plain_doc["actions"] == [] and plain_doc["changes"] == []  # watching never sends anything
    assert all(t is not None for _, t in act_laps), act_laps  # … and with --act it keeps finishing
    confirmed = [c for c in act_doc["changes"] if c["status"] == "confirmed"]
    assert len(confirmed) >= 2 and all(c["kind"] == "retune" for c in confirmed)
    for c in confirmed:  # each change came within 1 % of its prediction on the robot
        assert abs(sum(c["after"]) / len(c["after"]) / c["predicted_lap_time_s"] - 1) < 0.01
    assert {"decide", "send", "ack", "in_force", "confirm", "stored"} <= set(kinds(act_doc))
    # the robot's own record and the history database agree lap for lap: gains in force and lap times
    engine = sa.create_engine(db)
    with engine.connect() as c:
        rows = c.execute(sa.select(schema.laps.c.lap, schema.laps.c.gains_seq, schema.laps.c.lap_time_s)
                         .order_by(schema.laps.c.lap)).all()
        changes = c.execute(sa.select(schema.gain_changes.c.seq, schema.gain_changes.c.status)).all()
    engine.dispose()
    assert [(r.gains_seq, r.lap_time_s) for r in rows] == act_laps
    assert {(c["seq"], c["status"]) for c in confirmed} <= {tuple(r) for r in changes}

    # a power cycle on a corrupted EEPROM image: the newest stored set fails its CRC, the robot boots on the one
    # before and says so, and the twin reports it and follows the gains it runs
    image = bytearray((act_dir / "eeprom.bin").read_bytes())
    source, seq, gains, bad, newest = read_stored(bytes(image))
    assert (source, bad, seq) == ("STORED", 0, confirmed[-1]["seq"])  # stored after its confirmation
    image[newest * SLOT_SIZE + 10] ^= 0x10
    (act_dir / "eeprom.bin").write_bytes(bytes(image))
    again = robot(act_dir, "--laps", 2, "--lockstep", "--eeprom", "eeprom.bin", "--set", "motion.mu=0.7")
    code, doc, err = live_json(capsys, "--port", link(again), "--laps", 2, "--act", "--log", act_dir / "again.log")
    again.wait(timeout=60)
    assert code == 0
    boot = next(a for a in doc["actions"] if a["kind"] == "boot")
    assert (boot["source"], boot["bad"], boot["seq"]) == ("BACKUP", 1, confirmed[-2]["seq"])
    assert "failed the CRC check" in boot["outcome"] and "warning" in err.lower()
    assert any(a["kind"] == "adopt" and a["gains"] == confirmed[-2]["gains"] for a in doc["actions"])


@pytest.fixture
def stand_in_retune(monkeypatch):
    """retune_gains replaced: it proposes the given gains at once, as if raced over the whole envelope."""
    proposed = {}

    def fake(twin, address, low, high, seeds, timeout, **when):
        return Retune(dict(proposed), True, True, {address: (low, high)}, 7.0, 0, 0.0, "stand-in")

    monkeypatch.setattr(tuner.live.act, "retune_gains", fake)
    return proposed


def test_a_bad_tune_is_rolled_back(tmp_path, capsys, stand_in_retune):
    # too soft a steering: the robot loses the line on every noise seed at μ 0.8 (0 of 60 laps finish with K_P 4;
    # with K_P 8, 5 of 30 did, so the lap on which the change lands, which depends on when the alignment ends,
    # decided whether it failed)
    stand_in_retune.update({**PLAIN, "control.kp": 4.0})
    emu = robot(tmp_path, "--laps", 9, "--lockstep", "--set", "motion.mu=0.8", "--echo", tmp_path / "echo.txt")
    code, doc, err = live_json(capsys, "--port", link(emu), "--laps", 9, "--act", "--log", tmp_path / "live.log")
    emu.wait(timeout=60)
    assert code == 0, err
    bad, back = doc["changes"][:2]
    assert (bad["kind"], bad["status"]) == ("retune", "rolled_back") and bad["after"] == [None, None]
    assert (back["kind"], back["status"], back["gains"]) == ("rollback", "confirmed", PLAIN)
    rollback = next(a for a in doc["actions"] if a["kind"] == "rollback")
    assert "worse than before" in rollback["outcome"] and rollback["seq"] == bad["seq"]
    laps = echoed_laps(tmp_path / "echo.txt")
    assert [t is None for s, t in laps if s == bad["seq"]] == [True, True]  # the robot ran them, and failed
    assert all(t is not None for s, t in laps if s == back["seq"])  # back on the plain gains, it finishes again
    assert "rollback" in err


@pytest.mark.parametrize("mode, kind, why, wait_s", [("nak", "nak", "refused (LOCKED)", 5),
                                                    ("ignore", "silent", "no answer within", 0.2)])
def test_a_robot_that_refuses_or_stays_silent_keeps_its_gains(tmp_path, capsys, stand_in_retune, mode, kind, why,
                                                             wait_s):
    stand_in_retune.update({**PLAIN, "control.v_max": 1.2})  # (silent: a lap of the robot outlasts wait_s)
    emu = robot(tmp_path, "--laps", 5, "--lockstep", "--set", "motion.mu=0.8", "--commands", mode,
                "--echo", tmp_path / "echo.txt")
    code, doc, err = live_json(capsys, "--port", link(emu), "--laps", 5, "--act", "--ack-timeout", wait_s,
                               "--log", tmp_path / "live.log")
    emu.wait(timeout=60)
    assert code == 0, err
    change = doc["changes"][0]
    assert change["status"] == kind and change["after"] == []
    said = next(a for a in doc["actions"] if a["kind"] == kind)
    assert why in said["outcome"] and "keeps its gains #0" in said["outcome"]
    assert {s for s, _ in echoed_laps(tmp_path / "echo.txt")} == {0}  # the robot ran its own gains throughout
    assert f"act: {kind}" in err


@pytest.mark.quick
def test_a_change_the_robot_reports_in_force_before_its_first_lap_header_is_followed(stand_in_retune):
    """At real time a re-tuning holds the reader for a few laps: the robot's answer to GET (gains #n in force) may
    be read before the header of the first lap it ran them on. The change is in force either way, once."""
    new = {**PLAIN, "control.v_max": 1.2}
    stand_in_retune.update(new)
    twin = DigitalTwin()
    sent, actions = [], []
    actor = Actor(twin, "motion.mu", ActOptions(), 0, lambda line, deadline: sent.append(line), actions.append)
    actor.on_record(Header(8, 0.005, 2, "r7", 0), time.monotonic())
    actor.consider({"explained": True, "value": 0.8}, 3, 7.0, None)
    actor.end_of_lap()
    change = actor.current()
    assert change.status == "sent" and any(",SET," in line for line in sent)
    actor.on_record(Reply(change.seq, "ACK"), time.monotonic())
    actor.on_record(Reply(change.seq + 1, "GAINS", in_force=change.seq, gains=gains_to_wire(new)), time.monotonic())
    assert change.status == "in_force" and twin.space.get("control.v_max") == 1.2
    actor.on_record(Header(8, 0.005, 2, "r7", change.seq), time.monotonic())
    assert [a["kind"] for a in actions].count("in_force") == 1 and "adopt" not in [a["kind"] for a in actions]


def test_a_robot_in_lockstep_keeps_waiting_through_a_re_tune_longer_than_its_idle_timeout(tmp_path, capsys,
                                                                                        monkeypatch):
    """The twin re-tunes for 6 s against a robot whose idle timeout is 2.5 s: its keep-alives (one a second) keep
    the robot (before, the robot quit 'no command from the twin for 2.5 s after a lap' and the twin sent its gains
    to nobody)."""
    new = {**PLAIN, "control.v_max": 1.2}

    def slow(twin, address, low, high, seeds, timeout, **when):
        time.sleep(6.0)
        return Retune(dict(new), True, True, {address: (low, high)}, 7.0, 0, 6.0, "slow stand-in")

    monkeypatch.setattr(tuner.live.act, "retune_gains", slow)
    emu = robot(tmp_path, "--laps", 6, "--lockstep", "--set", "motion.mu=0.8", "--idle-timeout", 2.5,
                "--echo", tmp_path / "echo.txt")
    code, doc, err = live_json(capsys, "--port", link(emu), "--laps", 6, "--act", "--retry", 3,
                               "--log", tmp_path / "live.log")
    _, out, emu_err = emu.wait(timeout=60)
    assert code == 0 and doc["reconnects"] == 0 and doc["laps"] == 6, err
    assert "stops" not in out + emu_err
    assert doc["keep_alives"] >= 5 and "$LFK," in (tmp_path / "echo.txt").read_text()  # sent, and echoed
    assert any(c["status"] in ("in_force", "confirmed") for c in doc["changes"])  # the robot ran the change
    assert len(echoed_laps(tmp_path / "echo.txt")) == 6


def test_a_normal_end_in_lockstep_is_no_dropped_link(tmp_path, capsys, monkeypatch):
    """The robot hangs up after its last lap while the twin is still taking that lap in (slowed down here by 1 s a
    lap): the twin stops reading at the last lap --laps watches, so the end is no reconnect and no dropped link in
    the breaks file (before: '1 reconnects' and a 'dropped' break)."""
    from tuner.live.live_twin import LiveTwin
    from twin.link import breaks_path

    real = LiveTwin._lap

    def slowly(self, lap, replay):
        time.sleep(1.0)
        return real(self, lap, replay)

    monkeypatch.setattr(LiveTwin, "_lap", slowly)
    emu = robot(tmp_path, "--laps", 3, "--lockstep")
    log = tmp_path / "live.log"
    code, doc, err = live_json(capsys, "--port", link(emu), "--laps", 3, "--act", "--retry", 3, "--log", log)
    emu.wait(timeout=60)
    assert code == 0 and doc["laps"] == 3 and doc["reconnects"] == 0, err
    assert "dropped" not in open(breaks_path(str(log))).read()
    laps_seen = [a["lap"] for a in journaled(log) if a["kind"] == "command"]  # (GETs, each with the laps seen)
    assert laps_seen and max(laps_seen) < 3  # none after the last lap (how many before: the robot's pace decides)


def test_sigterm_during_a_re_tune_sends_nothing(tmp_path, capsys, monkeypatch):
    """SIGTERM while the twin re-tunes: it ends with 143, the change it decided is withdrawn, and the robot never
    sees a SET (before: the SET went out after the signal and the change stayed 'sent')."""
    new = {**PLAIN, "control.v_max": 1.2}

    def interrupted(twin, address, low, high, seeds, timeout, **when):
        os.kill(os.getpid(), signal.SIGTERM)  # the user's Ctrl-C, mid-re-tune
        time.sleep(1.0)
        return Retune(dict(new), True, True, {address: (low, high)}, 7.0, 0, 1.0, "stand-in")

    monkeypatch.setattr(tuner.live.act, "retune_gains", interrupted)
    emu = robot(tmp_path, "--laps", 9, "--lockstep", "--set", "motion.mu=0.8", "--echo", tmp_path / "echo.txt",
                "--idle-timeout", 5)
    code, doc, err = live_json(capsys, "--port", link(emu), "--laps", 9, "--act", "--log", tmp_path / "live.log")
    emu.kill()
    assert code == 143, err
    assert [c["status"] for c in doc["changes"]] == ["withdrawn"] and "send" not in kinds(doc)
    assert "SET" not in [a["op"] for a in journaled(tmp_path / "live.log") if a["kind"] == "command"]
    assert ",ACK*" not in (tmp_path / "echo.txt").read_text()  # the robot was asked nothing to acknowledge


def test_a_store_the_robot_never_answers_is_reported_not_stored_everywhere(tmp_path, capsys, stand_in_retune):
    """The robot runs the confirmed change but its EEPROM write hangs (emulate --commands no-store): the STORE goes
    out 3 times, then the change is confirmed but not stored in the journal, the database and --json, and the
    robot's state says it boots on #0, as its EEPROM image does (before: 'confirmed' like a stored change).
    The robot starts on slower gains and the re-tune proposes PLAIN: the races run ahead for PLAIN are the ones other
    tests' forecasts race on the same twin (the session's cache: raced once), not a race of this test's own."""
    start = {**PLAIN, "control.v_max": 1.2}
    slower = ["--set", f"control.v_max={start['control.v_max']}"]
    stand_in_retune.update(PLAIN)
    emu = robot(tmp_path, "--laps", 20, "--lockstep", *slower, "--set", "motion.mu=0.8", "--commands", "no-store",
                "--eeprom", tmp_path / "eeprom.bin")
    db = f"sqlite:///{tmp_path / 'h.sqlite'}"
    code, doc, err = live_json(capsys, *slower, "--port", link(emu), "--laps", 20, "--act", "--ack-timeout", 0.3,
                               "--db", db, "--log", tmp_path / "live.log")
    _, _, emu_err = emu.wait(timeout=60)
    assert code == 0, err + emu_err
    change = doc["changes"][0]
    assert (change["status"], change["stored"]) == ("confirmed", "not_stored")
    assert {(c["status"], c["stored"]) for c in doc["changes"]} == {("confirmed", "not_stored")}  # (more re-tunes)
    assert doc["robot_state"] == {"running_seq": doc["changes"][-1]["seq"], "stored_seq": 0, "store_pending": None}
    stores = [a["seq"] for a in journaled(tmp_path / "live.log") if a["kind"] == "command" and a["op"] == "STORE"]
    assert stores[:3] == [stores[0]] * 3  # the same STORE, 3 times
    # with --db the twin's races run ahead for history's forecast, and follow the gains that come into force
    ahead = doc["race_ahead"]
    assert ahead["gains"] == stand_in_retune and ahead["state"] == "done", ahead
    assert [e["gains"] for e in ahead["earlier"]] == [start]
    said = next(a for a in doc["actions"] if a["kind"] == "not_stored")
    assert "boots on gains #0" in said["outcome"] and "act: not_stored" in err
    engine = sa.create_engine(db)
    with engine.connect() as c:
        row = c.execute(sa.select(schema.gain_changes.c.status, schema.gain_changes.c.stored)
                        .where(schema.gain_changes.c.seq == change["seq"])).one()
    engine.dispose()
    assert tuple(row) == ("confirmed", "not_stored")
    assert not (tmp_path / "eeprom.bin").exists()  # nothing was ever stored (the image is made at the first write)


BUSY_LAPS = 6  # the busy machine's run: the wear in 6 laps (re-tunes with --act-every 3)


def test_live_act_in_lockstep_keeps_its_robot_on_a_machine_busy_on_every_core(tmp_path):
    """The documented pairing, `emulate --lockstep` with `live --act --act-every 3` at their default timeouts, while
    a CPU-bound process runs on each of the machine's cores (started here): no dropped link, no robot timeout,
    every lap sent and read, and every re-tune either in time or cut short by its deadline and saying so. How fast a
    re-tune is (issue 37's target, within one lap) depends on the machine: `benchmarks/bench_startup.py` measures it;
    on a machine half as fast per core, with these burners, the twin's share is a quarter of the old one's and the
    deadline cuts its re-tunes (2026-11-28), which must then leave the robot its gains or send the best found."""
    import subprocess
    import sys

    burners = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(os.cpu_count() or 2)]
    try:
        emu = robot(tmp_path, "--laps", BUSY_LAPS, "--drift", f"{WEAR}@{BUSY_LAPS}", "--lockstep",
                    "--echo", "echo.txt")
        live = Pumped([*RUN, "live", "--port", link(emu), *GAINS, "--laps", str(BUSY_LAPS), "--json", "--act",
                       "--act-every", "3"], cwd=tmp_path)
        code, out, err = live.wait(timeout=600)
        _, emu_out, emu_err = emu.wait(timeout=120)
    finally:
        for b in burners:
            b.kill()
            b.wait()
    assert code == 0, err[-3000:]
    doc = json.loads(out)
    assert doc["reconnects"] == 0 and doc["laps"] == BUSY_LAPS, err[-3000:]
    assert "stops" not in emu_out + emu_err and "no command" not in emu_out + emu_err
    assert len(echoed_laps(tmp_path / "echo.txt")) == BUSY_LAPS
    retunes = [a for a in doc["actions"] if a["kind"] == "retune"]
    assert retunes, doc["actions"]
    for a in retunes:  # late or not, a re-tune says what it did, and what it cost against what it was allowed
        assert a["wall_s"] > 0 and a["deadline_s"] > 0, a
        assert a["in_time"] or "deadline" in a["outcome"] or "stopping" in a["outcome"], a
