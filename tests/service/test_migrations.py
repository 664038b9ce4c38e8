"""Safe upgrades: an interrupted schema upgrade leaves the database as it was, and the next
start upgrades it; a database an older release left half-upgraded is repaired at start.

The interruption is injected at every SQL statement of the upgrade in turn: an exception
(the upgrade's own failure), and SIGKILL of the migrating process (a crash, no clean-up).
The old databases: the ``create_all`` releases' schema (revision 0001's tables, no
``alembic_version``) and an Alembic-stamped revision 0001, each holding a vehicle and events.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import sqlite3
import subprocess
import sys
from pathlib import Path

import pytest
from sqlalchemy import create_engine, event
from sqlalchemy.engine import Engine

from service.db import SchemaError, make_engine, schema_revision

ROOT = Path(__file__).resolve().parents[2]
HEAD = "0004"
_OLD_SCHEMA = [  # the create_all releases' tables (revision 0001)
    """CREATE TABLE vehicles (id VARCHAR(36) NOT NULL PRIMARY KEY, name VARCHAR(64), problem JSON NOT NULL,
       health JSON NOT NULL, health_version INTEGER NOT NULL, created_at DATETIME NOT NULL)""",
    """CREATE TABLE events (id INTEGER NOT NULL PRIMARY KEY, vehicle_id VARCHAR(36) NOT NULL
       REFERENCES vehicles (id) ON DELETE CASCADE, seq INTEGER NOT NULL, effector VARCHAR(64) NOT NULL,
       kind VARCHAR(16) NOT NULL, params JSON NOT NULL, note VARCHAR(500), recorded_at DATETIME NOT NULL)""",
    "CREATE INDEX ix_events_vehicle_id ON events (vehicle_id)",
]


def old_database(path: Path, *, stamped: bool) -> Path:
    """Revision 0001 with one vehicle and two events; ``stamped``: with ``alembic_version``."""
    path.parent.mkdir(parents=True, exist_ok=True)
    db = sqlite3.connect(path)
    for ddl in _OLD_SCHEMA:
        db.execute(ddl)
    problem = json.dumps({"B": [[1.0, 1.0]], "umin": [-1.0, -1.0], "umax": [1.0, 1.0]})
    db.execute("INSERT INTO vehicles VALUES ('v1', 'old', ?, '{}', 2, '2026-01-01 00:00:00')", (problem,))
    for seq in (1, 2):
        db.execute("INSERT INTO events (vehicle_id, seq, effector, kind, params, recorded_at) "
                   "VALUES ('v1', ?, 'e0', 'float', '{}', '2026-01-01 00:00:00')", (seq,))
    if stamped:
        db.execute("CREATE TABLE alembic_version (version_num VARCHAR(32) NOT NULL PRIMARY KEY)")
        db.execute("INSERT INTO alembic_version VALUES ('0001')")
    db.commit()
    db.close()
    return path


def snapshot(path: Path) -> dict:
    """Everything an upgrade could change: the schema's SQL and every row."""
    db = sqlite3.connect(path)
    try:
        schema = sorted(r for r in db.execute("SELECT type, name, sql FROM sqlite_master WHERE name NOT LIKE 'sqlite_%'"))
        rows = {name: sorted(db.execute(f'SELECT * FROM "{name}"').fetchall())
                for kind, name, _ in schema if kind == "table"}
    finally:
        db.close()
    return {"schema": schema, "rows": rows}


def url(path: Path) -> str:
    return f"sqlite:///{path}"


def upgrade_statements(path: Path) -> int:
    """How many SQL statements a full upgrade of this database runs (on a copy)."""
    copy = path.with_name("count.sqlite3")
    shutil.copy(path, copy)
    count = 0

    def counter(*args: object) -> None:
        nonlocal count
        count += 1
    event.listen(Engine, "before_cursor_execute", counter)
    try:
        make_engine(url(copy)).dispose()
    finally:
        event.remove(Engine, "before_cursor_execute", counter)
    return count


def assert_upgraded_intact(path: Path) -> None:
    engine = make_engine(url(path))  # the restart: upgrades to head
    engine.dispose()
    after = snapshot(path)
    assert after["rows"]["alembic_version"] == [(HEAD,)]
    assert len(after["rows"]["vehicles"]) == 1 and [r[2] for r in after["rows"]["events"]] == [1, 2]
    with create_engine(url(path)).connect() as conn:
        assert schema_revision(conn) == HEAD


class Interrupt(Exception):
    pass


