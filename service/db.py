"""Storage: SQLAlchemy 2.x tables for vehicles and their event history.

The schema is created and changed only by the Alembic migrations in
``service/migrations`` (:func:`migrate`, run at start-up under a lock so that workers and
replicas starting together migrate once): ``alembic -c service/alembic.ini`` is not
needed, the service upgrades to ``head`` itself.

The default is an embedded SQLite file in WAL mode with ``synchronous=FULL``, so a
transaction is on disk when ``commit()`` returns: a response sent after the commit
survives a SIGKILL of the service.  The same code runs on PostgreSQL given
``ALLOC_DATABASE_URL`` (its commits are durable by default).
"""

from __future__ import annotations

import logging
import re
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import fcntl
from contextlib import contextmanager
from collections.abc import Iterator

from sqlalchemy import (
    JSON, DateTime, ForeignKey, Integer, String, Text, TypeDecorator, UniqueConstraint, create_engine, event, inspect,
    text,
)
from sqlalchemy.engine import Engine, make_url
from sqlalchemy.pool import NullPool
from sqlalchemy.orm import DeclarativeBase, Mapped, mapped_column, sessionmaker

__all__ = ["Base", "VehicleRow", "EventRow", "IdempotencyRow", "TelemetryRow", "ProposalRow", "make_engine",
           "make_sessionmaker", "migrate", "schema_revision", "head_revision",
           "SchemaError", "utcnow"]

MIGRATIONS = Path(__file__).resolve().parent / "migrations"
_log = logging.getLogger("service")


def utcnow() -> datetime:
    return datetime.now(UTC)


class UTCDateTime(TypeDecorator[datetime]):
    """Timezone-aware UTC timestamps on every backend (SQLite drops the offset)."""

    impl = DateTime(timezone=True)
    cache_ok = True

    def process_result_value(self, value: datetime | None, dialect: Any) -> datetime | None:
        if value is not None and value.tzinfo is None:
            value = value.replace(tzinfo=UTC)
        return value


class Base(DeclarativeBase):
    type_annotation_map = {dict[str, Any]: JSON, datetime: UTCDateTime}


class VehicleRow(Base):
    __tablename__ = "vehicles"

    id: Mapped[str] = mapped_column(String(36), primary_key=True)
    name: Mapped[str | None] = mapped_column(String(64))
    #: the nominal problem, :meth:`alloc.Problem.to_dict`
    problem: Mapped[dict[str, Any]]
    #: effector name -> health (non-healthy effectors only), see service.health
    health: Mapped[dict[str, Any]]
    #: number of events recorded; optimistic-concurrency token of ``health``
    health_version: Mapped[int] = mapped_column(Integer, default=0)
    created_at: Mapped[datetime] = mapped_column(default=utcnow)


class EventRow(Base):
    __tablename__ = "events"
    __table_args__ = (UniqueConstraint("vehicle_id", "seq", name="uq_events_vehicle_seq"),)

    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    vehicle_id: Mapped[str] = mapped_column(ForeignKey("vehicles.id", ondelete="CASCADE"), index=True)
    seq: Mapped[int] = mapped_column(Integer)
    effector: Mapped[str] = mapped_column(String(64))
    kind: Mapped[str] = mapped_column(String(16))
    params: Mapped[dict[str, Any]]
    note: Mapped[str | None] = mapped_column(String(500))
    recorded_at: Mapped[datetime] = mapped_column(default=utcnow)


class IdempotencyRow(Base):
    """The answer to a write sent with an ``Idempotency-Key``: a retry with the same key gets
    it again (written in the same transaction as the write it answers)."""

    __tablename__ = "idempotency_keys"

    #: the write's method and path (``POST /v1/vehicles/<id>/events``): a key is per endpoint
    scope: Mapped[str] = mapped_column(String(200), primary_key=True)
    key: Mapped[str] = mapped_column(String(255), primary_key=True)
    #: SHA-256 of the scope and the validated body: the same key with another body is a 409
    fingerprint: Mapped[str] = mapped_column(String(64))
    status: Mapped[int] = mapped_column(Integer)
    body: Mapped[str] = mapped_column(Text)
    created_at: Mapped[datetime] = mapped_column(default=utcnow, index=True)


class TelemetryRow(Base):
    """A vehicle's telemetry policy, detector settings and detector state (:mod:`service.telemetry`)."""

    __tablename__ = "telemetry_states"

    vehicle_id: Mapped[str] = mapped_column(ForeignKey("vehicles.id", ondelete="CASCADE"), primary_key=True)
    policy: Mapped[str] = mapped_column(String(16))
    #: the detector's settings (validated), service.telemetry.DetectorSettings
    config: Mapped[dict[str, Any]]
    #: alloc.estimation.FailureDetector.to_dict(); null before the first batch
    state: Mapped[dict[str, Any] | None]
    #: optimistic-concurrency token of the row (every write adds 1)
    revision: Mapped[int] = mapped_column(Integer)
    #: the vehicle's health_version the detector's belief was last aligned with (-1: realign)
    synced_version: Mapped[int] = mapped_column(Integer)
    updated_at: Mapped[datetime] = mapped_column(default=utcnow)


