"""A lap's line side: the mean signed offset of the line from the sensor array's centre [m] (+ towards its last
sensor), from the robot's telemetry, which the forecast reads beside the lap time and the mean |offset| (issue 35).
Laps stored before it have none (NULL) until their log is rebuilt (``history --rebuild``); a forecast reads a
feature only when every lap it reads carries it.

Revision ID: 0004
Revises: 0003
"""

import sqlalchemy as sa
from alembic import op

revision = "0004"
down_revision = "0003"
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table("lf_laps") as t:
        t.add_column(sa.Column("line_side_m", sa.Float))


def downgrade() -> None:
    with op.batch_alter_table("lf_laps") as t:
        t.drop_column("line_side_m")
