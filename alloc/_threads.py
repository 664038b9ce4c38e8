"""Row-split work on a shared thread pool, for the compiled batch loops (which release the GIL).

:func:`split_rows` runs ``fn(start, stop)`` on contiguous chunks of ``range(n)``, one per
thread, and returns the results in row order; with one thread it runs inline.
:func:`threads_for` is how many threads a batch of ``n`` rows gets: one per core
(``MAX_THREADS``, default the core count), at least ``ROWS_PER_THREAD`` rows each.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import TypeVar

import numpy as np

__all__ = ["split_rows", "threads_for", "ROWS_PER_THREAD", "MAX_THREADS"]

T = TypeVar("T")

#: rows per thread below which a batch stays on one thread
ROWS_PER_THREAD = 1000
#: most threads a batch uses (None: one per core)
MAX_THREADS: int | None = None
_POOL: list[ThreadPoolExecutor] = []


def threads_for(n_rows: int) -> int:
    """Threads for ``n_rows``: one per core (``MAX_THREADS``), at least ``ROWS_PER_THREAD`` rows each."""
    cap = MAX_THREADS if MAX_THREADS is not None else (os.cpu_count() or 1)
    return max(1, min(cap, n_rows // ROWS_PER_THREAD))


def split_rows(fn: Callable[[int, int], T], n_rows: int, threads: int) -> list[T]:
    """``[fn(a, b) for (a, b) in chunks]`` over ``threads`` contiguous chunks of ``range(n_rows)``."""
    cuts = np.linspace(0, n_rows, threads + 1).astype(np.int64)
    chunks = [(int(cuts[i]), int(cuts[i + 1])) for i in range(threads)]
    if threads == 1:
        return [fn(*chunks[0])]
    if not _POOL or _POOL[0]._max_workers < threads:  # noqa: SLF001 - grow the pool when asked for more
        _POOL[:] = [ThreadPoolExecutor(max_workers=max(threads, os.cpu_count() or 1), thread_name_prefix="alloc-batch")]
    return list(_POOL[0].map(lambda ab: fn(*ab), chunks))
