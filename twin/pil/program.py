"""A program for the robot's ATmega328P as the user flashes it: an ELF or an Intel HEX file, read into its flash (and
EEPROM) image and checked against the MCU, with no need for its symbols.

An ELF gives its loadable segments (flash below 0x800000, EEPROM at 0x810000, as avr-gcc links them: avr-libc's
``avr/io.h`` memory sections), its MCU (architecture, avr-gcc's device note) and, if it was not stripped, its
globals; a HEX file gives the bytes avrdude would write to flash and nothing else. Either way the vector table at
address 0 tells an ATmega328P's program (26 four-byte vectors, datasheet "Interrupts") from one built for an MCU with
more vectors (ATmega644P, 1284P, 32U4, 2560) or a small AVR's two-byte table (ATtiny, ATmega8/48/88). A program
with the twin's traced globals (``fw_state``, …) is the twin's own firmware, which Python traces from RAM; any
other runs on the board model alone (:mod:`twin.pil.board`).
"""

from __future__ import annotations

import dataclasses
import os
import re
import struct

from lf_common.files import input_file
from twin.errors import TwinError

MCU = "atmega328p"
FLASH_BYTES, RAM_BYTES, EEPROM_BYTES = 32768, 2048, 1024  # the ATmega328P's
VECTORS = 26  # interrupt vectors of the ATmega328P, reset included (datasheet, "Interrupts")
TRACE_SYMBOLS = ("fw_state", "fw_raw_us", "fw_tick_mode", "fw_ticks_done")  # the twin firmware's traced globals
DATA_BASE, EEPROM_BASE, FUSE_BASE = 0x800000, 0x810000, 0x820000  # avr-gcc's address spaces in an ELF
TAKES = "--firmware takes c, avr, or a program file (ELF or Intel HEX)"
MAX_FILE_BYTES = 16 * 1024 * 1024  # far above any AVR program; a bigger file is not one


@dataclasses.dataclass(frozen=True)
class Program:
    """A program's images and what is known of it. ``flash``: bytes from address 0, as programmed (0xFF where none);
    ``symbols``: data-space addresses of globals (an ELF's symbol table; empty for HEX or a stripped ELF), ``sizes``
    their sizes [bytes]; ``flash_bytes`` the bytes of program, ``ram_bytes`` static RAM (.data + .bss; None unknown)."""

    path: str
    kind: str  # "elf" or "hex"
    flash: bytes
    eeprom: bytes
    symbols: dict[str, int]
    sizes: dict[str, int]
    flash_bytes: int
    ram_bytes: int | None

    @property
    def traced(self) -> bool:
        """The twin's own firmware: every global the glue traces each tick is there."""
        return all(n in self.symbols for n in TRACE_SYMBOLS)


def load_program(path: str) -> Program:
    """The program in ``path`` (ELF or Intel HEX), checked for the ATmega328P; a one-line TwinError otherwise."""
    if not os.path.lexists(path):
        raise TwinError(f"{path}: no such firmware file; {TAKES}")
    input_file(path, "firmware file")  # a FIFO or a device: the one message every input flag gives
    try:
        size = os.path.getsize(path)
        with open(path, "rb") as f:
            head = f.read(4)
    except OSError as e:
        raise TwinError(f"{path}: cannot read it ({e.strerror or e})") from None
    if size > MAX_FILE_BYTES:
        raise TwinError(f"{path}: {size} bytes is no AVR program; {TAKES}")
    if head == b"\x7fELF":
        program = _load_elf(path)
    elif head[:1] == b":":
        program = _load_hex(path)
    else:
        raise TwinError(f"{path}: not an ELF or Intel HEX file; {TAKES}")
    _check_vectors(program)
    return program


def _load_elf(path: str) -> Program:
    from elftools.common.exceptions import ELFError
    from elftools.elf.elffile import ELFFile

    try:
        with open(path, "rb") as f:
            elf = ELFFile(f)
            machine, arch, device = elf["e_machine"], elf["e_flags"] & 0x7F, _device_name(elf)
            if machine != "EM_AVR":
                raise TwinError(f"{path}: built for {str(machine).replace('EM_', '')}, not an AVR; build it with "
                                f"avr-gcc -mmcu={MCU}")
            if arch != 5:
                raise TwinError(f"{path}: built for avr{arch}, not the ATmega328P's avr5; build it with -mmcu={MCU}")
            if device and device not in (MCU, "atmega328"):
                raise TwinError(f"{path}: built for the {device}, not the {MCU}; build it with -mmcu={MCU}")
            flash, eeprom = bytearray(b"\xff" * FLASH_BYTES), bytearray()
            used = 0
            for seg in elf.iter_segments():
                if seg["p_type"] != "PT_LOAD" or not seg["p_filesz"]:
                    continue
                at, data = int(seg["p_paddr"]), seg.data()
                if at < DATA_BASE:
                    if at + len(data) > FLASH_BYTES:
                        raise TwinError(f"{path}: {at + len(data)} bytes of program do not fit the {MCU}'s "
                                        f"{FLASH_BYTES} bytes of flash")
                    flash[at: at + len(data)] = data
                    used = max(used, at + len(data))
                elif EEPROM_BASE <= at < FUSE_BASE:
                    at -= EEPROM_BASE
                    if at + len(data) > EEPROM_BYTES:
                        raise TwinError(f"{path}: its EEPROM data do not fit the {MCU}'s {EEPROM_BYTES} bytes")
                    eeprom[len(eeprom):] = b"\xff" * max(0, at + len(data) - len(eeprom))
                    eeprom[at: at + len(data)] = data
            symtab = elf.get_section_by_name(".symtab")
            symbols = {s.name: int(s["st_value"]) for s in symtab.iter_symbols() if s.name} if symtab else {}
            sizes = {s.name: int(s["st_size"]) for s in symtab.iter_symbols() if s.name} if symtab else {}
            section = {s.name: s["sh_size"] for s in elf.iter_sections()}
    except TwinError:  # (a ValueError too) said what is wrong with a readable ELF: as it is
        raise
    except (ELFError, struct.error, ValueError, KeyError, IndexError) as e:
        raise TwinError(f"{path}: not a readable ELF file ({e}); {TAKES}") from None
    except OSError as e:
        raise TwinError(f"{path}: cannot read it ({e.strerror or e})") from None
    if not used:
        raise TwinError(f"{path}: holds no program for the flash (no loadable code)")
    data = {n: v - DATA_BASE for n, v in symbols.items() if DATA_BASE <= v < EEPROM_BASE}
    ram = section.get(".data", 0) + section.get(".bss", 0) + section.get(".noinit", 0)
    return Program(path, "elf", bytes(flash[:used]), bytes(eeprom), data, {n: sizes[n] for n in data}, used, ram)


