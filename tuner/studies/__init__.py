"""Studies over many laps: design studies (paper §4.2: rebuild, tune, race; :func:`study`), the evidence behind a
design's lap time, their report, sensitivity sweeps (where a set of gains stops working: :func:`tuner.studies.sweep.sweep`), and both
on a Ray cluster (:mod:`tuner.studies.cluster`)."""

from tuner.studies.design import DesignResult, study
from tuner.studies.sweep import Axis

__all__ = ["Axis", "DesignResult", "study"]
