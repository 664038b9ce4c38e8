"""Service settings, read from the environment (prefix ``ALLOC_``).

===========================  ========================================================
``ALLOC_DATA_DIR``           directory of the embedded database (default ``./data``)
``ALLOC_DATABASE_URL``       SQLAlchemy URL; default ``sqlite:///<data_dir>/alloc.sqlite3``
                             (``postgresql+psycopg://...`` works through the same layer)
``ALLOC_API_KEY``            when set, write endpoints require header ``X-API-Key``; set
                             but empty refuses to start (it would disable authentication)
``ALLOC_MAX_BODY_BYTES``     request body limit, larger bodies get 413 (default 4 MiB)
``ALLOC_CACHE_SIZE``         built allocators kept in memory (default 512)
``ALLOC_CACHE_BYTES``        ... and their total size (default 128 MiB)
``ALLOC_INLINE_CACHE_BYTES`` the share of inline problems in it (default 32 MiB)
``ALLOC_BUILD_BUDGET_S``     predicted build time above which a build is refused (3 s: the
                             library's FACET_LIMIT priced by the cost model, service.cost)
``ALLOC_BUILD_WORKERS``      build processes for costly builds (default 1; service.builds)
``ALLOC_BUILD_QUEUE``        costly builds waiting beyond those, then 429 (default 8)
``ALLOC_WARMUP``             compile the numba kernels at start-up (default true)
``ALLOC_REQUEST_TIMEOUT_S``  seconds for a request's headers and body to arrive (10)
===========================  ========================================================

The size caps (``MAX_EFFECTORS``, ``MAX_AXES``, ``MAX_BATCH``, ``MAX_MAGNITUDE``) are part
of the API contract (they appear in the OpenAPI schema) and are therefore constants.

Memory bound (documented, checked by ``tests/test_service_limits.py`` on the service and its
build processes together): the start-up RSS of the service and of its
``ALLOC_BUILD_WORKERS`` build processes, plus ``ALLOC_CACHE_BYTES``, plus up to 1,024
vehicle states (~70 MiB at m = 64), plus one build in flight per build process of at most
~90 MiB (a facet enumeration at the cost cap, see :mod:`service.cost`), plus the request
bodies in flight (``ALLOC_MAX_BODY_BYTES`` each, at most ``limit_concurrency``).
"""

from __future__ import annotations

from pathlib import Path

from pydantic import Field, field_validator
from pydantic_settings import BaseSettings, SettingsConfigDict

from .cost import DEFAULT_BUILD_BUDGET_S

__all__ = ["Settings", "MAX_EFFECTORS", "MAX_AXES", "MAX_BATCH", "MAX_DIRECTIONS", "MAX_MAGNITUDE",
           "MIN_WEIGHT", "OPTION_CAPS"]

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
#: per-call bounds on method options that set how many iterations one allocation may run
#: (a call runs on the event loop): the library accepts any positive value, a shared service cannot.
#: Build-time options are bounded by the build-cost model instead (service.cost).
OPTION_CAPS: dict[tuple[str, str], int] = {
    ("da_bisect", "angles"): 1024,
    ("da_bisect", "max_rounds"): 1000,
}


class Settings(BaseSettings):
    """Runtime configuration; every field can be set as ``ALLOC_<FIELD>``."""

    model_config = SettingsConfigDict(env_prefix="ALLOC_", extra="ignore")

    data_dir: Path = Path("./data")
    database_url: str | None = None
    api_key: str | None = None
    max_body_bytes: int = Field(default=4 * 1024 * 1024, gt=0)
    cache_size: int = Field(default=512, gt=0)
    cache_bytes: int = Field(default=128 * 1024 * 1024, gt=0)
    inline_cache_bytes: int = Field(default=32 * 1024 * 1024, ge=0)
    build_budget_s: float = Field(default=DEFAULT_BUILD_BUDGET_S, gt=0, le=600)
    build_workers: int = Field(default=1, ge=1, le=16)
    build_queue: int = Field(default=8, ge=0, le=1024)
    warmup: bool = True
    request_timeout_s: float = Field(default=10.0, gt=0, le=600)  # read by service.server

    @field_validator("api_key")
    @classmethod
    def _key_not_empty(cls, value: str | None) -> str | None:
        if value is not None and not value.strip():
            raise ValueError("ALLOC_API_KEY is set but empty: that would disable authentication; "
                             "unset it to run without a key, or give a key")
        return value

    @property
    def resolved_database_url(self) -> str:
        """The configured URL, or the embedded SQLite file under ``data_dir``."""
        if self.database_url:
            return self.database_url
        return f"sqlite:///{(self.data_dir / 'alloc.sqlite3').resolve()}"
