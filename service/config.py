"""Service settings, read from the environment (prefix ``ALLOC_``).

=========================  ==========================================================
``ALLOC_DATA_DIR``         directory of the embedded database (default ``./data``)
``ALLOC_DATABASE_URL``     SQLAlchemy URL; default ``sqlite:///<data_dir>/alloc.sqlite3``
                           (a ``postgresql+psycopg://...`` URL works through the same layer)
``ALLOC_API_KEY``          when set, write endpoints require header ``X-API-Key``
``ALLOC_MAX_BODY_BYTES``   request body limit, larger bodies get 413 (default 4 MiB)
``ALLOC_CACHE_SIZE``       built allocators kept in memory (default 512)
=========================  ==========================================================

The size caps (``MAX_EFFECTORS``, ``MAX_AXES``, ``MAX_BATCH``) are part of the API
contract (they appear in the OpenAPI schema) and are therefore constants, not settings.
"""

from __future__ import annotations

from pathlib import Path

from pydantic import Field
from pydantic_settings import BaseSettings, SettingsConfigDict

__all__ = ["Settings", "MAX_EFFECTORS", "MAX_AXES", "MAX_BATCH", "MAX_DIRECTIONS", "MAX_FACET_SUBSETS",
           "OPTION_CAPS"]

#: largest number of effectors ``m`` of a problem or vehicle
MAX_EFFECTORS = 64
#: largest number of virtual-control axes ``k``
MAX_AXES = 6
#: largest number of demands in one batch request
MAX_BATCH = 10_000
#: largest number of directions in one AMS request
MAX_DIRECTIONS = 256
#: largest number of (k-1)-subsets of moving effectors for work that enumerates the AMS
#: facets (``alloc.ams``: the ``da_facet``/``da_bisect``/``da_table`` methods and the exact
#: AMS summary), about a second of build time.  It grows as C(m, k-1): m = 64, k = 6 is
#: 7.6 million facets, hours; larger problems use the LP forms instead.
MAX_FACET_SUBSETS = 20_000
#: upper bounds on method options whose cost grows with their value (time or memory);
#: the library accepts any positive value, a shared service cannot
OPTION_CAPS: dict[tuple[str, str], int] = {
    ("da_table", "resolution"): 256,  # build time ~ resolution^2: 256 -> ~3 s, 1024 -> ~1 min (ICE)
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

    @property
    def resolved_database_url(self) -> str:
        """The configured URL, or the embedded SQLite file under ``data_dir``."""
        if self.database_url:
            return self.database_url
        return f"sqlite:///{(self.data_dir / 'alloc.sqlite3').resolve()}"