def _device_name(elf) -> str | None:
    """The MCU avr-gcc wrote in the .note.gnu.avr.deviceinfo note, or simavr's .mmcu section, if there is one."""
    for name in (".note.gnu.avr.deviceinfo", ".mmcu"):
        section = elf.get_section_by_name(name)
        if section is not None:
            found = re.findall(rb"(at(?:mega|tiny|xmega)[0-9a-z]+)", section.data())
            if found:
                return found[-1].decode()
    return None


def _load_hex(path: str) -> Program:
    """Intel HEX as avr-objcopy writes it (records 00-05); every line's length and checksum are checked."""
    try:
        with open(path, "rb") as f:
            lines = f.read().splitlines()
    except OSError as e:
        raise TwinError(f"{path}: cannot read it ({e.strerror or e})") from None
    flash, used, base, ended = bytearray(b"\xff" * FLASH_BYTES), 0, 0, False
    for n, raw in enumerate(lines, 1):
        line = raw.strip()
        if not line:
            continue
        if ended:
            raise TwinError(f"{path}: line {n}: data after the end-of-file record; not an Intel HEX file")
        try:
            if line[:1] != b":" or len(line) % 2 != 1:
                raise ValueError
            record = bytes.fromhex(line[1:].decode("ascii"))
        except (ValueError, UnicodeDecodeError):
            raise TwinError(f"{path}: line {n} is not an Intel HEX record; {TAKES}") from None
        if len(record) < 5 or record[0] != len(record) - 5:
            raise TwinError(f"{path}: line {n}: the record's length does not match its data (truncated?)")
        if sum(record) & 0xFF:
            raise TwinError(f"{path}: line {n}: checksum error (the file is damaged)")
        count, offset, kind, data = record[0], record[1] << 8 | record[2], record[3], record[4:-1]
        if kind == 0:
            at = base + offset
            if at + count > FLASH_BYTES:
                raise TwinError(f"{path}: line {n}: data at 0x{at:x}, beyond the {MCU}'s {FLASH_BYTES} bytes of flash")
            flash[at: at + count] = data
            used = max(used, at + count)
        elif kind == 1:
            ended = True
        elif kind == 2 and count == 2:
            base = (data[0] << 8 | data[1]) << 4
        elif kind == 4 and count == 2:
            base = (data[0] << 8 | data[1]) << 16
        elif kind not in (3, 5):
            raise TwinError(f"{path}: line {n}: record type {kind:02X} is not Intel HEX")
    if not ended:
        raise TwinError(f"{path}: no end-of-file record (the file is truncated)")
    if not used:
        raise TwinError(f"{path}: holds no data for the flash")
    return Program(path, "hex", bytes(flash[:used]), b"", {}, {}, used, None)


def _check_vectors(p: Program) -> None:
    """Refuse a vector table that names another MCU: more four-byte vectors than the 328P's, or a two-byte table."""
    words = struct.unpack(f"<{len(p.flash) // 2}H", p.flash[: len(p.flash) // 2 * 2])

    def vector(k: int) -> bool:  # JMP k, or RJMP k and a NOP where the linker relaxed a JMP (avr-ld --relax)
        w0, w1 = words[2 * k], words[2 * k + 1] if 2 * k + 1 < len(words) else 0xFFFF
        return w0 & 0xFE0E == 0x940C or (w0 & 0xF000 == 0xC000 and w1 == 0)

    vectors = 0
    while 2 * vectors < len(words) and vector(vectors):
        vectors += 1
    if vectors > VECTORS:
        raise TwinError(f"{p.path}: its vector table has {vectors} entries, the {MCU} has {VECTORS}: it was built for "
                        f"another MCU; build it with -mmcu={MCU}")
    rjmps = 0
    while rjmps < len(words) and words[rjmps] & 0xF000 == 0xC000:
        rjmps += 1
    if rjmps >= 10:  # one-word vectors, one after the other
        raise TwinError(f"{p.path}: its vector table has two-byte entries (an ATtiny or ATmega8/48/88): it was built "
                        f"for another MCU; build it with -mmcu={MCU}")
