"""The libraries' values that the flags quote: defaults, choices, and figures in help texts.

They are written here, not imported, so that building the parsers (``--help``, a refused flag) loads no library:
the libraries' rooms import MuJoCo, NumPy, SciPy and more as they load, about 2 s of CPU. Each value has one
source, named beside it; ``tests/test_architecture.py`` checks every one against that source, so a change there
fails the tests until it is made here too."""

from __future__ import annotations

ROBOT_NAMES = ("3pi",)  # twin.model.robots.ROBOTS
MOTOR_MODEL = "motor.model"  # twin.model.motor_setup.MOTOR_MODEL

ALIGN_TOLERANCE = 0.001  # tuner.align.lap_time.TOLERANCE
ALIGN_ACCEPT = 0.005  # tuner.align.lap_time.ACCEPT
DIAGNOSE_CANDIDATES = ("motion.mu", "motor.supply_voltage", "motor.R_M", "cad.m_c")  # tuner.align.diagnose.DEFAULT_CANDIDATES

DESIGN_GRID = {"cad.L": (0.035, 0.045, 0.055), "cad.S": (0.04, 0.06, 0.08)}  # tuner.studies.design.DEFAULT_GRID

ROBUST_AXES = {"motion.mu": (0.6, 0.9), "motor.supply_voltage": (4.8, 6.0)}  # tuner.search.envelope.ROBUST_AXES
ROBUST_SEEDS = 8  # tuner.search.envelope.ROBUST_SEEDS
ROBUST_RISK = "worst"  # tuner.search.envelope.ROBUST_RISK

SENSITIVITY_SAMPLES = 256  # tuner.sensitivity.laps.SAMPLES
SENSITIVITY_TRAJECTORIES = 12  # tuner.sensitivity.laps.TRAJECTORIES
SENSITIVITY_MAX_SOBOL = 8  # tuner.sensitivity.laps.MAX_SOBOL

ACT_EVERY_LAPS = 5  # tuner.live.ActOptions.every_laps
ACT_CONFIRM_LAPS = 2  # tuner.live.ActOptions.confirm_laps
ACT_ACK_TIMEOUT_S = 3.0  # tuner.live.ActOptions.ack_timeout_s
ACT_STORE_TRIES = 3  # tuner.live.ActOptions.store_tries

LINK_FSYNC_INTERVAL_S = 0.25  # twin.link.reader.FSYNC_INTERVAL_S
LINK_RETRY_S = 30.0  # twin.link.reader.RETRY_S
COMMAND_MODES = ("answer", "nak", "ignore", "no-store")  # twin.link.robot_end.COMMAND_MODES

FIRMWARE_BOARD = "pololu-3pi-atmega328p"  # twin.pil.firmware.BOARD
TELEMETRY_EVERY = 2  # twin.pil.lap.TELEMETRY_EVERY

FMU_PLANT, FMU_CLOSED_LOOP = "plant", "closed-loop"  # twin.fmi.PLANT, twin.fmi.CLOSED_LOOP
FMU_KINDS = (FMU_PLANT, FMU_CLOSED_LOOP)  # twin.fmi.KINDS

