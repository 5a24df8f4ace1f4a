"""The history database's tables (SQLAlchemy Core), as the newest migration leaves them
(:mod:`tuner.history.migrations`); every name starts with ``lf_`` so the database can be shared (PostgreSQL for a
fleet) with other programs' tables.

* ``lf_robots``: each robot by its wire id (``kind`` robot), and the twin itself (``kind`` twin: ``lap``, ``tune``
  and ``align`` runs without a robot).
* ``lf_runs``: a live session on one log, or one ``lap``, ``tune``, ``align`` command; ``source`` is its unique key.
* ``lf_laps``: every lap: lap time, completed or why not, cross-track error, energy (the twin's laps; a robot does not
  report it), the gains in force (their command's sequence number and values), the twin's prediction and the
  aligned values at the time.
* ``lf_alignments``: each alignment: the laps it measured (``first_lap`` to ``lap``), the value, its consistent
  interval, what it explained; ``estimated`` marks the live twin's estimate from failed laps, which is no evidence.
* ``lf_gain_changes``: each change of gains the twin decided: sent (or withdrawn), answered (ACK, NAK and why,
  silence), in force, confirmed or rolled back, with the prediction it was sent on; apart from that, whether the
  robot stored it (``stored``: the gains it boots on).
* ``lf_events``: every other action of the live twin (boot, adopt, hold, retune, stored, …), as it was journaled.

Rows that come from a telemetry log carry a ``source`` key (``<log>#lap7``, ``<log>#j42``): writing one again
replaces it, which makes rebuilding from the logs idempotent.
"""

from __future__ import annotations

import sqlalchemy as sa

metadata = sa.MetaData()


def _of_a_run(name: str, *columns: sa.Column) -> sa.Table:
    """A table of rows that belong to a run of a robot, each with its unique ``source`` key."""
    return sa.Table(
        name, metadata,
        sa.Column("id", sa.Integer, primary_key=True),
        sa.Column("run_id", sa.Integer, sa.ForeignKey("lf_runs.id"), nullable=False, index=True),
        sa.Column("robot_id", sa.Integer, sa.ForeignKey("lf_robots.id"), nullable=False, index=True),
        sa.Column("source", sa.String(512), nullable=False, unique=True),
        *columns,
    )

robots = sa.Table(
    "lf_robots", metadata,
    sa.Column("id", sa.Integer, primary_key=True),
    sa.Column("name", sa.String(64), nullable=False, unique=True),
    sa.Column("kind", sa.String(16), nullable=False),
    sa.Column("first_seen", sa.Float),
    sa.Column("last_seen", sa.Float),
)

runs = sa.Table(
    "lf_runs", metadata,
    sa.Column("id", sa.Integer, primary_key=True),
    sa.Column("robot_id", sa.Integer, sa.ForeignKey("lf_robots.id"), nullable=False, index=True),
    sa.Column("command", sa.String(16), nullable=False),
    sa.Column("source", sa.String(512), nullable=False, unique=True),
    sa.Column("log_path", sa.String(1024), index=True),
    sa.Column("started", sa.Float),
    sa.Column("first_lap", sa.Integer),
    sa.Column("settings", sa.JSON),
    sa.Column("result", sa.JSON),
)

laps = _of_a_run(
    "lf_laps",
    sa.Column("lap", sa.Integer, nullable=False),
    sa.Column("time", sa.Float),
    sa.Column("completed", sa.Boolean, nullable=False),
    sa.Column("lap_time_s", sa.Float),
    sa.Column("failure", sa.String(64)),
    sa.Column("implausible", sa.Text),
    sa.Column("energy_j", sa.Float),
    sa.Column("xte_max_m", sa.Float),
    sa.Column("xte_mean_m", sa.Float),
    sa.Column("line_side_m", sa.Float),  # the line's mean signed offset from the array's centre (+ its last sensor)
    sa.Column("gains_seq", sa.Integer),
    sa.Column("gains", sa.JSON),
    sa.Column("twin_lap_time_s", sa.Float),
    sa.Column("discrepancy", sa.Float),
    sa.Column("values", sa.JSON),
)

alignments = _of_a_run(
    "lf_alignments",
    sa.Column("lap", sa.Integer),  # the last lap it measured (a robot's lap number in its run)
    sa.Column("time", sa.Float),
    sa.Column("address", sa.String(64), nullable=False),
    sa.Column("before", sa.Float),
    sa.Column("value", sa.Float),
    sa.Column("lo", sa.Float),
    sa.Column("hi", sa.Float),
    sa.Column("explained", sa.Boolean, nullable=False),
    sa.Column("identifiable", sa.Boolean),
    sa.Column("measured_lap_time_s", sa.Float),
    sa.Column("message", sa.Text),
    sa.Column("reason", sa.Text),
    sa.Column("first_lap", sa.Integer),  # the first lap it measured (migration 0002)
    sa.Column("estimated", sa.Boolean),  # an estimate from failed laps, not a measurement: never evidence
)

gain_changes = _of_a_run(
    "lf_gain_changes",
    sa.Column("seq", sa.Integer, nullable=False),
    sa.Column("kind", sa.String(16), nullable=False),
    sa.Column("decided_lap", sa.Integer),
    sa.Column("first_lap", sa.Integer),
    sa.Column("status", sa.String(16), nullable=False),
    sa.Column("stored", sa.String(16)),  # None (no STORE asked), pending, stored, not_stored (migration 0003)
    sa.Column("gains", sa.JSON),
    sa.Column("previous", sa.JSON),
    sa.Column("previous_seq", sa.Integer),
    sa.Column("reason", sa.Text),
    sa.Column("predicted_lap_time_s", sa.Float),
    sa.Column("nak_reason", sa.String(16)),
    sa.Column("outcome", sa.Text),
    sa.Column("decided_at", sa.Float),
    sa.Column("sent_at", sa.Float),
    sa.Column("answered_at", sa.Float),
)

events = _of_a_run(
    "lf_events",
    sa.Column("lap", sa.Integer),
    sa.Column("time", sa.Float),
    sa.Column("kind", sa.String(16), nullable=False),
    sa.Column("seq", sa.Integer),
    sa.Column("outcome", sa.Text),
    sa.Column("data", sa.JSON),
)

TABLES = (robots, runs, laps, alignments, gain_changes, events)
VERSION_TABLE = "lf_alembic_version"
