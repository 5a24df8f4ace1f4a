"""Seeing laps: rerun recordings (:mod:`twin.viz.recording`), the rerun viewer (:mod:`twin.viz.viewer`) and rerun's
web viewer in headless Chromium (:mod:`twin.viz.web_viewer`)."""

from twin.viz.recording import log_lap, log_track, save_charts, save_laps

__all__ = ["log_lap", "log_track", "save_charts", "save_laps"]
