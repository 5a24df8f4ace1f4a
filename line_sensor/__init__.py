"""Sensor partial model (paper §3.5, Eqs. 8–9), in Python: the array's geometry (:mod:`line_sensor.geometry`), the
reflectance physics of one sensor over the track (:mod:`line_sensor.reflectance`), how high an array may sit
(:mod:`line_sensor.working_range`), and calibration, calibrated values and the line position as Pololu's
QTRSensors compute them (:mod:`line_sensor.processing`). These are the references the C is tested against, bit for
bit: the raycast sensor physics in ``twin/csrc/sim/sensor_physics.c`` and Eqs. 8–9 in the firmware
(``twin/csrc/firmware``)."""

from line_sensor.geometry import SensorArray

__all__ = ["SensorArray"]
