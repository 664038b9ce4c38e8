"""``alloc serve``: the service's sub-command of the ``alloc`` command.

Registered as the entry point ``serve`` of the group ``alloc.commands`` (``pyproject.toml``);
the library's command line never imports the service.  The web stack is imported only when
the command runs.
"""

from __future__ import annotations

import ipaddress
import re
from pathlib import Path

import typer

__all__ = ["serve_command"]

#: most worker processes on one port (each loads the library and its kernels, about 0.2 GB)
MAX_WORKERS = 64
_HOSTNAME_LABEL = re.compile(r"(?!-)[A-Za-z0-9-]{1,63}(?<!-)")


def bind_address(text: str) -> str:
    """An IP address or a host name (RFC 1123 labels), else ``BadParameter``: refused before any start."""
    try:
        return str(ipaddress.ip_address(text))
    except ValueError:
        pass
    name = text[:-1] if text.endswith(".") else text
    if 0 < len(name) <= 253 and all(_HOSTNAME_LABEL.fullmatch(label) for label in name.split(".")):
        return text
    raise typer.BadParameter(f"expected an IP address or a host name, got {text!r}")


def serve_command(
    host: str = typer.Option("127.0.0.1", parser=bind_address, help="bind address: an IP address or a host name"),
    port: int = typer.Option(8000, min=1, max=65535, help="TCP port (1-65535)"),
    data_dir: Path | None = typer.Option(None, file_okay=False,
                                            help="where the embedded SQLite database lives (ALLOC_DATA_DIR)"),
    database_url: str | None = typer.Option(None, help="SQLAlchemy URL, e.g. postgresql+psycopg://... (ALLOC_DATABASE_URL)"),
    api_key_file: Path | None = typer.Option(
        None, exists=True, dir_okay=False, readable=True, help="file holding the X-API-Key that write endpoints require (ALLOC_API_KEY_FILE; or set "
                   "ALLOC_API_KEY). A key is never taken on the command line: /proc/<pid>/cmdline is world-readable"),
    workers: int = typer.Option(1, min=1, max=MAX_WORKERS, help=f"worker processes on this port (1-{MAX_WORKERS}); "
                                "any number of them (and of replicas) may share one database"),
    access_log: bool = typer.Option(False, "--access-log", help="log every request"),
) -> None:
    """Start the allocation and reconfiguration HTTP service (OpenAPI docs at /docs)."""
    from service.main import serve

    serve(host=host, port=port, data_dir=data_dir, database_url=database_url, api_key_file=api_key_file, workers=workers,
          access_log=access_log)