class ProposalRow(Base):
    """A detection proposed as a health event (policy ``confirm``), until accepted or rejected."""

    __tablename__ = "telemetry_proposals"

    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    vehicle_id: Mapped[str] = mapped_column(ForeignKey("vehicles.id", ondelete="CASCADE"), index=True)
    status: Mapped[str] = mapped_column(String(16))
    effector: Mapped[str] = mapped_column(String(64))
    kind: Mapped[str] = mapped_column(String(16))
    params: Mapped[dict[str, Any]]
    detection: Mapped[dict[str, Any]]
    #: the vehicle's health_version when proposed
    health_version: Mapped[int] = mapped_column(Integer)
    #: the event an accepted proposal became
    event_seq: Mapped[int | None] = mapped_column(Integer)
    created_at: Mapped[datetime] = mapped_column(default=utcnow)
    decided_at: Mapped[datetime | None]


def _sqlite_pragmas(dbapi_connection: Any, connection_record: Any) -> None:
    cursor = dbapi_connection.cursor()
    cursor.execute("PRAGMA journal_mode=WAL")
    cursor.execute("PRAGMA synchronous=FULL")  # fsync the WAL on every commit: durable on return
    cursor.execute("PRAGMA foreign_keys=ON")
    cursor.execute("PRAGMA busy_timeout=5000")
    cursor.close()


def make_engine(url: str) -> Engine:
    """An engine for ``url``; SQLite gets WAL + synchronous=FULL and its directory created."""
    parsed = make_url(url)
    if parsed.get_backend_name() == "sqlite":
        if parsed.database and parsed.database != ":memory:":
            Path(parsed.database).parent.mkdir(parents=True, exist_ok=True)
        engine = create_engine(url, connect_args={"check_same_thread": False})
        event.listen(engine, "connect", _sqlite_pragmas)
    else:
        engine = create_engine(url, pool_pre_ping=True, pool_size=10, max_overflow=20)
    migrate(engine)
    return engine


@contextmanager
def _migration_lock(engine: Engine) -> Iterator[None]:
    """One migrator at a time: a file lock beside a SQLite file, an advisory lock on PostgreSQL."""
    if engine.dialect.name == "sqlite":
        path = engine.url.database
        if not path or path == ":memory:":
            yield
            return
        with open(f"{path}.migrate.lock", "w") as lock:
            fcntl.flock(lock, fcntl.LOCK_EX)
            try:
                yield
            finally:
                fcntl.flock(lock, fcntl.LOCK_UN)
    elif engine.dialect.name == "postgresql":
        with engine.connect() as conn:
            conn.execute(text("SELECT pg_advisory_lock(72412)"))
            try:
                yield
            finally:
                conn.execute(text("SELECT pg_advisory_unlock(72412)"))
                conn.commit()
    else:  # pragma: no cover - other backends: no concurrent start-up protection
        yield


class SchemaError(RuntimeError):
    """The database's schema is neither a known revision nor repairable: start-up stops."""


def _migration_engine(engine: Engine) -> Engine:
    """The engine migrations run on.  SQLite: a connection of its own whose transaction
    really covers DDL.  Python's sqlite3 module commits before ``CREATE``/``DROP``/``ALTER``
    on its own (it opens transactions for DML only), so an upgrade that failed half-way
    used to keep its first tables and an empty ``alembic_version``; with the driver's
    transaction handling off and ``BEGIN`` sent explicitly (SQLAlchemy's pysqlite recipe),
    an upgrade is all or nothing.  Foreign keys stay off here, as SQLite's table-rebuilding
    ``ALTER`` (Alembic's batch mode) needs.  Other databases: the engine itself."""
    if engine.dialect.name != "sqlite":
        return engine
    migrating = create_engine(engine.url, poolclass=NullPool)

    @event.listens_for(migrating, "connect")
    def _connect(dbapi_connection: Any, connection_record: Any) -> None:
        dbapi_connection.isolation_level = None  # the driver opens no transaction; we do
        cursor = dbapi_connection.cursor()
        cursor.execute("PRAGMA journal_mode=WAL")
        cursor.execute("PRAGMA synchronous=FULL")
        cursor.execute("PRAGMA busy_timeout=5000")
        cursor.close()

    @event.listens_for(migrating, "begin")
    def _begin(conn: Any) -> None:
        conn.exec_driver_sql("BEGIN IMMEDIATE")  # the write lock up front: one migrator at a time
    return migrating


