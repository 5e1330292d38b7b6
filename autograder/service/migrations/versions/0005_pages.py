"""roster: the Canvas user id of each person (the "ID" column of the Canvas CSV)

Revision ID: 0005_pages
Revises: 0004_manual
Create Date: 2026-12-03 16:30:00
"""
import sqlalchemy as sa
from alembic import op

revision = '0005_pages'
down_revision = '0004_manual'
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table('users', schema=None) as batch_op:
        batch_op.add_column(sa.Column('canvas_id', sa.String(length=32), nullable=False,
                                      server_default=''))


def downgrade() -> None:
    with op.batch_alter_table('users', schema=None) as batch_op:
        batch_op.drop_column('canvas_id')
