"""``alloc serve``: the service's sub-command of the ``alloc`` command.

Registered as the entry point ``serve`` of the group ``alloc.commands`` (``pyproject.toml``);
the library's command line never imports the service.  The web stack is imported only when
the command runs.
"""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

__all__ = ["serve_command"]


def serve_command(
    host: str = typer.Option("127.0.0.1", help="bind address"),
    port: int = typer.Option(8000, help="TCP port"),
    data_dir: Optional[Path] = typer.Option(None, help="where the embedded SQLite database lives (ALLOC_DATA_DIR)"),
    database_url: Optional[str] = typer.Option(None, help="SQLAlchemy URL, e.g. postgresql+psycopg://... (ALLOC_DATABASE_URL)"),
    api_key_file: Optional[Path] = typer.Option(
        None, help="file holding the X-API-Key that write endpoints require (ALLOC_API_KEY_FILE; or set "
                   "ALLOC_API_KEY). A key is never taken on the command line: /proc/<pid>/cmdline is world-readable"),
    workers: int = typer.Option(1, min=1, help="worker processes on this port; any number (and any number of "
                                               "replicas) may share one database"),
    access_log: bool = typer.Option(False, "--access-log", help="log every request"),
) -> None:
    """Start the allocation and reconfiguration HTTP service (OpenAPI docs at /docs)."""
    from service.main import serve

    serve(host=host, port=port, data_dir=data_dir, database_url=database_url, api_key_file=api_key_file, workers=workers,
          access_log=access_log)
