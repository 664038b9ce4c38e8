"""Start-up's cheap paths keep their guarantees: a database at the latest revision starts
without loading Alembic, and every other database is still migrated (issue 22: service
ready within 3 s)."""

from __future__ import annotations

import sys
from pathlib import Path

from sqlalchemy import create_engine, inspect

from service.db import MIGRATIONS, head_revision, make_engine


def _alembic_config(url: str):
    from alembic.config import Config
    cfg = Config()
    cfg.set_main_option("script_location", str(MIGRATIONS))
    cfg.set_main_option("sqlalchemy.url", url)
    return cfg


def _version(url: str) -> list[str]:
    engine = create_engine(url)
    try:
        with engine.connect() as conn:
            return list(conn.exec_driver_sql("SELECT version_num FROM alembic_version").scalars())
    finally:
        engine.dispose()


def test_head_read_from_the_scripts_is_alembics_head():
    from alembic.script import ScriptDirectory
    assert ScriptDirectory.from_config(_alembic_config("sqlite://")).get_heads() == [head_revision()]


def test_a_current_database_starts_without_alembic(tmp_path: Path, monkeypatch):
    url = f"sqlite:///{tmp_path / 'service.db'}"
    make_engine(url).dispose()  # a fresh database: migrated, by Alembic
    assert _version(url) == [head_revision()]
    monkeypatch.setitem(sys.modules, "alembic", None)  # from here any import of Alembic fails
    make_engine(url).dispose()
    assert _version(url) == [head_revision()]


def test_an_older_or_damaged_database_is_still_migrated(tmp_path: Path):
    from alembic import command
    url = f"sqlite:///{tmp_path / 'service.db'}"
    make_engine(url).dispose()
    head = head_revision()
    engine = create_engine(url)
    with engine.begin() as conn:  # one revision behind (the migrations run on the caller's connection)
        cfg = _alembic_config(url)
        cfg.attributes["connection"] = conn
        command.downgrade(cfg, "-1")
    engine.dispose()
    assert _version(url) != [head]
    make_engine(url).dispose()
    assert _version(url) == [head]
    # stamped at head but with an interrupted batch upgrade's leftover: repaired, not skipped
    engine = create_engine(url)
    with engine.begin() as conn:
        conn.exec_driver_sql('CREATE TABLE "_alembic_tmp_events" (id INTEGER)')
    engine.dispose()
    make_engine(url).dispose()
    engine = create_engine(url)
    assert not [t for t in inspect(engine).get_table_names() if t.startswith("_alembic_tmp_")]
    engine.dispose()
    assert _version(url) == [head]


def test_the_application_imports_without_the_kernels_or_scipy_extras():
    """What the start-up does not load: numba and the methods (the warm-up thread loads them
    after the server binds), ``scipy.special`` and ``scipy.linalg`` (the detector's tail
    and whitener, imported where used).  Together about 0.7 s of CPU at every start."""
    import subprocess

    code = ("import sys, service.main; "
            "print(sorted(m for m in ('numba', 'alloc.methods', 'alloc.api', 'scipy.special', 'scipy.linalg', "
            "'scipy.stats', 'scipy.signal', 'alembic') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                         cwd=Path(__file__).resolve().parents[2], check=True).stdout
    assert out.strip() == "[]", out
