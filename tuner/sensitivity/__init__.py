"""The model space learns its own relations (paper §5): global sensitivity of the lap measured from batches of laps.

* :mod:`tuner.sensitivity.ranges`: what is varied, over its documented physical range (:func:`default_factors`);
* :mod:`tuner.sensitivity.analysis`: Morris screening, then Sobol' indices for the factors that matter (SALib),
  for any model (:func:`analyse`);
* :mod:`tuner.sensitivity.precision`: how sure an index is (clipped to [0, 1] with a note; too few samples flagged);
* :mod:`tuner.sensitivity.laps`: the twin's laps as that model (:func:`learn`: lap time, completion, energy,
  cross-track error);
* :mod:`tuner.sensitivity.relations`: the learned graph against the declared one (:func:`compare`);
* :mod:`tuner.sensitivity.learned`: the learned influences kept per twin configuration, for ``diagnose`` and
  ``align`` (:func:`load`, :func:`store`);
* :mod:`tuner.sensitivity.report`, :mod:`tuner.sensitivity.charts`: the document, the folder and the drawings.
"""

from tuner.sensitivity.analysis import Analysis, Influence, analyse, check_samples
from tuner.sensitivity.laps import OUTPUTS, LapModel, learn
from tuner.sensitivity.learned import (barely_moves, diagnosis_candidates, is_default, lap_time_governors,
                                       lap_time_warning, load, scan_spread, store)
from tuner.sensitivity.ranges import (ASSUMED, PHYSICAL_RANGES, Factor, PhysicalRange, chosen_factors, default_factors,
                                      is_setting, physical_range)
from tuner.sensitivity.relations import Relation, by_status, compare, table
from tuner.sensitivity.report import document, write_folder

__all__ = ["ASSUMED", "Analysis", "Factor", "Influence", "LapModel", "OUTPUTS", "PHYSICAL_RANGES", "PhysicalRange", "Relation",
           "analyse", "barely_moves", "by_status", "check_samples", "chosen_factors", "compare", "default_factors",
           "diagnosis_candidates", "document", "is_default", "is_setting", "lap_time_governors", "lap_time_warning", "learn", "load",
           "physical_range", "scan_spread", "store", "table", "write_folder"]
