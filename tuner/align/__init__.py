"""Keeping the twin true to its robot (paper §4.1): alignment to a measured lap time (:func:`align_lap_time`), to a
recorded run's traces (:func:`align_telemetry`), and diagnosis of which single change explains a robot slower or
faster than its twin (:func:`tuner.align.diagnose.diagnose`)."""

from tuner.align.lap_time import LapTimeAlignment, align_lap_time
from tuner.align.trace import TraceAlignment, align_telemetry

__all__ = ["LapTimeAlignment", "TraceAlignment", "align_lap_time", "align_telemetry"]
