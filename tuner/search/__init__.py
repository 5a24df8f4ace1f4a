"""What the learning model searches and how: model-space addresses with bounds in a unit box
(:class:`SearchSpace`), the lap objective over an envelope of conditions (:class:`LapObjective`,
:class:`Envelope`), gradient descent (Eq. 12: :func:`descend`, :func:`sequential`) and its start."""

from tuner.search.envelope import Envelope, Risk
from tuner.search.gradient import DescentOptions, DescentResult, descend, sequential
from tuner.search.objective import LapObjective
from tuner.search.space import DEFAULT_BOUNDS, SearchSpace, TunerError, robot_bounds
from tuner.search.start import rescue_start

__all__ = ["DEFAULT_BOUNDS", "DescentOptions", "DescentResult", "Envelope", "LapObjective", "Risk", "SearchSpace",
           "TunerError", "descend", "rescue_start", "robot_bounds", "sequential"]
