"""Learning partial model (paper §3.7, Eqs. 12–13): gradient descent over model-space addresses, its laps run
as batches of parallel simulations (``twin.closed_loop.run_laps``)."""

from tuner.gradient import DescentOptions, descend, sequential
from tuner.objective import LapObjective, lap_cost
from tuner.space import SearchSpace, TunerError

__all__ = ["DescentOptions", "LapObjective", "SearchSpace", "TunerError", "descend", "lap_cost", "sequential"]
