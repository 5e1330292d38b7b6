"""Alembic environment: the connection is handed over by :func:`autograder.service.db.upgrade`."""

from __future__ import annotations

from alembic import context

from autograder.service.models import Base

connection = context.config.attributes.get("connection")
if connection is None:
    raise RuntimeError("run migrations through autograder.service.db.upgrade(engine)")
context.configure(connection=connection, target_metadata=Base.metadata,
                  render_as_batch=connection.dialect.name == "sqlite")
with context.begin_transaction():
    context.run_migrations()
