"""The robot's end of the command link (:mod:`twin.telemetry.wire`, "Twin → robot"), as the emulated C robot runs
it, and the stored-gains slots of its EEPROM, which the twin's ATmega328P program keeps in the same layout.

* **Commands.** SET is checked against the range the firmware accepts (the model space's range of each gain),
  answered at once, and applied only at the next lap start; GET answers the gains in force; STORE writes them to
  EEPROM, reads them back and answers. A command repeating the last sequence number gets the last answer again.
  A keep-alive (``$LFK``) is echoed at once and is no command: it changes nothing and is not counted in
  :attr:`RobotEnd.received` (a robot in lockstep goes on waiting for the lap's command).
* **Stored gains.** Two slots of ``"LFG2" | gen | seq | five gains | CRC-16/XMODEM`` (:data:`SLOT`, 30 bytes
  each). STORE writes the slot that does not hold the newest good set; at power-up the newest slot whose CRC
  checks wins, and the robot says which it took and how many failed (the BOOT event).
* **Faults a test asks for**: ``commands="nak"`` refuses every SET and STORE (NAK,LOCKED: its owner locked the
  gains), ``commands="ignore"`` answers nothing and applies nothing (its receive line is cut),
  ``commands="no-store"`` answers SET and GET but neither writes nor answers a STORE (an EEPROM write that hangs).
"""

from __future__ import annotations

import logging
import os
import struct
from typing import Mapping

from lf_common.crc import CRC_BYTES, crc_ok, with_crc
from lf_common.errors import LineFollowerError
from lf_common.files import atomic_file
from twin.errors import TwinError
from twin.telemetry.wire import (GAIN_ADDRESSES, Boot, Command, KeepAlive, LineSplitter, Reply, UnknownCommand, WireError,
                                 decode, encode, gains_from_wire, gains_to_wire)

log = logging.getLogger(__name__)

MAGIC = b"LFG2"
SLOT = struct.Struct("<4sHH5i")  # magic, generation, seq, gains in thousandths; then the CRC (uint16)
SLOT_SIZE = SLOT.size + CRC_BYTES  # 30 bytes
SLOTS = 2
IMAGE_SIZE = SLOT_SIZE * SLOTS  # the C robot's EEPROM file: the two slots
COMMAND_MODES = ("answer", "nak", "ignore", "no-store")


def pack_slot(generation: int, seq: int, gains: tuple[int, ...]) -> bytes:
    body = SLOT.pack(MAGIC, generation & 0xFFFF, seq, *gains)
    return with_crc(body)


def unpack_slot(raw: bytes) -> tuple[int, int, tuple[int, ...]] | None:
    """(generation, seq, gains) of a good slot; None if it was never written or fails its check."""
    if len(raw) < SLOT_SIZE or raw[:4] != MAGIC or not crc_ok(raw[:SLOT_SIZE]):
        return None
    magic, generation, seq, *gains = SLOT.unpack(raw[:SLOT.size])
    return generation, seq, tuple(gains)


def _newer(a: int, b: int) -> bool:
    """Generation a is after b, counting on 16 bits that wrap."""
    return a != b and (a - b) & 0xFFFF < 0x8000


def read_stored(image: bytes) -> tuple[str, int, tuple[int, ...] | None, int, int]:
    """What a robot boots on from its slots: (source, seq, gains or None for CONFIG, bad slots, newest slot index).
    A slot that was never written (erased, 0xFF) is not bad; one with the mark whose CRC fails is."""
    good, bad = [], 0
    for i in range(SLOTS):
        raw = image[i * SLOT_SIZE:(i + 1) * SLOT_SIZE]
        slot = unpack_slot(raw)
        if slot is not None:
            good.append((i, *slot))
        elif raw[:4] == MAGIC or (raw and raw != b"\xff" * len(raw)):
            bad += 1
    if not good:
        return "CONFIG", 0, None, bad, -1
    newest = good[0]
    for g in good[1:]:
        if _newer(g[1], newest[1]):
            newest = g
    # BACKUP: the slot after the newest good one was written later (its generation would follow) but is bad
    source = "BACKUP" if bad else "STORED"
    return source, newest[2], newest[3], bad, newest[0]


