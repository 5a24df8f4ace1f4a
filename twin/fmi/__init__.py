"""The twin in co-simulation (FMI): the twin exported as a Co-Simulation FMU (:func:`export_fmu`: the plant, or the
closed loop with its firmware; FMI 2.0 or 3.0, linux64, built from the same C core as the lap), and third-party
controller FMUs driving the twin in its own loop (:class:`ControllerFmu`, :func:`run_controller_lap`)."""

from twin.fmi.controller import DRIVE_PORTS, ControllerFmu, parse_map, sense_ports
from twin.fmi.controller_lap import run_controller_lap
from twin.fmi.export import ExportedFmu, export_fmu, fmu_is_ours
from twin.fmi.variables import CLOSED_LOOP, KINDS, PLANT, Variable, fmu_variables

__all__ = ["CLOSED_LOOP", "DRIVE_PORTS", "ControllerFmu", "ExportedFmu", "KINDS", "PLANT", "Variable", "export_fmu",
           "fmu_is_ours", "fmu_variables", "parse_map", "run_controller_lap", "sense_ports"]
