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

Every action (what, why, the outcome) goes to ``on_action``: the journal beside the log, the history database,
the human lines and ``--json``.
"""

from __future__ import annotations

import dataclasses
import logging
import time
from typing import Callable

import numpy as np

from tuner.live.retune import bounds_for, predict, retune_gains
from twin.core.digital_twin import DigitalTwin
from twin.telemetry.wire import (GAIN_ADDRESSES, SEQ_MAX, Boot, Command, Header, Reply, encode, gains_from_wire,
                                 gains_to_wire, on_the_wire)

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


@dataclasses.dataclass
class Change:
    seq: int
    kind: str  # retune or rollback
    gains: dict[str, float]
    previous: dict[str, float]
    previous_seq: int
    reason: str
    predicted_lap_time_s: float | None
    aligned: dict[str, float]
    decided_lap: int
    status: str = "decided"  # sent, acked, nak, silent, in_force, confirmed, rolled_back, superseded
    deadline: float = 0.0
    first_lap: int | None = None
    before: list[dict] = dataclasses.field(default_factory=list)
    after: list[dict] = dataclasses.field(default_factory=list)


def _times(entries: list[dict]) -> tuple[int, float | None]:
    done = [e["robot_lap_time_s"] for e in entries if e["robot_lap_time_s"] is not None]
    return len(entries) - len(done), (float(np.mean(done)) if done else None)


def judge(change: Change, tolerance: float) -> tuple[bool, str]:
    """(worse than before, why): the laps with the new gains against the prediction and the laps before them."""
    fails_after, after = _times(change.after)
    fails_before, before = _times(change.before)
    if fails_after > fails_before:
        return True, f"{fails_after} of {len(change.after)} laps failed with them, {fails_before} before"
    if after is None:
        return False, "every lap failed, as before"
    p = change.predicted_lap_time_s
    off = f"{after:.3f} s against {p:.3f} s predicted" if p else f"{after:.3f} s"
    slower_than_predicted = p is not None and after > p * (1 + tolerance)
    if slower_than_predicted and before is not None and after > before * (1 + tolerance):
        return True, f"{off}, slower than the {before:.3f} s before"
    return False, off + (f", {before:.3f} s before" if before is not None else "")


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
        self.pending_store: int | None = None  # the STORE sent after the last confirmation
        self.lap = 0  # laps seen so far
        self.asked = False  # a GET went out since the robot last (re)started
        self.live = True  # False while the log is replayed: state follows, nothing is sent

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
        if change is None:
            if r.kind == "NAK":
                self._act("nak", None, seq=r.seq, reason_code=r.reason, outcome=f"command #{r.seq} refused ({r.reason})")
            elif self.pending_store == r.seq:
                self._act("stored", None, seq=r.seq, outcome="the robot stored the confirmed gains in its EEPROM")
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
        """No answer by the deadline: the robot keeps its gains."""
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
        """A change is on its way or being confirmed: no re-alignment, no new change."""
        c = self.current()
        return c is not None and c.status in ("sent", "acked", "in_force")

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
                self.pending_command = Command(self._next_seq(), "STORE")
                self.pending_store = self.pending_command.seq
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
        low, high = self._envelope(value, trend)
        timeout = 2 * robot_lap_s if robot_lap_s else 60.0
        r = retune_gains(self.twin, self.address, low, high, tuple(range(self.seed, self.seed + self.o.seeds)), timeout,
                         progress=self.retune_progress)
        self._act("retune", None, aligned={self.address: value}, envelope=r.envelope, gains=r.gains, laps=r.laps,
                  wall_s=round(r.wall_s, 2), outcome=r.note + ("" if r.changed else "; no change"))
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
            return f"change #{self.current().seq} is not confirmed yet"
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

    def end_of_lap(self) -> None:
        """The one command of this lap: a decided SET, a STORE, or GET."""
        if not self.live or self.version != 2:
            self.pending_command = None
            return
        cmd = self.pending_command or Command(self._next_seq(), "GET")
        self.pending_command = None
        c = self.current()
        if cmd.op == "SET" and c is not None and c.seq == cmd.seq:
            c.status, c.deadline = "sent", time.monotonic() + self.o.ack_timeout_s
            self._act("send", c, outcome=encode(cmd).strip())
        self._send(cmd)

    def _send(self, cmd: Command) -> None:
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
                          decided_lap=change.decided_lap)
        action.update(fields)
        (log.warning if warn else log.info)("act: %s%s: %s", kind, f" #{change.seq}" if change else "",
                                            action.get("outcome", ""))
        if self.live:
            self.on_action(action)

    def summary(self) -> list[dict]:
        return [{"seq": c.seq, "kind": c.kind, "status": c.status, "gains": c.gains, "previous_seq": c.previous_seq,
                 "reason": c.reason, "predicted_lap_time_s": c.predicted_lap_time_s, "decided_lap": c.decided_lap,
                 "first_lap": c.first_lap, "after": [e["robot_lap_time_s"] for e in c.after]} for c in self.changes]