def _why_not_image(path: str) -> str | None:
    """Why the file is not an EEPROM image this program wrote (None: it is one). Every image written holds a
    stored set, so at least one slot starts with :data:`MAGIC`, even when a bit of it has since flipped (a slot
    that fails its CRC is the robot's to report, not a stranger's file)."""
    try:
        with open(path, "rb") as f:
            image = f.read(IMAGE_SIZE + 1)
    except OSError as e:
        return f"cannot be read ({e.strerror or e})"
    if len(image) != IMAGE_SIZE:
        return f"{len(image) if len(image) <= IMAGE_SIZE else 'more than ' + str(IMAGE_SIZE)} bytes, expected {IMAGE_SIZE}"
    if not any(image[i * SLOT_SIZE:i * SLOT_SIZE + len(MAGIC)] == MAGIC for i in range(SLOTS)):
        return f"no stored-gains slot: neither of its {SLOTS} slots of {SLOT_SIZE} bytes begins with {MAGIC.decode()}"
    return None


def _is_image(path: str) -> bool:
    return _why_not_image(path) is None


class EepromFile:
    """The emulated robot's EEPROM, kept in a file of exactly :data:`IMAGE_SIZE` bytes, its two slots (created on
    the first STORE; a file there that is not such an image, :func:`_why_not_image`, is refused, untouched). Each
    write replaces it atomically."""

    def __init__(self, path: str):
        self.path = path
        if os.path.isdir(path):
            raise TwinError(f"{path}: is a folder; name a file for the robot's EEPROM image")
        if os.path.exists(path):
            why = _why_not_image(path)
            if why is not None:
                raise TwinError(f"{path}: is not this robot's EEPROM image ({why}); it is left as it is")
        elif not os.path.isdir(os.path.dirname(os.path.abspath(path))):
            raise TwinError(f"{path}: folder {os.path.dirname(os.path.abspath(path))} does not exist")

    def read(self) -> bytes:
        try:
            with open(self.path, "rb") as f:
                return f.read(IMAGE_SIZE + 1)[:IMAGE_SIZE].ljust(IMAGE_SIZE, b"\xff")
        except FileNotFoundError:
            return b"\xff" * IMAGE_SIZE

    def write(self, image: bytes) -> None:
        with atomic_file(self.path, _is_image, "robot's EEPROM image", binary=True) as f:
            f.write(image)


