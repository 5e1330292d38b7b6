"""manual grading: rubric items, graded answers, releases, score overrides, regrade requests

Revision ID: 0004_manual
Revises: 0003_lti
Create Date: 2026-12-03 16:05:00
"""
import sqlalchemy as sa
from alembic import op

revision = '0004_manual'
down_revision = '0003_lti'
branch_labels = None
depends_on = None


def _submission(name: str = 'submission_id') -> sa.Column:
    return sa.Column(name, sa.Integer(), sa.ForeignKey('submissions.id', ondelete='CASCADE'),
                     nullable=False)


def upgrade() -> None:
    op.create_table('rubric_items',
                    sa.Column('id', sa.Integer(), primary_key=True, autoincrement=True),
                    sa.Column('assignment', sa.String(128), nullable=False, index=True),
                    sa.Column('question', sa.String(128), nullable=False),
                    sa.Column('text', sa.Text(), nullable=False),
                    sa.Column('points', sa.Float(), nullable=False))
    op.create_table('answer_grades', _submission(),
                    sa.Column('question', sa.String(128), nullable=False),
                    sa.Column('comment', sa.Text(), nullable=False),
                    sa.Column('grader', sa.String(128), nullable=False),
                    sa.Column('updated_at', sa.DateTime(), nullable=False),
                    sa.PrimaryKeyConstraint('submission_id', 'question'))
    op.create_table('applied_items', _submission(),
                    sa.Column('item_id', sa.Integer(),
                              sa.ForeignKey('rubric_items.id', ondelete='CASCADE'), nullable=False),
                    sa.PrimaryKeyConstraint('submission_id', 'item_id'))
    op.create_table('manual_releases',
                    sa.Column('assignment', sa.String(128), nullable=False),
                    sa.Column('question', sa.String(128), nullable=False),
                    sa.Column('released_by', sa.String(128), nullable=False),
                    sa.Column('released_at', sa.DateTime(), nullable=False),
                    sa.PrimaryKeyConstraint('assignment', 'question'))
    op.create_table('score_overrides',
                    sa.Column('id', sa.Integer(), primary_key=True, autoincrement=True),
                    _submission(), sa.Column('check', sa.String(256), nullable=False),
                    sa.Column('score', sa.Float(), nullable=True),
                    sa.Column('reason', sa.Text(), nullable=False),
                    sa.Column('author', sa.String(128), nullable=False),
                    sa.Column('created_at', sa.DateTime(), nullable=False))
    op.create_index('ix_score_overrides_submission_id', 'score_overrides', ['submission_id'])
    op.create_table('regrade_requests',
                    sa.Column('id', sa.Integer(), primary_key=True, autoincrement=True),
                    _submission(), sa.Column('check', sa.String(256), nullable=False),
                    sa.Column('status', sa.String(16), nullable=False),
                    sa.Column('created_at', sa.DateTime(), nullable=False))
    op.create_index('ix_regrade_requests_submission_id', 'regrade_requests', ['submission_id'])
    op.create_table('regrade_messages',
                    sa.Column('id', sa.Integer(), primary_key=True, autoincrement=True),
                    sa.Column('request_id', sa.Integer(),
                              sa.ForeignKey('regrade_requests.id', ondelete='CASCADE'),
                              nullable=False, index=True),
                    sa.Column('author', sa.String(128), nullable=False),
                    sa.Column('staff', sa.Boolean(), nullable=False),
                    sa.Column('text', sa.Text(), nullable=False),
                    sa.Column('created_at', sa.DateTime(), nullable=False))


def downgrade() -> None:
    for table in ('regrade_messages', 'regrade_requests', 'score_overrides', 'manual_releases',
                  'applied_items', 'answer_grades', 'rubric_items'):
        op.drop_table(table)
