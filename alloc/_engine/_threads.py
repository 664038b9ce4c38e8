"""Row-split work on a shared thread pool, for the compiled batch loops (which release the GIL).

:func:`split_rows` runs ``fn(start, stop)`` on contiguous chunks of ``range(n)``, one per
thread, and returns the results in row order; with one thread it runs inline.
:func:`run_chunks` balances the load instead: every thread (the caller's one of them) pulls
the next chunk of rows from a shared counter until none is left, so a thread slowed by other
work on the machine takes fewer chunks and the batch does not wait for it.
:func:`threads_for` is how many threads a batch of ``n`` rows gets: one per core
(``MAX_THREADS``, default the core count), at least ``ROWS_PER_THREAD`` rows each.

Thread safety: the allocator's batch holds its lock (:class:`alloc.api.Allocator`) in the
calling thread while the pool works, so no other call of that allocator runs meanwhile; the
pool threads never take that lock (they would wait for their own caller).  Each pool thread
therefore works only on private state -- ``fn`` reads shared read-only data and writes its
own rows, and :func:`run_chunks` gives each thread its own context from ``make_worker`` (a
copy of a solver's caches) -- so the threads of one batch never write the same memory.
"""

from __future__ import annotations

import os
import threading
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import TypeVar

import numpy as np

__all__ = ["split_rows", "run_chunks", "threads_for", "ROWS_PER_THREAD", "MAX_THREADS", "CHUNK_ROWS"]

T = TypeVar("T")

#: rows per thread below which a batch stays on one thread
ROWS_PER_THREAD = 1000
#: most threads a batch uses (None: one per core)
MAX_THREADS: int | None = None
#: rows a thread takes at a time in :func:`run_chunks` (a few hundred microseconds of work: the
#: counter and the compiled call cost a few microseconds a chunk, the last chunk bounds the wait)
CHUNK_ROWS = 256
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
    return list(_pool(threads).map(lambda ab: fn(*ab), chunks))


def _pool(threads: int) -> ThreadPoolExecutor:
    if not _POOL or _POOL[0]._max_workers < threads:  # grow the pool when asked for more
        _POOL[:] = [ThreadPoolExecutor(max_workers=max(threads, os.cpu_count() or 1), thread_name_prefix="alloc-batch")]
    return _POOL[0]


def run_chunks(make_worker: Callable[[], Callable[[int, int], None]], n_rows: int, threads: int,
               chunk: int | None = None) -> None:
    """Run ``range(n_rows)`` in chunks of ``chunk`` rows (default :data:`CHUNK_ROWS`) on
    ``threads`` threads, the caller's included.  A thread that gets a chunk calls
    ``make_worker()`` once (its private context, e.g. a copy of a solver's state; a pool thread
    that starts after the rows are gone makes none) and then the returned ``work(a, b)`` on the
    chunks it pulls, in any order: ``work`` must write rows ``a:b`` of a shared output and give
    the same rows whichever thread runs them.  The caller works too, so a pool busy with another
    batch delays nothing.  An exception in any thread is raised here after every thread has
    stopped."""
    if threads <= 1 or n_rows <= 0:
        make_worker()(0, n_rows)
        return
    size = max(1, int(chunk or CHUNK_ROWS))
    lock = threading.Lock()
    nxt = [0]

    def loop() -> None:
        work = None
        while True:
            with lock:
                a = nxt[0]
                nxt[0] = a + size
            if a >= n_rows:
                return
            if work is None:
                work = make_worker()
            work(a, min(n_rows, a + size))

    futures = [_pool(threads).submit(loop) for _ in range(threads - 1)]
    try:
        loop()
    finally:
        errors = [f.exception() for f in futures]  # waits for each
    for e in errors:
        if e is not None:
            raise e
