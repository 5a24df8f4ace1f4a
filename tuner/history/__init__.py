"""A robot's life, kept: the actions of the live twin beside its telemetry log (:mod:`tuner.history.journal`), the
trend of each aligned parameter (:mod:`tuner.history.trend`)."""

from tuner.history.journal import Journal, actions_path, check_journal, read_journal
from tuner.history.trend import Trend, trend

__all__ = ["Journal", "Trend", "actions_path", "check_journal", "read_journal", "trend"]
