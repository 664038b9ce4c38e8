"""Service settings, read from the environment (prefix ``ALLOC_``): every limit in one table.

==================================  =================================================================
``ALLOC_DATA_DIR``                  directory of the embedded database (default ``./data``)
``ALLOC_DATABASE_URL``              SQLAlchemy URL; default ``sqlite:///<data_dir>/alloc.sqlite3``
                                    (``postgresql+psycopg://...`` works through the same layer)
``ALLOC_API_KEY``                   when set, write endpoints require header ``X-API-Key``; empty, or
``ALLOC_API_KEY_FILE``              with surrounding whitespace, refuses to start.  The file form
                                    holds the key (one trailing newline allowed); never on argv
``ALLOC_MAX_BODY_BYTES``            request body limit, larger bodies get 413 (default 4 MiB)
``ALLOC_BODY_BYTES_IN_FLIGHT``      request bodies held at once (until parsed), 503 beyond (64 MiB)
``ALLOC_WRITER_BODY_BYTES``         ... of which kept for authenticated writes (default 8 MiB)
``ALLOC_MAX_HEADER_BYTES``          request line and headers together, 431 beyond (default 16 KiB)
``ALLOC_MAX_HEADERS``               header fields per request, 431 beyond (default 64)
``ALLOC_MAX_VALIDATION_ERRORS``     entries listed in a 422's ``errors`` (the rest counted; 20)
``ALLOC_CACHE_SIZE``                built allocators kept in memory (default 512)
``ALLOC_CACHE_BYTES``               ... and their total size (default 128 MiB)
``ALLOC_INLINE_CACHE_BYTES``        the share of inline problems in it (default 32 MiB)
``ALLOC_BUILD_BUDGET_S``            predicted build time above which a build is refused (3 s: the
                                    library's FACET_LIMIT priced by the cost model, service.cost)
``ALLOC_BATCH_BUDGET_S``            predicted time of one batch (rows x the method's declared
                                    per-call cost) above which it is refused with 422 (default 2 s)
``ALLOC_MAX_ANSWER_BYTES``          predicted size of one answer above which it is refused (16 MiB)
``ALLOC_ANSWER_BYTES_IN_FLIGHT``    answer bytes held for clients at once, 503 beyond (96 MiB)
``ALLOC_WRITE_TIMEOUT_S``           a client must take an answer's next bytes within this, else the
                                    connection is dropped and its answer freed (default 10 s)
``ALLOC_BUILD_WORKERS``             build processes for costly builds and batches (default 1)
``ALLOC_BUILD_QUEUE``               costly work waiting beyond those, then 429 (default 8)
``ALLOC_WARMUP``                    compile/load the numba kernels before the worker is ready (true)
``ALLOC_STARTUP_TIMEOUT_S``         a worker must be ready (kernels loaded) within this, else it is
                                    restarted; health checks start only once it is ready (300 s)
``ALLOC_REQUEST_TIMEOUT_S``         seconds for a request's headers and body to arrive (10)
``ALLOC_KEEP_ALIVE_S``              idle keep-alive connections closed after this (5 s)
``ALLOC_MAX_CONNECTIONS``           open connections per worker process (512)
``ALLOC_RESERVED_CONNECTIONS``      kept free for new connections: beyond ``MAX - RESERVED`` open,
                                    the oldest connection that is not running a request (still
                                    sending its head, or idle) is closed (default 64)
``ALLOC_MAX_CONNECTIONS_PER_CLIENT`` open connections per client address (default 128; behind a reverse
                                    proxy or NAT every client shares the proxy's: docs/service.md)
``ALLOC_RESERVED_REQUESTS``         HTTP requests in flight beyond ``ALLOC_MAX_CONNECTIONS`` admitted
                                    only for events and the other keyed priority writes,
                                    ``/v1/health`` and ``/v1/ready`` (default 32)
``ALLOC_MAX_WEBSOCKETS``            open WebSockets per worker process, counted apart from HTTP's
                                    limit; an upgrade beyond gets 503 (default 1024: one worker
                                    held 1,000 sockets at 50 Hz, about 85 KiB each)
``ALLOC_WS_KEY_MESSAGES_PER_S``     telemetry messages per second one API key's WebSockets may have
                                    processed together, per worker process; beyond, 429 unparsed,
                                    and refusals paced at the same rate (default 100)
``ALLOC_WS_KEY_BYTES_PER_S``        ... and their bytes per second (default 4 MiB)
``ALLOC_IDEMPOTENCY_TTL_S``         how long an ``Idempotency-Key`` and its answer are kept (24 h)
==================================  =================================================================

The size caps (``MAX_EFFECTORS``, ``MAX_AXES``, ``MAX_BATCH``, ``MAX_MAGNITUDE``) are part
of the API contract (they appear in the OpenAPI schema) and are therefore constants.

Memory bound (documented, checked by ``tests/service/test_limits.py`` and
``tests/service/test_attacks.py`` on the service and its build processes together): the
start-up RSS of the service and of its ``ALLOC_BUILD_WORKERS`` build processes, plus
``ALLOC_CACHE_BYTES``, plus up to 1,024 vehicle states (~70 MiB at m = 64), plus one build
in flight per build process of at most ~90 MiB (a facet enumeration at the cost cap, see
:mod:`service.cost`), plus the request bodies in flight (``ALLOC_BODY_BYTES_IN_FLIGHT``, and
uvicorn's read buffer of at most 64 KiB plus one read per open connection before a body
reaches the budget), plus ``ALLOC_ANSWER_BYTES_IN_FLIGHT`` of answers (an answer
held for a client that does not read is freed after ``ALLOC_WRITE_TIMEOUT_S``).
"""

