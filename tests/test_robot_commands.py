"""The command link (wire version 2, twin.telemetry.wire; the robot's end, twin.link.robot_end): records round-trip
and version 1 lines are still read; a robot applies gains only between laps, answers every command once (a repeat
gets the same answer), refuses what it cannot take; stored gains carry a CRC and a robot whose newest set fails the
check boots on the one before and says so; a keep-alive is echoed and is no command; a drift is linear and
checked."""

from __future__ import annotations

import pytest

from twin.core.digital_twin import DigitalTwin
from twin.errors import TwinError
from twin.link.emulator import Drift, check_drifts, drifted
from twin.link.robot_end import IMAGE_SIZE, SLOT_SIZE, EepromFile, RobotEnd, read_stored
from twin.telemetry.laps import LapAssembler
from twin.telemetry.wire import (Boot, Command, Event, Header, KeepAlive, Reply, UnknownCommand, WireError, decode, encode,
                                 frame, gains_to_wire, on_the_wire)

pytestmark = pytest.mark.quick

FLASHED = {"control.v_max": 0.6, "control.kb": 0.5, "control.kp": 15.0, "control.ki": 0.0, "control.kd": 0.3}
LIMITS = {a: (0.0, 100.0) for a in FLASHED}
NEW = {"control.v_max": 1.1, "control.kb": 0.2, "control.kp": 31.0, "control.ki": 0.0, "control.kd": 1.12}  # arbitrary, for the wire


def robot(**kw) -> RobotEnd:
    return RobotEnd("r7", FLASHED, LIMITS, **kw)


def send(r: RobotEnd, *commands) -> list:
    return [decode(line) for line in r.receive("".join(encode(c) for c in commands).encode())]


def test_records_round_trip_and_version_1_is_still_read():
    records = [Header(8, 0.005, 2), Header(8, 0.005, 2, "robot-7_B", 12), Boot(1.5, "BACKUP", 12, 1),
               Command(5, "SET", gains_to_wire(NEW)), Command(6, "GET"), Command(7, "STORE"), Reply(5, "ACK"),
               Reply(5, "NAK", "RANGE"), Reply(6, "GAINS", in_force=5, gains=gains_to_wire(NEW))]
    for rec in records:
        assert decode(encode(rec)) == rec and len(encode(rec)) < 70
    assert encode(Header(8, 0.005, 2)) == "$LFH,1,8,5000,2*7C\n"  # what version 1 firmware sends, unchanged
    assert decode(encode(Header(8, 0.005, 2))).version == 1
    for bad in (frame(["LFH", 2, "no spaces!", 8, 5000, 2, 0]), frame(["LFH", 3, 8, 5000, 2]),
                frame(["LFC", 0, "GET"]), frame(["LFR", 5, "GAINS", 1, 2])):
        with pytest.raises(WireError):
            decode(bad)
    with pytest.raises(UnknownCommand) as e:
        decode(frame(["LFC", 9, "REBOOT"]))
    assert e.value.seq == 9
    assert on_the_wire({**NEW, "control.kp": 33.520195})["control.kp"] == 33.52


def test_gains_change_only_between_laps_and_every_command_is_answered_once():
    r = robot()
    assert decode(r.boot()) == Boot(0.0, "CONFIG", 0, 0)
    assert send(r, Command(1, "SET", gains_to_wire(NEW))) == [Reply(1, "ACK")]
    assert r.in_force() == FLASHED  # staged, not applied mid-lap
    assert send(r, Command(2, "GET")) == [Reply(2, "GAINS", in_force=0, gains=gains_to_wire(FLASHED))]
    assert r.lap_start() == (NEW, 1)
    assert send(r, Command(2, "GET")) == [Reply(2, "GAINS", in_force=0, gains=gains_to_wire(FLASHED))]  # a repeat
    too_fast = {**NEW, "control.v_max": 250.0}
    assert send(r, Command(3, "SET", gains_to_wire(too_fast))) == [Reply(3, "NAK", "RANGE")]
    assert send(r, Command(4, "GET")) == [Reply(4, "GAINS", in_force=1, gains=gains_to_wire(NEW))]
    assert r.receive(frame(["LFC", 5, "REBOOT"]).encode()) == [encode(Reply(5, "NAK", "BADCMD"))]
    assert r.receive(b"$LFC,6,GET*00\n") == []  # a bad checksum is not answered: the twin's wait ends
    locked = robot(commands="nak")
    assert send(locked, Command(1, "SET", gains_to_wire(NEW)), Command(2, "STORE")) == [
        Reply(1, "NAK", "LOCKED"), Reply(2, "NAK", "LOCKED")]
    deaf = robot(commands="ignore")
    assert send(deaf, Command(1, "SET", gains_to_wire(NEW))) == [] and deaf.lap_start() == (FLASHED, 0)


