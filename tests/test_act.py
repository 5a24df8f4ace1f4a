"""``live --act`` end to end against ``emulate`` at speed (lockstep: the robot waits after each lap for the twin's
command, so decisions land on the lap they were taken): a robot whose tyre grip drifts down keeps finishing its
laps with ``--act`` where plain ``live`` sees failures, and the robot's own record (``--echo``) and the history
database agree lap for lap; a corrupted EEPROM image boots on the last good set and the twin says so; a
deliberately bad tune is rolled back; a robot that refuses (NAK) or stays silent keeps its gains.

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
from twin.telemetry.wire import Boot, Header, Reply, gains_to_wire

# gains tuned plainly for the robot as built (μ = 0.9): they lose the line somewhere below μ ≈ 0.75
PLAIN = {"control.v_max": 1.5, "control.kb": 0.125, "control.kp": 33.52, "control.ki": 0.0, "control.kd": 1.118}
GAINS = [w for a, v in PLAIN.items() for w in ("--set", f"{a}={v}")]
DRIFT = "motion.mu=0.84:0.6@16"  # plain gains fail from about lap 7 on
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
                     "--act-every", "3", "--db", db, "--retune-deadline", "600"], cwd=act_dir)  # (lockstep: it waits)
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


# --- the acting loop as a transaction (issue 39, items 2-4) ---------------------------------------------------------

class Robot7:
    """The twin's side of a robot "r7" that booted on its stored gains #0, driven by hand: the actor, what it sent
    (command lines), what it did (actions), and a stop switch."""

    def __init__(self, **options):
        self.sent, self.actions, self.stopped = [], [], False
        self.actor = Actor(DigitalTwin(), "motion.mu", ActOptions(ack_timeout_s=0.05, **options), 0,
                           lambda line, deadline: self.sent.append(line), self.actions.append)
        self.actor.stopping = lambda: self.stopped
        self.actor.on_record(Header(8, 0.005, 2, "r7", 0), time.monotonic())
        self.actor.on_record(Boot(0.0, "STORED", 0), time.monotonic())

    def ops(self) -> list[str]:
        return [line.split(",")[2].split("*")[0] for line in self.sent]

    def kinds(self) -> list[str]:
        return [a["kind"] for a in self.actions if a["kind"] != "command"]

    def confirmed(self, new: dict) -> None:
        """A re-tune to ``new`` decided, sent, ACKed, in force and confirmed over two laps as fast as predicted."""
        self.actor.consider({"explained": True, "value": 0.8}, 3, 7.0, None)
        self.actor.end_of_lap()
        c = self.actor.current()
        self.actor.on_record(Reply(c.seq, "ACK"), time.monotonic())
        self.actor.on_record(Header(8, 0.005, 2, "r7", c.seq), time.monotonic())
        for lap in (4, 5):
            self.actor.observe({"lap": lap, "gains_seq": c.seq, "robot_lap_time_s": c.predicted_lap_time_s}, [])
        assert c.status == "confirmed"


@pytest.mark.quick
@pytest.mark.parametrize("when", ["during the re-tune", "before the lap's command"])
def test_a_change_decided_once_the_run_is_stopping_is_withdrawn_never_sent(stand_in_retune, monkeypatch, when):
    """Ctrl-C or SIGTERM during a re-tune, or the last lap --laps watches: the change is journaled withdrawn, and
    no SET goes out (before, it was sent and stayed 'sent' with nobody to confirm or roll it back)."""
    robot = Robot7()
    stand_in_retune.update({**PLAIN, "control.v_max": 1.2})
    if when == "during the re-tune":
        real = tuner.live.act.retune_gains

        def stopped_meanwhile(*args, **kwargs):
            robot.stopped = True
            return real(*args, **kwargs)

        monkeypatch.setattr(tuner.live.act, "retune_gains", stopped_meanwhile)
    robot.actor.consider({"explained": True, "value": 0.8}, 3, 7.0, None)
    robot.stopped = True
    robot.actor.end_of_lap()
    change = robot.actor.current()
    assert change.status == "withdrawn" and "SET" not in robot.ops()
    withdraw = next(a for a in robot.actions if a["kind"] == "withdraw")
    assert withdraw["seq"] == change.seq and "not sent" in withdraw["outcome"]
    assert robot.actor.summary()[0]["status"] == "withdrawn"
    robot.actor.idle(time.monotonic() + 10)  # nothing sent once stopping, not even a GET or a keep-alive
    robot.actor.keep_alive()
    assert robot.ops() == ["GET"]  # (the one after the robot's first header, before the stop)


@pytest.mark.quick
def test_no_re_tune_once_the_run_is_stopping(stand_in_retune):
    robot = Robot7()
    robot.stopped = True
    robot.actor.consider({"explained": True, "value": 0.8}, 3, 7.0, None)
    assert robot.actor.changes == [] and robot.kinds()[-1] == "hold" and "stopping" in robot.actions[-1]["outcome"]


@pytest.mark.quick
def test_an_unanswered_store_is_sent_again_then_reported_not_stored(stand_in_retune):
    """The robot runs the confirmed gains but never answers STORE: the same STORE goes out store_tries times in
    all, then the change is 'not_stored' and the robot's state says it boots on #0 (before: 'confirmed' like a
    stored change, nothing retried)."""
    robot = Robot7(store_tries=3)
    new = {**PLAIN, "control.v_max": 1.2}
    stand_in_retune.update(new)
    robot.confirmed(new)
    change = robot.actor.current()
    robot.actor.end_of_lap()  # the lap's command: STORE
    store = robot.sent[-1]
    assert ",STORE*" in store and change.stored == "pending"
    for _ in range(5):
        time.sleep(0.06)  # past the 0.05 s ack timeout
        robot.actor.idle(time.monotonic())
    assert [line for line in robot.sent if ",STORE*" in line] == [store] * 3  # the same command, 3 times in all
    assert robot.kinds().count("store_retry") == 2 and robot.kinds()[-1] == "not_stored"
    assert change.status == "confirmed" and change.stored == "not_stored"
    assert robot.actor.robot_state() == {"running_seq": change.seq, "stored_seq": 0, "store_pending": None}
    said = robot.actions[-1]
    assert (said["running_seq"], said["stored_seq"]) == (change.seq, 0) and "boots on gains #0" in said["outcome"]
    assert robot.actor.summary()[-1]["stored"] == "not_stored"
    robot.actor.on_record(Reply(int(store.split(",")[1]), "ACK"), time.monotonic())  # answered after all
    assert change.stored == "stored" and robot.actor.robot_state()["stored_seq"] == change.seq
    assert "after all" in robot.actions[-1]["outcome"]


@pytest.mark.quick
def test_a_store_answered_on_its_second_try_is_stored(stand_in_retune):
    robot = Robot7()
    new = {**PLAIN, "control.v_max": 1.2}
    stand_in_retune.update(new)
    robot.confirmed(new)
    change = robot.actor.current()
    robot.actor.end_of_lap()
    seq = int(robot.sent[-1].split(",")[1])
    time.sleep(0.06)
    robot.actor.idle(time.monotonic())
    robot.actor.on_record(Reply(seq, "ACK"), time.monotonic())  # the answer to the second
    assert change.stored == "stored" and robot.actor.robot_state()["stored_seq"] == change.seq
    assert robot.kinds()[-2:] == ["store_retry", "stored"]


@pytest.mark.quick
def test_the_stored_state_is_kept_apart_in_the_history_database(tmp_path, stand_in_retune):
    """Each change's row says what the robot runs (status) and, apart, what it boots on (stored)."""
    from tuner.history.ingest import LogIngest
    from tuner.history.store import History

    robot = Robot7(store_tries=1)
    stand_in_retune.update({**PLAIN, "control.v_max": 1.2})
    robot.confirmed({})
    robot.actor.end_of_lap()
    time.sleep(0.06)
    robot.actor.idle(time.monotonic())
    history = History(f"sqlite:///{tmp_path / 'h.sqlite'}")
    ingest = LogIngest(history, str(tmp_path / "live.log"))
    for i, a in enumerate(robot.actions):
        with history.begin() as c:
            ingest.journal_record(c, a, i)
    with history.begin() as c:
        rows = c.execute(sa.select(schema.gain_changes.c.seq, schema.gain_changes.c.status,
                                   schema.gain_changes.c.stored)).all()
    history.close()
    assert [tuple(r) for r in rows] == [(robot.actor.current().seq, "confirmed", "not_stored")]