from __future__ import annotations

from pathlib import Path

from pydantic import Field, field_validator, model_validator
from pydantic_settings import BaseSettings, SettingsConfigDict

from .cost import DEFAULT_BUILD_BUDGET_S

__all__ = ["Settings", "MAX_EFFECTORS", "MAX_AXES", "MAX_BATCH", "MAX_DIRECTIONS", "MAX_MAGNITUDE",
           "MIN_WEIGHT"]

MiB = 1024 * 1024

#: largest number of effectors ``m`` of a problem or vehicle
MAX_EFFECTORS = 64
#: largest number of virtual-control axes ``k``
MAX_AXES = 6
#: largest number of demands in one batch request
MAX_BATCH = 10_000
#: largest number of directions in one AMS request
MAX_DIRECTIONS = 256
#: largest magnitude of any number in a request.  Products of a few such numbers (B^T W B,
#: weighted pseudo-inverses) stay far from overflow (1e9^4 = 1e36 << 1.8e308); a 1e300 entry
#: overflows to inf inside LAPACK, whose SVD then never returns (issue 12's hostile request)
MAX_MAGNITUDE = 1e9
#: smallest magnitude of a non-zero weight entry (Wu, Wv): 1 / MAX_MAGNITUDE, for the same reason
MIN_WEIGHT = 1e-9
# Per-call bounds on method options that set how many iterations one allocation may run (a call
# runs on the event loop) are declared on the options' specs (alloc.options.Option.call_cap) and
# read by service.builds.  Build-time options are bounded by the build-cost model (service.cost).


