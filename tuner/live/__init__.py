"""The twin beside the running robot (paper §3.8, §4.2): each lap compared with the twin's prediction, re-alignment in
the background when laps keep disagreeing (:class:`LiveTwin`), its state file, and the lines of a link or a log fed
through it (:mod:`tuner.live.replay`)."""

from tuner.live.live_twin import LiveOptions, LiveTwin
from tuner.live.replay import feed_line, replay_log, resume
from tuner.live.state import check_state

__all__ = ["LiveOptions", "LiveTwin", "check_state", "feed_line", "replay_log", "resume"]
