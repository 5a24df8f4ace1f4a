"""Acting on the robot (``live --act``): when re-alignment has found what the robot has become, re-tune its gains
on the aligned twin, predict the lap they should give, send them, follow the answer, compare the laps that come
with the prediction, and roll back what did worse (paper §4.2, §5: optimisation during operation).

A change goes through: decided (re-tuned and raced) → sent (SET, its sequence number kept) → ACK (or NAK, or no
answer within ``ack_timeout_s``: the robot keeps its gains, the twin says why) → in force (a lap header carries
its number: the robot applies gains only between laps) → confirmed after ``confirm_laps`` laps (then STORE, so the
robot keeps them across power cycles) or rolled back (SET of the gains before) when those laps did worse than
before: more failures, or slower than both the prediction and the laps before by more than ``tolerance`` (2 %:
a lap's noise and a few laps of drift stay within it).

Guards: gains only inside the tuner's bounds for this robot; at most one change every ``every_laps`` laps; none
while another is unconfirmed; none that the twin has not raced over the envelope (every lap finished); none to a
version 1 robot; none after ``MAX_REFUSALS`` refusals (NAK or silence) in a row; none tuned for the same aligned
value as a change that was rolled back. After each lap the twin sends exactly one command (SET, STORE, or GET,
reading the gains back: a robot that reset or was changed by hand is seen within a lap), which is also what a
robot emulated in lockstep waits for.

The acting loop is a transaction: nothing goes out once the run is stopping (``stopping()``: Ctrl-C, SIGTERM,
``--duration``, or the last lap ``--laps`` watches has come): a change decided then is ``withdrawn``, never sent, and
a STORE not sent leaves the gains unstored. A STORE is acknowledged or sent again (the same sequence number: a
robot that did store answers again without storing twice) up to ``store_tries`` times, each waiting
``ack_timeout_s``; failing that the change is reported ``not_stored``. The robot's two states are kept apart: the
gains it runs (``running_seq``: a lap header or its answer to GET) and the gains it boots on (``stored_seq``: its
BOOT line, or an acknowledged STORE; None while unknown); every action carries both, each change its ``stored``
state (None: not asked; ``pending``, ``stored``, ``not_stored``).

Every action (what, why, the outcome) goes to ``on_action``: the journal beside the log, the history database,
the human lines and ``--json``.
"""

from __future__ import annotations

import dataclasses
import logging
import time
from typing import Callable

import numpy as np

from tuner.live.change import Change, Store, judge
from tuner.live.retune import bounds_for, predict, retune_gains
from twin.core.digital_twin import DigitalTwin
from twin.telemetry.wire import (GAIN_ADDRESSES, KEEPALIVE_S, SEQ_MAX, Boot, Command, Header, KeepAlive, Reply, encode,
                                 gains_from_wire, gains_to_wire, on_the_wire)

log = logging.getLogger(__name__)

MAX_REFUSALS = 2  # NAKs or silences in a row after which the twin stops sending changes


@dataclasses.dataclass(frozen=True)
class ActOptions:
    every_laps: int = 5  # at most one change per this many laps
    confirm_laps: int = 2  # laps with new gains before they are confirmed or rolled back
    ack_timeout_s: float = 3.0  # [s] wall clock to wait for an answer
    margin: float = 0.1  # the envelope reaches this fraction beyond the aligned value
    horizon_laps: int = 10  # … or as far as the parameter's trend goes in this many laps
    seeds: int = 2  # noise seeds per envelope value
    tolerance: float = 0.02  # laps slower than predicted and than before by more than this fraction did worse
    store_tries: int = 3  # STOREs sent (the same one again) before the gains are reported not stored
    retune_deadline_s: float | None = None  # [s] wall clock a re-tune may take; None: horizon_laps laps of the robot