def schema_revision(conn: Any) -> str | None:
    """The revision the tables match, read from the tables themselves (``None``: no schema).

    Each revision leaves a mark: 0001 the ``vehicles`` and ``events`` tables, 0002 the
    unique ``(vehicle_id, seq)`` constraint, 0003 the ``idempotency_keys`` table, 0004 the
    ``telemetry_states`` table.  A new
    revision adds its mark here.
    """
    inspector = inspect(conn)
    tables = set(inspector.get_table_names())
    if "vehicles" not in tables:
        if tables - {"alembic_version"}:
            raise SchemaError(f"the database has tables {sorted(tables)} but no 'vehicles': not this "
                              f"service's database, or damaged; restore it from a backup")
        return None
    if "events" not in tables:
        raise SchemaError("the database has 'vehicles' but no 'events' table: damaged; restore it from a backup")
    if "telemetry_states" in tables:
        return "0004"
    if "idempotency_keys" in tables:
        return "0003"
    uniques = {u["name"] for u in inspector.get_unique_constraints("events")}
    return "0002" if "uq_events_vehicle_seq" in uniques else "0001"


def _repair(conn: Any, cfg: Any) -> None:
    """A database left half-upgraded by an older release (its SQLite DDL committed statement
    by statement): Alembic's leftover batch tables dropped, and a missing or empty
    ``alembic_version`` stamped with the revision the tables match, saying so in the log."""
    from alembic import command

    tables = set(inspect(conn).get_table_names())
    for leftover in sorted(t for t in tables if t.startswith("_alembic_tmp_")):
        _log.warning("database repair: dropping %s, left by an interrupted upgrade", leftover)
        conn.exec_driver_sql(f'DROP TABLE "{leftover}"')
    if _stamped(conn) is not None:
        return
    found = schema_revision(conn)
    if found is not None:
        if "alembic_version" in tables:
            _log.warning("database repair: alembic_version is empty but the tables are revision %s "
                         "(an upgrade interrupted by an older release); stamping %s and upgrading", found, found)
        command.stamp(cfg, found)


_REVISION = re.compile(r"""^(down_revision|revision)\s*(?::[^=]*)?=\s*(None|"[^"]*"|'[^']*')\s*$""", re.M)


def head_revision() -> str | None:
    """The newest revision of ``service/migrations/versions``, read from the scripts' text (the
    one no other revises); ``None`` when that does not name exactly one (a merge, a branch, a
    revision written another way): then Alembic decides."""
    revises: dict[str, str | None] = {}
    for script in (MIGRATIONS / "versions").glob("*.py"):
        found = dict((k, None if v == "None" else v[1:-1]) for k, v in _REVISION.findall(script.read_text()))
        if set(found) != {"revision", "down_revision"} or found["revision"] is None:
            return None
        revises[found["revision"]] = found["down_revision"]
    heads = set(revises) - set(revises.values())
    return heads.pop() if len(heads) == 1 else None


def _is_current(conn: Any) -> bool:
    """Whether the database is stamped at :func:`head_revision` with nothing to repair: then
    start-up skips Alembic, whose import alone cost 0.3-0.7 s of CPU."""
    head = head_revision()
    if head is None:
        return False
    tables = inspect(conn).get_table_names()
    if "alembic_version" not in tables or any(t.startswith("_alembic_tmp_") for t in tables):
        return False
    return conn.exec_driver_sql("SELECT version_num FROM alembic_version").scalars().all() == [head]


def migrate(engine: Engine) -> None:
    """Upgrade the schema to the latest Alembic revision, all or nothing (one transaction,
    on SQLite too: :func:`_migration_engine`).  A database made by an older ``create_all``
    release (tables present, no version) is stamped with the revision its tables match, as
    is one that an older release left half-upgraded (:func:`_repair`).  A database at the
    latest revision is left as it is without loading Alembic (:func:`_is_current`, read in
    the migration's own transaction, under its lock)."""
    migrating = _migration_engine(engine)
    try:
        with _migration_lock(engine):
            try:
                with migrating.begin() as conn:
                    if _is_current(conn):
                        return
                    from alembic import command
                    from alembic.config import Config

                    cfg = Config()
                    cfg.set_main_option("script_location", str(MIGRATIONS))
                    cfg.attributes["connection"] = conn
                    _repair(conn, cfg)
                    command.upgrade(cfg, "head")
            except SchemaError:
                raise
            except Exception as exc:
                with migrating.connect() as conn:
                    at = _stamped(conn)
                raise SchemaError(f"the database upgrade failed and was rolled back: the database is unchanged "
                                  f"(at revision {at or 'none'}); {type(exc).__name__}: {exc}") from exc
    finally:
        if migrating is not engine:
            migrating.dispose()


def _stamped(conn: Any) -> str | None:
    """The revision ``alembic_version`` records (``None``: no table or no row)."""
    if "alembic_version" not in inspect(conn).get_table_names():
        return None
    return conn.exec_driver_sql("SELECT version_num FROM alembic_version").scalar()


def make_sessionmaker(engine: Engine) -> sessionmaker:
    return sessionmaker(engine, expire_on_commit=False)
