"""The twin and its laps: model-space values → a compiled MuJoCo world (:class:`DigitalTwin`), the C core's Python
face (:mod:`twin.core.native`), laps in closed loop on ``mujoco.batch`` (:func:`run_laps`) and their judge
(:class:`LapJudge`, :class:`LapResult`, :class:`Outcome`)."""

from twin.core.closed_loop import check_seed, run_laps
from twin.core.digital_twin import DigitalTwin
from twin.core.lap import COL, LapJudge, LapLimits, LapResult, LapTrace
from twin.core.outcomes import Outcome
from twin.core.variant import Variant

__all__ = ["COL", "DigitalTwin", "LapJudge", "LapLimits", "LapResult", "LapTrace", "Outcome", "Variant", "check_seed",
           "run_laps"]
