"""``firmware``: what to flash into the robot: the ATmega328P program and the EEPROM image of this twin's parameters."""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import tempfile

from lf_common.files import output_dir
from twin.cli import options as o
from twin.cli import twin_options as tw
from twin.cli.library_values import FIRMWARE_BOARD, TELEMETRY_EVERY
from twin.cli.output import Output
from twin.cli.startup import loading
from twin.errors import TwinError

HELP = "write the robot's firmware (ELF, flash .hex) and its parameters (EEPROM .hex) for avrdude"


def add_parser(sub) -> None:
    p = sub.add_parser("firmware", help=HELP, description=HELP + ". The program is built from twin/csrc/firmware/avr "
                       f"for the {FIRMWARE_BOARD} (pin map: board_3pi.h); the EEPROM image holds the gains, geometry and "
                       "sensor timeout of the robot the flags describe, the ones 'lap --firmware avr' runs with.")
    o.add_world(p)
    o.add_values(p)
    p.add_argument("--every", type=o.number(1, 1000, integer=True), default=TELEMETRY_EVERY, metavar="N",
                   help="one telemetry sample line every N control ticks")
    o.add_out_dir(p, "robot.elf, robot.hex and config.hex", "firmware")
    o.add_json(p)
    o.add_verbose(p)
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    with loading():
        from twin.pil import firmware as fw

    out = Output(args.json)
    twin = tw.twin_from_args(args)
    warning = tw.gains_warning(args, twin)  # about to be flashed into a robot: say so before it is
    image = fw.config_image(twin.control_params(), twin.sensor_model().timeout_us, args.every)
    elf = fw.build("robot")
    info = fw.check_elf(elf, need=fw.TRACE_SYMBOLS)
    objcopy = shutil.which("avr-objcopy")
    if not objcopy:
        raise TwinError(f"avr-objcopy is not installed; it writes the flash image ({fw.INSTALL_AVR_GCC})")
    flash_hex = _flash_hex(objcopy, elf)
    with output_dir(args.out_dir, "firmware folder") as tmp:  # every write here is this program's: a failing one
        shutil.copyfile(elf, os.path.join(tmp, "robot.elf"))  # names the folder and the cause
        with open(os.path.join(tmp, "robot.hex"), "wb") as f:
            f.write(flash_hex)
        with open(os.path.join(tmp, "config.hex"), "w") as f:
            f.write(fw.intel_hex(image))
    folder = os.path.abspath(args.out_dir)
    flash = (f"avrdude -p m328p -c avrispv2 -P PORT -U flash:w:{os.path.join(folder, 'robot.hex')}:i "
             f"-U eeprom:w:{os.path.join(folder, 'config.hex')}:i")
    out.document({"folder": folder, "mcu": fw.MCU, "board": fw.BOARD, "flash_bytes": info.flash_bytes,
                  "ram_bytes": info.ram_bytes, "eeprom_bytes": len(image), "avrdude": flash,
                  "gains_warning": warning})
    out.say(f"wrote {folder}: robot.elf, robot.hex (flash {info.flash_bytes} B), config.hex (EEPROM {len(image)} B)")
    out.say(f"flash the robot (Pololu's USB AVR programmer speaks avrispv2): {flash}")
    return 0


def _flash_hex(objcopy: str, elf: str) -> bytes:
    """The flash image (Intel HEX) of ``elf``, made by avr-objcopy in a scratch folder of its own: its failures
    are its own (reported with its message), never a half-written output."""
    with tempfile.TemporaryDirectory(prefix="lf-firmware-") as scratch:
        hex_path = os.path.join(scratch, "robot.hex")
        done = subprocess.run([objcopy, "-O", "ihex", "-R", ".eeprom", elf, hex_path], capture_output=True, text=True,
                              timeout=60)
        if done.returncode != 0:
            why = (done.stderr.strip().splitlines() or [f"exit status {done.returncode}"])[-1]
            raise TwinError(f"avr-objcopy could not make the flash image of {elf} ({why})")
        with open(hex_path, "rb") as f:
            return f.read()
