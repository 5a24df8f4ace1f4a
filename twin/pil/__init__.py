"""Processor in the loop: the robot's firmware as an AVR program (:mod:`twin.pil.firmware`: built, checked,
configured through its EEPROM image), an emulated ATmega328P in lockstep with MuJoCo (:mod:`twin.pil.mcu`, the C
glue ``twin/csrc/pil``), and a lap driven by that binary (:func:`run_pil_lap`)."""

from twin.pil.lap import McuReport, run_pil_lap, runnable_firmware

__all__ = ["McuReport", "run_pil_lap", "runnable_firmware"]
