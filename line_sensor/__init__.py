"""Sensor partial model (paper §3.5, Eqs. 8–9): reflectance array geometry, response, calibration, line angle.

This release provides the array geometry; the reflectance model, calibration and the C implementation
arrive with the closed-loop work.
"""

from line_sensor.geometry import SensorArray

__all__ = ["SensorArray"]
