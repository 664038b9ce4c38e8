"""Alembic environment: run by :func:`service.db.migrate` with an open connection."""

from __future__ import annotations

from alembic import context

from service.db import Base

connection = context.config.attributes["connection"]
# transactional_ddl: the caller's transaction covers the DDL on every backend (on SQLite the
# caller's engine makes that true: service.db._migration_engine), so an upgrade is all or nothing
context.configure(connection=connection, target_metadata=Base.metadata, render_as_batch=True,
                  transactional_ddl=True)
with context.begin_transaction():
    context.run_migrations()