def test_a_keep_alive_is_echoed_and_is_no_command():
    """The twin's keep-alive ($LFK,n, checksum by hand: L^F^K^,^1 = 0x4C^0x46^0x4B^0x2C^0x31 = 0x5C) is answered at
    once with the same line; it changes nothing, does not replace the last command's answer, and is not counted as a
    command (a robot in lockstep waits on for the lap's)."""
    assert encode(KeepAlive(1)) == "$LFK,1*5C\n" and decode("$LFK,1*5C") == KeepAlive(1)
    for bad in (frame(["LFK", 0]), frame(["LFK", 65536]), frame(["LFK"])):
        with pytest.raises(WireError):
            decode(bad)
    r = robot()
    assert send(r, Command(1, "SET", gains_to_wire(NEW))) == [Reply(1, "ACK")]
    assert send(r, KeepAlive(7), KeepAlive(8)) == [KeepAlive(7), KeepAlive(8)]
    assert (r.received, r.keep_alives) == (1, 2)
    assert send(r, Command(1, "SET", gains_to_wire(NEW))) == [Reply(1, "ACK")]  # still the repeat of the last command
    assert r.lap_start() == (NEW, 1)
    assert robot(commands="nak").receive(encode(KeepAlive(3)).encode()) == [encode(KeepAlive(3))]
    assert robot(commands="ignore").receive(encode(KeepAlive(3)).encode()) == []  # a cut receive line


def test_stored_gains_survive_a_power_cycle_and_a_corrupted_set_falls_back_to_the_one_before(tmp_path):
    path = str(tmp_path / "eeprom.bin")
    r = robot(eeprom=EepromFile(path))
    r.boot()
    for seq, gains in ((1, NEW), (3, {**NEW, "control.v_max": 1.2})):
        send(r, Command(seq, "SET", gains_to_wire(gains)))
        r.lap_start()
        assert send(r, Command(seq + 1, "STORE")) == [Reply(seq + 1, "ACK")]
    again = robot(eeprom=EepromFile(path))
    assert decode(again.boot()) == Boot(0.0, "STORED", 3, 0) and again.in_force()["control.v_max"] == 1.2
    image = bytearray(open(path, "rb").read())
    newest = read_stored(bytes(image))[4]
    image[newest * SLOT_SIZE + 10] ^= 0x40  # one bit of the newest set's gains
    open(path, "wb").write(bytes(image))
    fallen = robot(eeprom=EepromFile(path))
    assert decode(fallen.boot()) == Boot(0.0, "BACKUP", 1, 1) and fallen.in_force() == NEW
    send(fallen, Command(9, "STORE"))  # storing again overwrites the bad slot, not the good one
    assert read_stored(open(path, "rb").read())[:4] == ("STORED", 1, gains_to_wire(NEW), 0)
    (tmp_path / "notes.bin").write_bytes(b"mine")
    with pytest.raises(TwinError, match="left as it is"):
        EepromFile(str(tmp_path / "notes.bin"))
    assert (tmp_path / "notes.bin").read_bytes() == b"mine" and IMAGE_SIZE == 60


def test_laps_carry_the_robot_and_the_gains_in_force_and_a_drift_is_linear():
    a = LapAssembler()
    for rec in (Header(8, 0.005, 2, "r7", 4), Event(0.0, "START"), Event(7.0, "FAIL", reason="off_track")):
        lap = a.feed(rec)
    assert (lap.robot, lap.gains_seq, lap.failure, lap.lap_time_s) == ("r7", 4, "off_track", None)
    twin = DigitalTwin()
    d = Drift.parse("motion.mu=0.9:0.5@40", twin)
    assert (d.at(0), d.at(20), d.at(40), d.at(99)) == (0.9, pytest.approx(0.7), pytest.approx(0.5), pytest.approx(0.5))
    for bad, why in (("motion.mu=0.9:0.5", "START:END@LAPS"), ("cad.L=0.04:0.05@3", "rebuilds"),
                     ("motion.mu=0.9:9@3", "motion.mu"), ("motion.mu=0.9:0.5@0", "at least 1"),
                     ("motion.mu=0.9:0.5@40:wobbly", "linear|accelerating|step@K"),
                     ("motion.mu=0.9:0.5@40:step", "step@K"), ("motion.mu=0.9:0.5@40:linear@3", "step@K"),
                     ("motion.mu=0.9:0.5@40:step@0", "at least 1")):
        with pytest.raises(TwinError, match=why):
            Drift.parse(bad, twin)


@pytest.mark.quick
def test_drifts_accelerate_step_back_and_come_two_at_once():
    twin = DigitalTwin()
    acc = Drift.parse("motion.mu=0.9:0.5@40:accelerating", twin)  # 0.9 − 0.4·(lap/40)²
    assert (acc.at(0), acc.at(20), acc.at(40), acc.at(60)) == (0.9, pytest.approx(0.8), pytest.approx(0.5),
                                                                pytest.approx(0.5))
    step = Drift.parse("motion.mu=0.9:0.5@40:step@30", twin)  # renewed at lap 30, then wearing from 0.9 again
    assert (step.at(29), step.at(30), step.at(40)) == (pytest.approx(0.61), 0.9, pytest.approx(0.8))
    assert Drift.parse("motion.mu=0.9:0.5@40:linear", twin) == Drift.parse("motion.mu=0.9:0.5@40", twin)
    both = [Drift.parse("motion.mu=0.9:0.6@40", twin), Drift.parse("motor.supply_voltage=6:5@40", twin)]
    check_drifts(both)
    assert drifted(both, 20) == {"motion.mu": pytest.approx(0.75), "motor.supply_voltage": pytest.approx(5.5)}
    with pytest.raises(TwinError, match="more than once"):
        check_drifts([both[0], Drift.parse("motion.mu=0.8:0.7@10", twin)])
