"""A gain change's stored state, apart from its status (what the robot runs): ``stored`` is None when no STORE was
asked, else ``pending``, ``stored`` (acknowledged: the robot boots on these gains) or ``not_stored`` (no answer
after the retries, refused, or not sent because the run stopped).

Revision ID: 0003
Revises: 0002
"""

import sqlalchemy as sa
from alembic import op

revision = "0003"
down_revision = "0002"
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table("lf_gain_changes") as t:
        t.add_column(sa.Column("stored", sa.String(16)))


def downgrade() -> None:
    with op.batch_alter_table("lf_gain_changes") as t:
        t.drop_column("stored")
