"""The acting loop of ``live --act`` as a transaction (issue 39): nothing goes out once the run is stopping (a
change decided then is withdrawn), a STORE is answered or sent again and failing that reported not stored, the
robot's running and stored gains kept apart (the actor, its journal records and the history database); a re-tune
has a deadline and says whether it kept it. The actor is driven by hand, the re-tuning replaced by the stand-in of
:mod:`test_act` where it is not under test; the end-to-end cases against ``emulate`` are in :mod:`test_act`."""

from __future__ import annotations

import time

import pytest
import sqlalchemy as sa

import tuner.live.act
from test_act import PLAIN, stand_in_retune  # noqa: F401  (fixture)
from tuner.history import schema
from tuner.live import ActOptions, Actor
from twin.core.digital_twin import DigitalTwin
from twin.telemetry.wire import Boot, Header, Reply


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
    ingest = LogIngest(history, str(tmp_path / "live.log"), "test-log")  # the log as the journal names it
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
