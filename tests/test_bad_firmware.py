"""The firmware's command and ``--firmware`` against bad input and outputs they cannot write: exit 2 and one last
``error: …`` line naming the input or the output and what is wrong (see :mod:`bad_cli`)."""

from __future__ import annotations

import os
import shutil
import subprocess

import pytest

from bad_cli import check_row, disks  # noqa: F401  (fixtures)

# (command line, exit status, words the one error line must hold)
ROWS = [
    ("firmware --every 0", 2, ["--every", "outside"]),
    ("firmware --out-dir {user.json}", 2, ["{user.json}", "is a file"]),
    ("firmware --out-dir {missing_dir}/fw", 2, ["does not exist"]),
    # the ELF fits, its flash image does not: avr-objcopy's failure was an internal error
    ("firmware --out-dir {free24k}/fw", 2, ["{free24k}/fw", "No space left on device"]),
    ("firmware --out-dir {full}/fw", 2, ["{full}/fw", "No space left on device"]),
    ("lap --firmware {user.json}", 2, ["{user.json}", "not an ELF or Intel HEX file"]),
    ("lap --firmware {missing_dir}/robot.elf", 2, ["no such firmware file"]),
    # a readable ELF for another MCU: what it is built for, the path once (it was "not a readable ELF file")
    ("lap --firmware {mega.elf}", 2, ["error: {mega.elf}: built for avr6, not the ATmega328P's avr5"]),
    ("lap --firmware {m168.elf}", 2, ["error: {m168.elf}: built for the atmega168, not the atmega328p"]),
]


@pytest.fixture(scope="module")
def places(tmp_path_factory):
    if not (shutil.which("avr-gcc") and shutil.which("avr-objcopy")):
        missing = " and ".join(t for t in ("avr-gcc", "avr-objcopy") if not shutil.which(t))
        if os.environ.get("CI"):
            pytest.fail(f"{missing} missing: CI installs gcc-avr, avr-libc and binutils-avr")
        pytest.skip(f"needs {missing} (apt-get install gcc-avr avr-libc binutils-avr)")
    d = tmp_path_factory.mktemp("firmware")
    (d / "user.json").write_text('{"mine": true}')
    (d / "idle.c").write_text("int main(void) { for (;;) ; }\n")
    (d / "wdt.c").write_text("#include <avr/wdt.h>\nint main(void) { wdt_enable(WDTO_15MS); for (;;) ; }\n")
    for name, source, mcu in (("mega.elf", "idle.c", "atmega2560"), ("m168.elf", "idle.c", "atmega168"),
                              ("wdt.elf", "wdt.c", "atmega328p")):
        subprocess.run(["avr-gcc", f"-mmcu={mcu}", "-Os", str(d / source), "-o", str(d / name)], check=True)
    return {"dir": str(d), "missing_dir": str(d / "no" / "such"), "user.json": str(d / "user.json"),
            **{n: str(d / n) for n in ("mega.elf", "m168.elf", "wdt.elf")}}


@pytest.mark.parametrize("line, status, words", ROWS, ids=[r[0] for r in ROWS])
def test_bad_firmware_input_is_one_last_line(capfd, places, disks, line, status, words):
    check_row(capfd, {**places, **disks.places(line)}, line, status, words, owned=["{user.json}"])


# (command line, exit status, words the lap's report must hold): a program that misbehaves is a reported result
REPORTED = [
    # it resets itself by its watchdog every 16 ms (the resets were counted nowhere)
    ("lap --firmware {wdt.elf} --lap-timeout 1", 0, ["MCU resets: 62 by its watchdog", "every 16 ms"]),
    ("lap --firmware {wdt.elf} --lap-timeout 1 --json", 0, ['"resets": {"count": 62, "by": "watchdog"']),
]


@pytest.mark.parametrize("line, status, words", REPORTED, ids=[r[0] for r in REPORTED])
def test_a_misbehaving_program_is_reported(capfd, places, line, status, words):
    out = check_row(capfd, places, line, status, [])
    for w in words:
        assert w in out, (w, out[-2000:])
