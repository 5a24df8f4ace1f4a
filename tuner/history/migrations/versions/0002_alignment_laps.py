"""An alignment's laps: the first lap it measured (``first_lap``; ``lap`` is the last), and whether it is an
estimate rather than a measurement (``estimated``: the live twin's value from failed laps, never evidence for a
trend or a forecast).

Revision ID: 0002
Revises: 0001
"""

import sqlalchemy as sa
from alembic import op

revision = "0002"
down_revision = "0001"
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table("lf_alignments") as t:
        t.add_column(sa.Column("first_lap", sa.Integer))
        t.add_column(sa.Column("estimated", sa.Boolean))


def downgrade() -> None:
    with op.batch_alter_table("lf_alignments") as t:
        t.drop_column("estimated")
        t.drop_column("first_lap")