@pytest.mark.quick
@pytest.mark.parametrize("stop, allowed_s, said", [(False, 0.0, "the deadline (0 s allowed) would pass"),
                                                  (True, 600.0, "the run is stopping")])
def test_a_re_tune_out_of_time_or_stopped_proposes_nothing_and_says_so(stop, allowed_s, said):
    """The plain gains fail at μ 0.6 (the drift test's aged robot), so a re-tune is needed; with no time left (or
    the run stopping) it proposes nothing, and says which (before: no deadline, it always ran to its end)."""
    from tuner.live.retune import retune_gains

    twin = DigitalTwin()
    twin.update({**PLAIN, "motion.mu": 0.6})
    t0 = time.monotonic()
    r = retune_gains(twin, "motion.mu", 0.55, 0.6, (0, 1), 20.0, deadline=time.monotonic() + allowed_s,
                     stop=lambda: stop)
    assert not r.changed and not r.in_time and r.gains == PLAIN and said in r.note
    assert time.monotonic() - t0 < 60 and r.laps <= 6  # the first race only (3 values × 2 seeds)


def test_a_re_tune_cut_by_its_deadline_answers_with_the_best_found_in_time(monkeypatch):
    """A deadline that ends the descent after its first iteration: the last race runs on that iteration's point,
    and the note says these are the best gains found by the deadline."""
    import tuner.live.retune as retune

    twin = DigitalTwin()
    twin.update({**PLAIN, "motion.mu": 0.6})
    iterations = []
    real = retune.descend

    def counted(f, z, o, on_iteration=None):
        def each(it):
            iterations.append(it)
            on_iteration(it)
        return real(f, z, o, on_iteration=each)

    monkeypatch.setattr(retune, "descend", counted)
    over = iter([False, False] + [True] * 100)  # in time up to the descent, out of time from its first iteration on
    monkeypatch.setattr(retune._Clock, "over", lambda self, *a: next(over))
    r = retune.retune_gains(twin, "motion.mu", 0.55, 0.6, (0, 1), 20.0, deadline=time.monotonic() + 1)
    assert len(iterations) == 1 and not r.in_time and "the best found by the deadline" in r.note
    assert r.changed == (r.gains != PLAIN)


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
