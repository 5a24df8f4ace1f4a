"""Prognostics (paper §4.2, §5: predictions about future behaviour): the degradation state of a wearing parameter
estimated lap by lap from all the evidence, measurements and lap outcomes (:mod:`tuner.prognostics.evidence`), by a
particle filter that carries its uncertainty (:func:`estimate`); the remaining useful life of the gains in force by
Monte Carlo, as a distribution of laps (:func:`remaining_life`); and what a person reads (:func:`life_sentence`).
Two causes at once: the same filter and Monte Carlo on both parameters, through models over their plane
(:mod:`tuner.prognostics.plane`)."""

from tuner.prognostics.evidence import (FailureModel, LapObservation, Measurement, ObservationModel, Outcome,
                                        measurement_sigma)
from tuner.prognostics.particle_filter import DegradationState, FilterSettings, estimate
from tuner.prognostics.monte_carlo import HORIZON, RemainingLife, remaining_life
from tuner.prognostics.statement import RETUNE_WITHIN, life_sentence, retune_advice, service_advice, shape_sentence

__all__ = ["DegradationState", "FailureModel", "FilterSettings", "HORIZON", "LapObservation", "Measurement",
           "ObservationModel", "Outcome", "RETUNE_WITHIN",
           "RemainingLife", "estimate", "life_sentence", "measurement_sigma", "remaining_life", "retune_advice",
           "service_advice", "shape_sentence"]