@pytest.mark.parametrize("stamped", [False, True], ids=["create_all-era", "stamped-0001"])
def test_upgrade_failing_at_every_statement_leaves_the_database_unchanged(tmp_path, stamped):
    original = old_database(tmp_path / "old" / "alloc.sqlite3", stamped=stamped)
    before = snapshot(original)
    total = upgrade_statements(original)
    assert total >= 8, total  # create, copy, drop, rename, index, stamp, ...
    for n in range(1, total + 1):
        path = tmp_path / f"at-{n}" / "alloc.sqlite3"
        path.parent.mkdir()
        shutil.copy(original, path)
        seen = 0

        def fail_at_n(*args: object) -> None:
            nonlocal seen
            seen += 1
            if seen == n:
                raise Interrupt(f"statement {n}")
        event.listen(Engine, "before_cursor_execute", fail_at_n)
        try:
            with pytest.raises(SchemaError, match="rolled back: the database is unchanged") as info:
                make_engine(url(path))
        finally:
            event.remove(Engine, "before_cursor_execute", fail_at_n)
        assert f"statement {n}" in str(info.value)
        assert snapshot(path) == before, f"interrupted at statement {n} of {total}"
        assert_upgraded_intact(path)


_KILL_AT = """
import os, signal, sys
from sqlalchemy import event
from sqlalchemy.engine import Engine
from service.db import make_engine
n, seen = int(sys.argv[2]), 0
def kill_at_n(*args):
    global seen
    seen += 1
    if seen == n:
        os.kill(os.getpid(), signal.SIGKILL)
event.listen(Engine, "before_cursor_execute", kill_at_n)
make_engine(sys.argv[1])
"""


def _kill_points(total: int, every: bool) -> list[int]:
    return list(range(1, total + 1)) if every else sorted({1, total // 3, total // 2, (2 * total) // 3, total})


@pytest.mark.parametrize("every", [False, pytest.param(True, marks=pytest.mark.slow)], ids=["sample", "every"])
def test_upgrade_killed_at_a_statement_recovers_on_restart(tmp_path, every):
    """SIGKILL of the migrating process mid-upgrade (no rollback runs): the next start finds the
    old database (SQLite's journal undoes the partial transaction) and upgrades it."""
    original = old_database(tmp_path / "old" / "alloc.sqlite3", stamped=False)
    before = snapshot(original)
    total = upgrade_statements(original)
    for n in _kill_points(total, every):
        path = tmp_path / f"kill-{n}" / "alloc.sqlite3"
        path.parent.mkdir()
        shutil.copy(original, path)
        proc = subprocess.run([sys.executable, "-c", _KILL_AT, url(path), str(n)], cwd=ROOT, capture_output=True,
                              timeout=120, env={**os.environ, "PYTHONPATH": str(ROOT)})
        assert proc.returncode == -signal.SIGKILL, proc.stderr.decode()[-2000:]
        assert snapshot(path) == before, f"killed at statement {n} of {total}"
        assert_upgraded_intact(path)


def test_half_upgraded_database_of_an_older_release_is_repaired(tmp_path, caplog):
    """What an older release left after a failed first upgrade: the 0001 tables, an empty
    ``alembic_version`` and Alembic's batch table; every start then failed with "table
    vehicles already exists".  Now: repaired with a warning naming what was done."""
    path = old_database(tmp_path / "broken" / "alloc.sqlite3", stamped=False)
    db = sqlite3.connect(path)
    db.execute("CREATE TABLE alembic_version (version_num VARCHAR(32) NOT NULL PRIMARY KEY)")
    db.execute("CREATE TABLE _alembic_tmp_events (id INTEGER)")
    db.commit()
    db.close()
    with caplog.at_level("WARNING", logger="service"):
        assert_upgraded_intact(path)
    text = caplog.text
    assert "alembic_version is empty but the tables are revision 0001" in text and "_alembic_tmp_events" in text
    assert "_alembic_tmp_events" not in snapshot(path)["rows"]


def test_upgrade_that_cannot_succeed_says_so_and_changes_nothing(tmp_path):
    """Duplicate (vehicle, seq) rows make revision 0002's unique constraint impossible: every
    start refuses with the reason, and the database stays as it was (no half state)."""
    path = old_database(tmp_path / "dup" / "alloc.sqlite3", stamped=True)
    db = sqlite3.connect(path)
    db.execute("INSERT INTO events (vehicle_id, seq, effector, kind, params, recorded_at) "
               "VALUES ('v1', 2, 'e0', 'float', '{}', '2026-01-01 00:00:00')")
    db.commit()
    db.close()
    before = snapshot(path)
    for _ in range(2):
        with pytest.raises(SchemaError, match=r"unchanged \(at revision 0001\).*UNIQUE"):
            make_engine(url(path))
        assert snapshot(path) == before


def test_damaged_schema_is_refused_with_a_clear_message(tmp_path):
    path = tmp_path / "damaged" / "alloc.sqlite3"
    path.parent.mkdir()
    db = sqlite3.connect(path)
    db.execute(_OLD_SCHEMA[0])
    db.commit()
    db.close()
    with pytest.raises(SchemaError, match="no 'events' table"):
        make_engine(url(path))
