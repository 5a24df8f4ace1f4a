"""A robot's life, kept (paper §4.2, §5: through-life service): what the live twin did, journaled beside its
telemetry log (:mod:`tuner.history.journal`); the history database of robots, runs, laps, alignments and gain
changes (SQLAlchemy, created and upgraded by Alembic migrations: :mod:`tuner.history.store`,
:mod:`tuner.history.schema`), written as live runs (:class:`HistoryWriter`) or rebuilt from the logs
(:func:`rebuild_log`), and by ``lap``, ``tune``, ``align`` (:mod:`tuner.history.commands`); the trend of each aligned
parameter (:func:`trend_of`), and the forecast of when the gains in force stop finishing (:func:`forecast_failure`:
the degradation state filtered from all the evidence, the twin's failure edge, the remaining life by Monte Carlo,
:mod:`tuner.prognostics`; each cause on its own and, when no one explains the laps, grip and battery at once:
:func:`forecasts_of`)."""

from tuner.history.commands import record_alignment, record_fit, record_lap
from tuner.history.forecast import Forecast, failure_bracket, first_failure, forecast_failure
from tuner.history.journal import Journal, actions_path, check_belongs, check_journal, lap_digest, log_id, read_journal
from tuner.history.rebuild import log_laps, rebuild_log
from tuner.history.store import DEFAULT_DB, History, HistoryError, check_db, default_url, display
from tuner.history.trend import Trend, trend_of
from tuner.history.two_causes import forecast_two_causes, forecasts_of
from tuner.history.writer import HistoryWriter

__all__ = ["DEFAULT_DB", "Forecast", "History", "HistoryError", "HistoryWriter", "Journal", "Trend", "actions_path",
           "check_belongs", "check_db", "check_journal", "default_url", "display", "failure_bracket", "first_failure",
           "forecast_failure", "forecast_two_causes", "forecasts_of", "lap_digest", "log_id", "log_laps", "read_journal", "rebuild_log", "record_alignment",
           "record_fit", "record_lap", "trend_of"]
