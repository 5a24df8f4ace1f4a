"""Processor in the loop: a program for the robot's ATmega328P, ELF or Intel HEX as the user flashes it
(:mod:`twin.pil.program`), on an emulated MCU in lockstep with MuJoCo (:mod:`twin.pil.mcu`, the C glue
``twin/csrc/pil``) inside a model of the 3pi's board (:mod:`twin.pil.board`). The twin's own firmware
(:mod:`twin.pil.firmware`: built, checked, configured through its EEPROM image) is traced from its RAM
(:func:`run_pil_lap`); any other program runs on the board alone (:func:`twin.pil.board.run_board_lap`)."""

from twin.pil.lap import McuReport, run_pil_lap, runnable_firmware
from twin.pil.program import Program, load_program

__all__ = ["McuReport", "Program", "load_program", "run_pil_lap", "runnable_firmware"]