class Actor:
    """The decisions of ``live --act`` for one robot; fed by :class:`tuner.live.live_twin.LiveTwin` in the order
    the robot's lines came, from one thread.

    Args:
      twin: the live twin's twin (its gains are the gains in force, as far as the twin knows).
      address: the re-aligned parameter.
      options: the guards and the envelope.
      seed: the twin's noise seed (predictions); re-tuning uses this and the next seeds.
      send: queues one command line for the robot (with its answer deadline).
      on_action: every action, as a dict.
      next_seq: the first sequence number to use (one past the last the twin sent to this robot).
      known: gains by sequence number the twin sent before (from its journal).
    """

    def __init__(self, twin: DigitalTwin, address: str, options: ActOptions, seed: int,
                 send: Callable[[str, float], None], on_action: Callable[[dict], None], next_seq: int = 1,
                 known: dict[int, dict] | None = None):
        self.twin, self.address, self.o, self.seed = twin, address, options, seed
        self.send_line, self.on_action = send, on_action
        self.seq = max(1, next_seq)
        self.known: dict[int, dict[str, float]] = dict(known or {})
        self.bounds = bounds_for(twin)
        self.changes: list[Change] = []
        self.robot: str | None = None
        self.version: int | None = None
        self.in_force_seq: int | None = None
        self.refusals = 0
        self.retune_progress: Callable[[int, int], None] | None = None  # (done, planned) steps of each re-tune
        self.rolled_back_for: set[float] = set()
        self.pending_command: Command | None = None
        self.lap = 0  # laps seen so far
        self.asked = False  # a GET went out since the robot last (re)started
        self.live = True  # False while the log is replayed: state follows, nothing is sent
        self.stopping: Callable[[], bool] = lambda: False  # the run is ending: nothing more goes out
        self.stored_seq: int | None = None  # the gains the robot boots on (None: not known yet)
        self.store: Store | None = None  # the STORE on its way
        self.given_up: Store | None = None  # the last STORE reported not stored (a late ACK still counts)
        self.keep_alives = 0  # keep-alives sent

    # --- what the robot says ------------------------------------------------------------------------------------

    def on_record(self, rec, arrival: float) -> None:
        if isinstance(rec, Header):
            self._header(rec)
        elif isinstance(rec, Boot):
            self._boot(rec)
        elif isinstance(rec, Reply):
            self._reply(rec, arrival)

    def _header(self, h: Header) -> None:
        self.robot, self.version = h.robot, h.version
        if h.robot is None:
            return
        if self.live and not self.asked:
            self.asked = True
            self._send(Command(self._next_seq(), "GET"))  # what it runs on, before its first lap is compared
        if self._applied(h.gains_seq, "in force from the lap that starts"):
            return
        if h.gains_seq == self.in_force_seq:
            return
        self.in_force_seq = h.gains_seq
        if h.gains_seq in self.known:
            self.twin.update(self.known[h.gains_seq])

    def _applied(self, seq: int, how: str) -> bool:
        """The robot runs gains ``seq`` (a lap header says so, or its answer to GET, whichever the twin reads
        first): when they are the change on its way, it is in force from now on."""
        change = self.current()
        if change is None or seq != change.seq or change.status not in ("sent", "acked", "silent"):
            return False
        late = change.status == "silent"
        change.status, change.first_lap = "in_force", None
        self.in_force_seq = seq
        self.twin.update(change.gains)
        self._act("in_force", change, outcome=how + (" (its answer was lost, but the robot applied it)" if late else ""))
        return True

    def _boot(self, b: Boot) -> None:
        self.asked = False  # a restarted robot: read its gains again
        gains = self.known.get(b.seq) if b.source != "CONFIG" else None
        what = {"STORED": "its stored gains", "BACKUP": "its last good stored gains",
                "CONFIG": "the gains it was flashed with"}[b.source]
        why = f"; {b.bad} stored set(s) failed the CRC check" if b.bad else ""
        self.stored_seq = b.seq
        if self.given_up is not None and b.seq == self.given_up.change.seq:  # reported not stored, yet it boots on them
            self._store_settled(True, "the robot restarted on them: they were stored after all", self.given_up)
        if self.store is not None:  # restarted with a STORE on its way: the BOOT line says whether it was written
            self._store_settled(b.seq == self.store.change.seq, "the robot restarted on its stored gains "
                                f"#{b.seq}" + ("" if b.seq == self.store.change.seq else ": they were not stored"))
        self._act("boot", None, seq=b.seq, gains=gains, source=b.source, bad=b.bad,
                  outcome=f"robot {self.robot or '?'} booted on {what} (#{b.seq}){why}", warn=bool(b.bad))
        current = self.current()
        if current is not None and current.status in ("sent", "acked", "in_force"):
            current.status = "superseded"
            self._act("superseded", current, outcome="the robot restarted before the change was confirmed")

    def _reply(self, r: Reply, arrival: float) -> None:
        if r.seq >= self.seq and r.seq < SEQ_MAX:  # (after a restart: never reuse a number the robot has answered)
            self.seq = r.seq + 1
        change = next((c for c in reversed(self.changes) if c.seq == r.seq), None)
        if r.kind == "GAINS":
            self._gains_read_back(r)
            return
        if self.store is not None and r.seq == self.store.seq:
            self._store_answer(r)
            return
        if self.given_up is not None and r.seq == self.given_up.seq and r.kind == "ACK":  # answered after all
            self._store_settled(True, f"the robot stored gains #{self.given_up.change.seq} after all (a late answer)",
                                self.given_up)
            return
        if change is None:
            if r.kind == "NAK":
                self._act("nak", None, seq=r.seq, reason_code=r.reason, outcome=f"command #{r.seq} refused ({r.reason})")
            return
        if change.status != "sent":
            return  # answered after it was given up on, or answered again
        if arrival > change.deadline:
            return  # too late: it was (or will be) reported silent; a header will show whether it applied
        if r.kind == "ACK":
            change.status = "acked"
            self.refusals = 0
            self._act("ack", change, outcome="accepted: in force from the robot's next lap")
        else:
            change.status = "nak"
            self.refusals += 1
            self._act("nak", change, reason_code=r.reason, warn=True,
                      outcome=f"refused ({r.reason}): the robot keeps its gains #{change.previous_seq}")

    def _gains_read_back(self, r: Reply) -> None:
        if self._applied(r.in_force, "in force (the robot's answer to GET says so)"):
            return
        gains = gains_from_wire(r.gains)
        self.known.setdefault(r.in_force, gains)
        believed = {a: self.twin.space.get(a) for a in GAIN_ADDRESSES}
        if gains_to_wire(believed) != r.gains:
            self.twin.update(gains)
            self._act("adopt", None, seq=r.in_force, gains=gains,
                      outcome=f"the robot runs gains #{r.in_force}: the twin follows them")
        self.in_force_seq = r.in_force

    def idle(self, now: float) -> None:
        """No answer by the deadline: the robot keeps its gains; a STORE is sent again, or reported not stored."""
        st = self.store
        if st is not None and st.deadline is not None and now > st.deadline:
            if st.tries < self.o.store_tries and self.live and not self.stopping():
                self._act("store_retry", st.change, store_seq=st.seq, warn=True,
                          outcome=f"no answer to STORE #{st.seq} within {self.o.ack_timeout_s:g} s: sent again "
                                  f"({st.tries + 1} of {self.o.store_tries})")
                self._send_store()
            else:
                self._store_settled(False, f"no answer to STORE #{st.seq} after {st.tries} tries")
        change = self.current()
        if change is not None and change.status == "sent" and now > change.deadline:
            change.status = "silent"
            self.refusals += 1
            self._act("silent", change, warn=True, outcome=f"no answer within {self.o.ack_timeout_s:g} s: the robot "
                      f"keeps its gains #{change.previous_seq}")

    # --- laps and decisions ------------------------------------------------------------------------------------

    def current(self) -> Change | None:
        return self.changes[-1] if self.changes else None

    def busy(self) -> bool:
        """A change is on its way or being confirmed, or its STORE: no re-alignment, no new change."""
        c = self.current()
        return self.store is not None or (c is not None and c.status in ("sent", "acked", "in_force"))

    def observe(self, entry: dict, recent: list[dict]) -> None:
        """A lap (the live twin's entry): counted for the change in force, which may be judged now."""
        self.lap = entry["lap"] + 1
        c = self.current()
        if c is None or c.status != "in_force" or entry.get("gains_seq") != c.seq or entry.get("implausible"):
            return
        if c.first_lap is None:
            c.first_lap = entry["lap"]
            c.before = [e for e in recent if e["lap"] < c.first_lap and not e.get("implausible")][-self.o.confirm_laps:]
        c.after.append(entry)
        if len(c.after) < self.o.confirm_laps:
            return
        worse, why = judge(c, self.o.tolerance)
        if not worse or c.kind == "rollback":
            c.status = "confirmed"
            self._act("confirm", c, outcome=why)
            if c.kind == "retune":
                self.store = Store(self._next_seq(), c)
                c.stored = "pending"
                self.pending_command = Command(self.store.seq, "STORE")
            return
        c.status = "rolled_back"
        self.rolled_back_for.add(round(c.aligned.get(self.address, float("nan")), 6))
        self._act("rollback", c, warn=True, outcome=f"worse than before ({why}): back to gains #{c.previous_seq}")
        if c.kind == "retune":
            self._propose(dict(c.previous), "rollback", f"change #{c.seq} did worse than before ({why})", entry["lap"])

    def consider(self, alignment: dict, lap: int, robot_lap_s: float | None, trend: float | None) -> None:
        """After an alignment: keep the gains if they finish over the envelope, else re-tune and send."""
        if not alignment.get("explained") or alignment.get("value") is None:
            return
        value = float(alignment["value"])
        hold = self._guard(lap, value)
        if hold:
            self._act("hold", None, outcome=hold, aligned={self.address: value})
            return
        if self.stopping():
            self._act("hold", None, outcome="the run is stopping: no re-tune, nothing sent", aligned={self.address: value})
            return
        low, high = self._envelope(value, trend)
        timeout = 2 * robot_lap_s if robot_lap_s else 60.0
        # by default horizon_laps laps of the robot: the envelope reaches as far as the parameter goes in as many
        # laps, so gains that came later would be tuned for a robot already past it
        allowed = self.o.retune_deadline_s or (self.o.horizon_laps * robot_lap_s if robot_lap_s else timeout)
        r = retune_gains(self.twin, self.address, low, high, tuple(range(self.seed, self.seed + self.o.seeds)), timeout,
                         deadline=time.monotonic() + allowed, stop=self.stopping,
                         progress=self.retune_progress)
        self._act("retune", None, aligned={self.address: value}, envelope=r.envelope, gains=r.gains, laps=r.laps,
                  wall_s=round(r.wall_s, 2), deadline_s=round(allowed, 2), in_time=r.in_time,
                  outcome=r.note + ("" if r.changed else "; no change"))
        if not r.changed:
            return
        if not r.completes:
            self._act("hold", None, outcome="no gains found that finish every lap of the envelope: the robot keeps "
                      "its gains", aligned={self.address: value})
            return
        reason = (f"{self.address} aligned to {value:.4g}: the gains in force do not finish every lap with "
                  f"{self.address} in [{low:.4g}, {high:.4g}]")
        self._propose(r.gains, "retune", reason, lap)

    def _guard(self, lap: int, value: float) -> str | None:
        if self.version != 2:
            return "the robot speaks wire version 1: it takes no commands, so the twin only watches"
        if self.refusals >= MAX_REFUSALS:
            return f"the robot refused the last {self.refusals} changes: the twin sends no more"
        if self.busy():
            return (f"change #{self.current().seq} is not confirmed yet" if self.store is None else
                    f"the STORE of gains #{self.store.change.seq} is not answered yet")
        last = self.current()
        if last is not None and lap - last.decided_lap < self.o.every_laps:
            return f"the last change was decided {lap - last.decided_lap} laps ago (at most one every {self.o.every_laps})"
        if round(value, 6) in self.rolled_back_for:
            return f"a change tuned for {self.address} = {value:.4g} was rolled back: not tried again"
        return None

    def _envelope(self, value: float, trend: float | None) -> tuple[float, float]:
        p = self.twin.space.parameter(self.address)
        direction = -1.0 if trend is None or trend <= 0 else 1.0
        far = value * (1 + direction * self.o.margin)
        if trend is not None:
            along = value + trend * self.o.horizon_laps
            far = min(far, along) if direction < 0 else max(far, along)
        far = float(np.clip(far, p.lower, p.upper))
        return min(value, far), max(value, far)

    def _propose(self, gains: dict[str, float], kind: str, reason: str, lap: int) -> None:
        gains = on_the_wire(gains)
        for a, v in gains.items():  # the tuner's bounds; a rollback returns to gains the robot ran
            lo, hi = self.bounds[a]
            if kind == "retune" and not lo <= v <= hi:
                self._act("hold", None, outcome=f"{a} = {v:g} is outside the tuner's bounds [{lo:g}, {hi:g}]")
                return
        previous = {a: self.twin.space.get(a) for a in GAIN_ADDRESSES}
        lap_result = predict(self.twin, gains, self.seed)  # raced before it is sent
        predicted = lap_result.lap_time_s if lap_result.completed else None
        c = Change(self._next_seq(), kind, gains, previous, self.in_force_seq or 0, reason, predicted,
                   {self.address: self.twin.space.get(self.address)}, lap)
        self.changes.append(c)
        self.known[c.seq] = gains
        self.pending_command = Command(c.seq, "SET", gains_to_wire(gains))
        self._act("decide", c, outcome=f"predicted lap {predicted:.3f} s" if predicted else "predicted lap fails")
        if self.stopping():
            self._withdraw()

    def end_of_lap(self) -> None:
        """The one command of this lap: a decided SET, a STORE, or GET; none once the run is stopping (what was
        decided is withdrawn)."""
        if not self.live or self.version != 2:
            self.pending_command = None
            return
        if self.stopping():
            self._withdraw()
            return
        cmd = self.pending_command or Command(self._next_seq(), "GET")
        self.pending_command = None
        c = self.current()
        if cmd.op == "SET" and c is not None and c.seq == cmd.seq:
            c.status, c.deadline = "sent", time.monotonic() + self.o.ack_timeout_s
            self._act("send", c, outcome=encode(cmd).strip())
        if self.store is not None and cmd.op == "STORE" and cmd.seq == self.store.seq:
            self._send_store()
            return
        self._send(cmd)

    def _withdraw(self) -> None:
        """The run is stopping: what was decided and not sent stays unsent, and is journaled so."""
        cmd, self.pending_command = self.pending_command, None
        if cmd is None:
            return
        c = self.current()
        if cmd.op == "SET" and c is not None and c.seq == cmd.seq and c.status == "decided":
            c.status = "withdrawn"
            self._act("withdraw", c, outcome=f"decided but not sent: the run stopped; the robot keeps its gains "
                      f"#{c.previous_seq}")
        elif cmd.op == "STORE" and self.store is not None and cmd.seq == self.store.seq:
            self._store_settled(False, "the STORE was not sent: the run stopped")

    def _send_store(self) -> None:
        st = self.store
        st.tries += 1
        st.deadline = time.monotonic() + self.o.ack_timeout_s
        self._send(Command(st.seq, "STORE"))

    def _store_answer(self, r: Reply) -> None:
        st = self.store
        if r.kind == "ACK":
            self._store_settled(True, f"the robot stored gains #{st.change.seq} in its EEPROM: it boots on them")
        elif r.reason == "EEPROM" and st.tries < self.o.store_tries and self.live and not self.stopping():
            self._act("store_retry", st.change, store_seq=st.seq, warn=True,
                      outcome=f"STORE #{st.seq} failed (EEPROM): sent again ({st.tries + 1} of {self.o.store_tries})")
            self._send_store()
        else:
            self._store_settled(False, f"STORE #{st.seq} refused ({r.reason})")

    def _store_settled(self, stored: bool, why: str, st: Store | None = None) -> None:
        """A STORE (default: the one on its way) has an outcome: the robot boots on the change's gains, or on what
        it did before."""
        st = st or self.store
        if st is self.store:
            self.store = None
        self.given_up = None if stored else st
        st.change.stored = "stored" if stored else "not_stored"
        if stored:
            self.stored_seq = st.change.seq
            self._act("stored", st.change, store_seq=st.seq, outcome=why)
            return
        boots = "unknown gains" if self.stored_seq is None else f"gains #{self.stored_seq}"
        self._act("not_stored", st.change, store_seq=st.seq, warn=True,
                  outcome=f"{why}: the robot runs gains #{st.change.seq} but at its next power-up boots on {boots}")

    def keep_alive(self) -> None:
        """The twin is busy (re-tuning): tell a robot that waits that it is there (nothing once stopping)."""
        if self.live and self.version == 2 and not self.stopping():
            self.keep_alives += 1
            self.send_line(encode(KeepAlive((self.keep_alives - 1) % SEQ_MAX + 1)), time.monotonic() + KEEPALIVE_S)

    def _send(self, cmd: Command) -> None:
        if self.stopping():
            log.info("act: %s #%d not sent: the run is stopping", cmd.op, cmd.seq)
            return
        if self.live:
            line = encode(cmd)
            self.send_line(line, time.monotonic() + self.o.ack_timeout_s)
            self.on_action({"kind": "command", "robot": self.robot, "lap": self.lap, "time": round(time.time(), 3),
                            "seq": cmd.seq, "op": cmd.op, "line": line.strip()})

    def _next_seq(self) -> int:
        s = self.seq
        self.seq = 1 if s >= SEQ_MAX else s + 1
        return s

    def _act(self, kind: str, change: Change | None, warn: bool = False, **fields) -> None:
        action = {"kind": kind, "robot": self.robot, "lap": self.lap, "time": round(time.time(), 3)}
        if change is not None:
            action.update(seq=change.seq, change=change.kind, gains=change.gains, previous=change.previous,
                          previous_seq=change.previous_seq, reason=change.reason, status=change.status,
                          predicted_lap_time_s=change.predicted_lap_time_s, aligned=change.aligned,
                          decided_lap=change.decided_lap, stored=change.stored)
        action.update(running_seq=self.in_force_seq, stored_seq=self.stored_seq)
        action.update(fields)
        (log.warning if warn else log.info)("act: %s%s: %s", kind, f" #{change.seq}" if change else "",
                                            action.get("outcome", ""))
        if self.live:
            self.on_action(action)

    def summary(self) -> list[dict]:
        return [{"seq": c.seq, "kind": c.kind, "status": c.status, "stored": c.stored, "gains": c.gains,
                 "previous_seq": c.previous_seq, "reason": c.reason, "predicted_lap_time_s": c.predicted_lap_time_s,
                 "decided_lap": c.decided_lap, "first_lap": c.first_lap,
                 "after": [e["robot_lap_time_s"] for e in c.after]} for c in self.changes]

    def robot_state(self) -> dict:
        """What the robot runs and what it boots on, as far as the twin knows (None: not known)."""
        return {"running_seq": self.in_force_seq, "stored_seq": self.stored_seq,
                "store_pending": self.store.seq if self.store is not None else None}
