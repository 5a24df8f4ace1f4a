"""The board model's Python parts on their own, no MCU: programs read from Intel HEX and checked for the ATmega328P
(twin.pil.program), the LCD's character codes as text (twin.pil.board.display), the operator's decisions and scripts
(twin.pil.board.operator)."""

from __future__ import annotations

import math
import struct

import pytest

from twin.errors import TwinError
from twin.pil.board.display import char, plain, screen_text
from twin.pil.board.operator import Operator, Seen, load_script
from twin.pil.layout import LcdFrame
from twin.pil.program import load_program

JMP = lambda target: struct.pack("<HH", 0x940C, target)  # noqa: E731  JMP k (k < 64 K words)


def hex_file(tmp_path, data: bytes, base: int = 0, name: str = "p.hex", extended: int | None = None) -> str:
    """``data`` at ``base`` as Intel HEX, written by hand: 16-byte records, checksums."""
    lines = []
    if extended is not None:
        rec = bytes([2, 0, 0, 4, extended >> 8, extended & 0xFF])
        lines.append(":" + (rec + bytes([-sum(rec) & 0xFF])).hex().upper())
    for at in range(0, len(data), 16):
        chunk = data[at: at + 16]
        rec = bytes([len(chunk), (base + at) >> 8 & 0xFF, (base + at) & 0xFF, 0]) + chunk
        lines.append(":" + (rec + bytes([-sum(rec) & 0xFF])).hex().upper())
    path = tmp_path / name
    path.write_text("\n".join(lines + [":00000001FF"]) + "\n")
    return str(path)


def program(vectors: int, relaxed: bool = False) -> bytes:
    table = b"".join(struct.pack("<HH", 0xC000 | 50, 0) if relaxed else JMP(0x40) for _ in range(vectors))
    return table + b"\x00\x00" * 8 + b"\xff\xcf"  # nops, then rjmp .-2


def test_hex_gives_the_flash_image_and_no_symbols(tmp_path):
    data = program(26)
    p = load_program(hex_file(tmp_path, data))
    assert p.kind == "hex" and p.flash == data and p.symbols == {} and not p.traced and p.ram_bytes is None
    relaxed = load_program(hex_file(tmp_path, program(26, relaxed=True), name="r.hex"))  # avr-ld --relax: RJMP, NOP
    assert relaxed.flash_bytes == len(program(26, relaxed=True))


def test_hex_with_an_extended_address_lands_where_it_says(tmp_path):
    p = load_program(hex_file(tmp_path, program(26)[:16], base=0x100, extended=0))
    assert p.flash[0x100:0x110] == program(26)[:16] and p.flash[:0x100] == b"\xff" * 0x100


@pytest.mark.parametrize("vectors, needle", [(31, "31 entries, the atmega328p has 26"), (43, "43 entries")])
def test_a_vector_table_of_another_mcu_is_refused(tmp_path, vectors, needle):
    with pytest.raises(TwinError, match=needle):
        load_program(hex_file(tmp_path, program(vectors)))


def test_a_two_byte_vector_table_is_refused(tmp_path):
    with pytest.raises(TwinError, match="two-byte entries"):
        load_program(hex_file(tmp_path, struct.pack("<20H", *([0xC000 | 19] * 20))))


@pytest.mark.parametrize("text, needle", [
    (":10000000", "length does not match"),
    (":0400000001020304F0\n", "checksum"),
    (":04000000010203040\n:00000001FF\n", "not an Intel HEX record"),
    (":0400000001020304F2\n", "truncated"),
    (":00000001FF\n:0400000001020304F2\n", "after the end-of-file"),
    (":0400000301020304EF\n:00000001FF\n", "holds no data"),
    (":0400000601020304EC\n:00000001FF\n", "record type 06"),
])
def test_damaged_hex_files_say_what_is_wrong(tmp_path, text, needle):
    path = tmp_path / "bad.hex"
    path.write_text(text)
    with pytest.raises(TwinError, match=needle):
        load_program(str(path))


def test_a_hex_beyond_the_flash_is_refused(tmp_path):
    with pytest.raises(TwinError, match="beyond the atmega328p's 32768 bytes"):
        load_program(hex_file(tmp_path, b"\x00" * 16, base=0x8000, extended=0))


def frame(text: bytes, cgram: bytes = bytes(64), on: int = 1) -> LcdFrame:
    f = LcdFrame()
    f.text[:] = list(text.ljust(16, b" "))
    f.cgram[:] = list(cgram)
    f.on = on
    return f


def test_lcd_codes_read_as_the_hd44780_rom_and_bars():
    bars = bytes(b for level in range(8) for b in [0] * (7 - level) + [0x1F] * (level + 1))  # 1..8 rows lit
    assert [char(k, bars) for k in range(8)] == list("▁▂▃▄▅▆▇█")
    odd = bytes([0x0E, 0x11, 0x11, 0x0E, 0, 0, 0, 0]) + bytes(56)
    assert char(0, odd) == "▒" and char(8, odd) == "▒"  # codes 8..15 are 0..7 again
    assert char(0xF7, b"") == "π" and char(0xFF, b"") == "█" and char(0x5C, b"") == "¥" and char(0x41, b"") == "A"
    assert screen_text(frame(b" Pololu 3\xf7 Robot")) == " Pololu \n3π Robot"
    assert screen_text(frame(b"anything", on=0)) == " " * 8 + "\n" + " " * 8
    assert plain("4794mV  \nPress B ") == "4794mV Press B"


@pytest.mark.quick
def test_the_operator_waits_for_polling_with_the_motors_still_then_presses_what_the_lcd_asks():
    op = Operator(patience_s=0.5, hold_s=0.2)
    never = -math.inf
    assert op.decide(Seen(1.0, never, never, "Hello")) is None  # not polling
    assert op.decide(Seen(2.0, 1.95, never, "Press C")) is None  # polling from 1.95 s: not for long enough yet
    press = op.decide(Seen(2.5, 2.45, never, "Press C"))
    assert press and press.button == "C" and press.t == 2.5 and press.hold == 0.2
    assert op.decide(Seen(3.0, 2.95, never, "Press C")) is None  # the press was released at 2.7 s: patience again
    assert op.decide(Seen(4.0, 3.95, 3.9, "Go")) is None  # the motors drove 0.1 s ago
    assert op.decide(Seen(4.6, 4.55, 3.9, "ready")).button == "B"  # nothing asked: B


@pytest.mark.parametrize("doc, needle", [
    ("[1, 2]", "expected"),
    ('{"presses": [{"button": "B"}]}', "give at"),
    ('{"presses": [{"button": "B", "at": -1}]}', "at must be"),
    ('{"presses": [{"button": "B", "at": 1, "hold": 0}]}', "hold must be"),
    ('{"presses": [{"button": "B", "lcd": "  "}]}', "lcd must be"),
    ('{"presses": [{"button": "B", "at": 1, "when": 2}]}', "expected an object"),
    ('{"presses": []', "not JSON"),
])
def test_operator_scripts_are_checked(tmp_path, doc, needle):
    path = tmp_path / "ops.json"
    path.write_text(doc)
    with pytest.raises(TwinError, match=needle):
        load_script(str(path))
