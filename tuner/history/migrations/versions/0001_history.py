"""The history database: robots, runs, laps, alignments, gain changes, events.

Revision ID: 0001
Revises:
"""

import sqlalchemy as sa
from alembic import op

revision = "0001"
down_revision = None
branch_labels = None
depends_on = None


def _id():
    return sa.Column("id", sa.Integer, primary_key=True)


def _owner():
    return [sa.Column("run_id", sa.Integer, sa.ForeignKey("lf_runs.id"), nullable=False, index=True),
            sa.Column("robot_id", sa.Integer, sa.ForeignKey("lf_robots.id"), nullable=False, index=True),
            sa.Column("source", sa.String(512), nullable=False, unique=True)]


def upgrade() -> None:
    op.create_table("lf_robots", _id(), sa.Column("name", sa.String(64), nullable=False, unique=True),
                    sa.Column("kind", sa.String(16), nullable=False), sa.Column("first_seen", sa.Float),
                    sa.Column("last_seen", sa.Float))
    op.create_table("lf_runs", _id(),
                    sa.Column("robot_id", sa.Integer, sa.ForeignKey("lf_robots.id"), nullable=False, index=True),
                    sa.Column("command", sa.String(16), nullable=False),
                    sa.Column("source", sa.String(512), nullable=False, unique=True),
                    sa.Column("log_path", sa.String(1024), index=True), sa.Column("started", sa.Float),
                    sa.Column("first_lap", sa.Integer), sa.Column("settings", sa.JSON), sa.Column("result", sa.JSON))
    op.create_table("lf_laps", _id(), *_owner(), sa.Column("lap", sa.Integer, nullable=False),
                    sa.Column("time", sa.Float), sa.Column("completed", sa.Boolean, nullable=False),
                    sa.Column("lap_time_s", sa.Float), sa.Column("failure", sa.String(64)),
                    sa.Column("implausible", sa.Text), sa.Column("energy_j", sa.Float), sa.Column("xte_max_m", sa.Float),
                    sa.Column("xte_mean_m", sa.Float), sa.Column("gains_seq", sa.Integer), sa.Column("gains", sa.JSON),
                    sa.Column("twin_lap_time_s", sa.Float), sa.Column("discrepancy", sa.Float),
                    sa.Column("values", sa.JSON))
    op.create_table("lf_alignments", _id(), *_owner(), sa.Column("lap", sa.Integer), sa.Column("time", sa.Float),
                    sa.Column("address", sa.String(64), nullable=False), sa.Column("before", sa.Float),
                    sa.Column("value", sa.Float), sa.Column("lo", sa.Float), sa.Column("hi", sa.Float),
                    sa.Column("explained", sa.Boolean, nullable=False), sa.Column("identifiable", sa.Boolean),
                    sa.Column("measured_lap_time_s", sa.Float), sa.Column("message", sa.Text),
                    sa.Column("reason", sa.Text))
    op.create_table("lf_gain_changes", _id(), *_owner(), sa.Column("seq", sa.Integer, nullable=False),
                    sa.Column("kind", sa.String(16), nullable=False), sa.Column("decided_lap", sa.Integer),
                    sa.Column("first_lap", sa.Integer), sa.Column("status", sa.String(16), nullable=False),
                    sa.Column("gains", sa.JSON), sa.Column("previous", sa.JSON), sa.Column("previous_seq", sa.Integer),
                    sa.Column("reason", sa.Text), sa.Column("predicted_lap_time_s", sa.Float),
                    sa.Column("nak_reason", sa.String(16)), sa.Column("outcome", sa.Text),
                    sa.Column("decided_at", sa.Float), sa.Column("sent_at", sa.Float),
                    sa.Column("answered_at", sa.Float))
    op.create_table("lf_events", _id(), *_owner(), sa.Column("lap", sa.Integer), sa.Column("time", sa.Float),
                    sa.Column("kind", sa.String(16), nullable=False), sa.Column("seq", sa.Integer),
                    sa.Column("outcome", sa.Text), sa.Column("data", sa.JSON))


def downgrade() -> None:
    for table in ("lf_events", "lf_gain_changes", "lf_alignments", "lf_laps", "lf_runs", "lf_robots"):
        op.drop_table(table)
