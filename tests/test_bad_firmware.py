"""The firmware's command and ``--firmware`` against bad input and outputs they cannot write: exit 2 and one last
``error: …`` line naming the input or the output and what is wrong (see :mod:`bad_cli`)."""

from __future__ import annotations

import os
import shutil

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
    return {"dir": str(d), "missing_dir": str(d / "no" / "such"), "user.json": str(d / "user.json")}


@pytest.mark.parametrize("line, status, words", ROWS, ids=[r[0] for r in ROWS])
def test_bad_firmware_input_is_one_last_line(capfd, places, disks, line, status, words):
    check_row(capfd, {**places, **disks.places(line)}, line, status, words, owned=["{user.json}"])