class Settings(BaseSettings):
    """Runtime configuration; every field can be set as ``ALLOC_<FIELD>`` (table above)."""

    # hide_input_in_errors: a refused key is never echoed into a log
    model_config = SettingsConfigDict(env_prefix="ALLOC_", extra="ignore", hide_input_in_errors=True)

    data_dir: Path = Path("./data")
    database_url: str | None = None
    api_key: str | None = None
    api_key_file: Path | None = None
    max_body_bytes: int = Field(default=4 * MiB, gt=0)
    body_bytes_in_flight: int = Field(default=64 * MiB, gt=0)
    writer_body_bytes: int = Field(default=8 * MiB, ge=0)
    max_header_bytes: int = Field(default=16 * 1024, ge=1024, le=1024 * 1024)
    max_headers: int = Field(default=64, ge=8, le=1024)
    max_validation_errors: int = Field(default=20, ge=1, le=1000)
    cache_size: int = Field(default=512, gt=0)
    cache_bytes: int = Field(default=128 * MiB, gt=0)
    inline_cache_bytes: int = Field(default=32 * MiB, ge=0)
    build_budget_s: float = Field(default=DEFAULT_BUILD_BUDGET_S, gt=0, le=600)
    batch_budget_s: float = Field(default=2.0, gt=0, le=600)
    max_answer_bytes: int = Field(default=16 * MiB, ge=64 * 1024)
    answer_bytes_in_flight: int = Field(default=96 * MiB, ge=64 * 1024)
    write_timeout_s: float = Field(default=10.0, gt=0, le=600)
    build_workers: int = Field(default=1, ge=1, le=16)
    build_queue: int = Field(default=8, ge=0, le=1024)
    warmup: bool = True
    startup_timeout_s: float = Field(default=300.0, gt=0, le=3600)
    request_timeout_s: float = Field(default=10.0, gt=0, le=600)
    keep_alive_s: float = Field(default=5.0, gt=0, le=600)
    max_connections: int = Field(default=512, ge=16, le=65536)
    reserved_connections: int = Field(default=64, ge=1)
    max_connections_per_client: int = Field(default=128, ge=1)
    reserved_requests: int = Field(default=32, ge=1, le=4096)
    max_websockets: int = Field(default=1024, ge=1, le=65536)
    ws_key_messages_per_s: float = Field(default=100.0, gt=0, le=1e6)
    ws_key_bytes_per_s: int = Field(default=4 * MiB, ge=64 * 1024)
    idempotency_ttl_s: float = Field(default=86400.0, gt=0)

    @field_validator("api_key")
    @classmethod
    def _key_usable(cls, value: str | None) -> str | None:
        return None if value is None else _check_key(value, "ALLOC_API_KEY")

    @model_validator(mode="after")
    def _key_from_file(self) -> Settings:
        if self.api_key_file is not None:
            if self.api_key is not None:
                raise ValueError("both ALLOC_API_KEY and ALLOC_API_KEY_FILE are set: give the key one way")
            try:
                text = self.api_key_file.read_text()
            except OSError as exc:
                raise ValueError(f"ALLOC_API_KEY_FILE = {str(self.api_key_file)!r} cannot be read: {exc}") from exc
            # one trailing newline is how a file written by `echo` or an editor ends
            text = text[:-2] if text.endswith("\r\n") else text[:-1] if text.endswith("\n") else text
            self.api_key = _check_key(text, f"the key in ALLOC_API_KEY_FILE ({self.api_key_file})")
        if self.max_body_bytes > self.body_bytes_in_flight - self.writer_body_bytes:
            raise ValueError(f"ALLOC_MAX_BODY_BYTES = {self.max_body_bytes} must be at most ALLOC_BODY_BYTES_IN_FLIGHT "
                             f"- ALLOC_WRITER_BODY_BYTES = {self.body_bytes_in_flight - self.writer_body_bytes}: "
                             f"a body of the largest size could otherwise never be accepted")
        if self.reserved_connections >= self.max_connections:
            raise ValueError(f"ALLOC_RESERVED_CONNECTIONS = {self.reserved_connections} must be below "
                             f"ALLOC_MAX_CONNECTIONS = {self.max_connections}")
        return self

    @property
    def resolved_database_url(self) -> str:
        """The configured URL, or the embedded SQLite file under ``data_dir``."""
        if self.database_url:
            return self.database_url
        return f"sqlite:///{(self.data_dir / 'alloc.sqlite3').resolve()}"


def _check_key(value: str, where: str) -> str:
    """A key a client can send: not empty, no surrounding whitespace (HTTP strips it from a
    header value, so a padded key could never match), printable ASCII."""
    if not value.strip():
        raise ValueError(f"{where} is set but empty: that would disable authentication; "
                         f"unset it to run without a key, or give a key")
    if value != value.strip():
        raise ValueError(f"{where} has surrounding whitespace ({len(value) - len(value.lstrip())} leading, "
                         f"{len(value) - len(value.rstrip())} trailing characters): a client's X-API-Key "
                         f"header is stripped of it and could never match; remove it")
    if not all(33 <= ord(c) <= 126 or c == " " for c in value):
        raise ValueError(f"{where} contains characters that are not printable ASCII: a header cannot carry them")
    return value
