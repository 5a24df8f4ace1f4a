"""The twin beside the running robot (paper §3.8, §4.2): each lap compared with the twin's prediction, re-alignment in
the background when laps keep disagreeing (:class:`LiveTwin`), acting on the robot with re-tuned gains, confirmed
or rolled back (:mod:`tuner.live.act`, :mod:`tuner.live.change`, :mod:`tuner.live.retune`, fed by
:class:`Worker`), its state file, and the lines of a link or a log fed through it (:mod:`tuner.live.replay`)."""

from tuner.live.act import ActOptions, Actor
from tuner.live.live_twin import LiveOptions, LiveTwin
from tuner.live.replay import decode_line, feed_line, replay_log, resume
from tuner.live.retune import Retune, retune_gains
from tuner.live.state import check_state
from tuner.live.worker import Worker

__all__ = ["ActOptions", "Actor", "LiveOptions", "LiveTwin", "Retune", "Worker", "check_state", "decode_line",
           "feed_line", "replay_log", "resume", "retune_gains"]