class RobotEnd:
    """The command side of an emulated robot: the gains in force, the staged SET, the last answer, the EEPROM.

    Args:
      robot_id: its id on the wire.
      flashed: the gains it was flashed with (by address).
      limits: {address: (lo, hi)} the firmware accepts for each gain.
      eeprom: its EEPROM image file, or None for an EEPROM that starts erased and is not kept.
      commands: ``answer`` (default), ``nak``, ``ignore`` or ``no-store`` (see the module docstring).
    """

    def __init__(self, robot_id: str, flashed: Mapping[str, float], limits: Mapping[str, tuple[float, float]],
                 eeprom: EepromFile | None = None, commands: str = "answer"):
        if commands not in COMMAND_MODES:
            raise TwinError(f"commands {commands!r}: expected one of {', '.join(COMMAND_MODES)}")
        self.robot_id, self.limits, self.eeprom, self.mode = robot_id, dict(limits), eeprom, commands
        self.image = eeprom.read() if eeprom else b"\xff" * IMAGE_SIZE
        self.gains = gains_to_wire(flashed)  # in force
        self.seq = 0  # the command that set them
        self.staged: tuple[int, tuple[int, ...]] | None = None
        self.last: tuple[int, str] | None = None  # (seq, answer line) of the last command answered
        self.splitter = LineSplitter()
        self.received = 0  # commands decoded (answered or not)
        self.keep_alives = 0  # keep-alives decoded (echoed unless commands are ignored)

    def boot(self, t: float = 0.0) -> str:
        """Power-up: load the newest good stored set; the BOOT line saying what it runs on."""
        source, seq, gains, bad, _ = read_stored(self.image)
        if gains is not None:
            self.gains, self.seq = gains, seq
        if bad:
            log.warning("robot %s: %d stored gain set(s) failed the CRC check; running on %s #%d", self.robot_id, bad,
                        source.lower(), seq)
        return encode(Boot(t, source, seq, bad))

    def in_force(self) -> dict[str, float]:
        return gains_from_wire(self.gains)

    def lap_start(self) -> tuple[dict[str, float], int]:
        """Between laps: a staged SET takes effect. The gains for the lap that starts, and their command."""
        if self.staged is not None:
            self.seq, self.gains = self.staged
            self.staged = None
        return self.in_force(), self.seq

    def receive(self, data: bytes) -> list[str]:
        """Bytes from the twin → the answer lines to send (none for lines that do not decode)."""
        out = []
        for raw in self.splitter.feed(data):
            if raw is None:
                continue
            try:
                cmd = decode(raw)
            except UnknownCommand as e:
                cmd = Command(e.seq, "?")
            except WireError:
                continue  # not a good line: the twin's wait for an answer will end
            if isinstance(cmd, KeepAlive):
                self.keep_alives += 1
                if self.mode != "ignore":
                    out.append(encode(cmd))
                continue
            if not isinstance(cmd, Command):
                continue
            self.received += 1
            answer = self._answer(cmd)
            if answer is not None:
                out.append(answer)
        return out

    def _answer(self, cmd: Command) -> str | None:
        if self.mode == "ignore" or (self.mode == "no-store" and cmd.op == "STORE"):
            return None
        if self.last is not None and self.last[0] == cmd.seq:
            return self.last[1]  # sent again: the same answer, nothing done twice
        if cmd.op == "?":
            reply = Reply(cmd.seq, "NAK", "BADCMD")
        elif cmd.op == "GET":
            reply = Reply(cmd.seq, "GAINS", in_force=self.seq, gains=self.gains)
        elif self.mode == "nak":
            reply = Reply(cmd.seq, "NAK", "LOCKED")
        elif cmd.op == "SET":
            reply = self._set(cmd)
        else:
            reply = self._store(cmd)
        line = encode(reply)
        self.last = (cmd.seq, line)
        return line

    def _set(self, cmd: Command) -> Reply:
        for address, g in zip(GAIN_ADDRESSES, cmd.gains):
            lo, hi = self.limits.get(address, (float("-inf"), float("inf")))
            if not lo <= g / 1000 <= hi:
                return Reply(cmd.seq, "NAK", "RANGE")
        self.staged = (cmd.seq, cmd.gains)
        return Reply(cmd.seq, "ACK")

    def _store(self, cmd: Command) -> Reply:
        _, _, _, _, newest = read_stored(self.image)
        generation = 0
        if newest >= 0:
            generation = unpack_slot(self.image[newest * SLOT_SIZE:(newest + 1) * SLOT_SIZE])[0] + 1
        target = 1 - newest if newest >= 0 else 0
        slot = pack_slot(generation, self.seq, self.gains)
        image = self.image[:target * SLOT_SIZE] + slot + self.image[(target + 1) * SLOT_SIZE:]
        try:
            if self.eeprom is not None:
                self.eeprom.write(image)
                if self.eeprom.read() != image:
                    return Reply(cmd.seq, "NAK", "EEPROM")
        except (OSError, LineFollowerError) as e:
            log.warning("robot %s: cannot write its EEPROM image (%s)", self.robot_id, e)
            return Reply(cmd.seq, "NAK", "EEPROM")
        self.image = image
        return Reply(cmd.seq, "ACK")
