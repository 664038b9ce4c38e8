"""Loading the numba kernels before the requests that need them (``ALLOC_WARMUP``).

Every registered method is built and called once on a small problem (a demand, a
rate-limited demand, a batch), so its kernels are loaded from the on-disk cache (or
compiled, where the cache is cold) before a user's call would.  The service process does
it on a background thread once it serves (:func:`start_background_warm_up`): start-up is
the HTTP layer and the database, and a request that comes before its method is warm loads
that method's kernels itself (from the cache: milliseconds to tenths of a second, never a
compile of the whole set).  The build processes do it in their initializer, before their
first job (:mod:`service.builds`).

A module of its own so that the application (:mod:`service.main`) and the build processes
(:mod:`service.builds`) both import it and neither imports the other.
"""

from __future__ import annotations

import gc
import logging
import threading
import time
from collections.abc import Callable

import numpy as np

import alloc

__all__ = ["warm_up", "is_warm", "start_background_warm_up"]

_log = logging.getLogger("service")
_lock = threading.Lock()
_warm: set[str] = set()


def _warm_one(name: str, problem: alloc.Problem, v: np.ndarray) -> None:
    try:
        options = {"resolution": 8} if "resolution" in alloc.method_info(name)["options"] else {}
        allocator = alloc.make_allocator(problem, name, **options)
    except alloc.AllocError:
        return  # a method that needs options this problem cannot give (none today)
    allocator(v)
    allocator(v, u_prev=np.zeros(problem.m), dt=0.01)
    allocator.batch(np.stack([v, -v]))


def warm_up(stop: threading.Event | None = None) -> float:
    """Build and call every registered method once on a small problem (and a batch), so the
    numba kernels are compiled (or loaded from their on-disk cache) before a user's call.
    The default method first.  Returns the seconds spent; a method already warm in this
    process is skipped, and ``stop`` (when set) ends the work between two methods."""
    t0 = time.perf_counter()
    B = np.array([[1.0, -1.0, 0.5, 0.2], [0.3, 0.4, -1.0, 0.8], [0.2, 0.1, 0.3, -1.0]])
    problem = alloc.Problem(B, [-1.0] * 4, [1.0] * 4, rate_min=[-5.0] * 4, rate_max=[5.0] * 4)
    v = np.array([0.3, -0.2, 0.1])
    default = alloc.registry.DEFAULT_METHOD
    for name in sorted(alloc.methods(), key=lambda n: n != default):
        if stop is not None and stop.is_set():
            break
        with _lock:  # two threads warming at once would do the same work twice
            if name in _warm:
                continue
            _warm_one(name, problem, v)
            _warm.add(name)
    return time.perf_counter() - t0


def is_warm() -> bool:
    """Whether every registered method has been warmed in this process."""
    return _warm >= set(alloc.methods())


def start_background_warm_up(stop: threading.Event, then: Callable[[], None] | None = None) -> threading.Thread:
    """:func:`warm_up` on a daemon thread, then ``then()`` (unless ``stop`` was set first).

    What the warm-up allocated is moved out of the collector's reach afterwards (``gc.freeze``,
    as the start-up does for its own objects), so full collections keep scanning only
    per-request garbage."""
    def run() -> None:
        try:
            seconds = warm_up(stop)
            _log.info("numba kernels warmed in %.2f s", seconds)
            if then is not None and not stop.is_set():
                then()
            gc.collect()
            gc.freeze()
        except Exception:  # noqa: BLE001 - a warm-up failure leaves each request to load its own kernels
            _log.exception("kernel warm-up failed; requests load their kernels on first use")

    # The thread imports numba and the methods while the server binds its socket.  A codec
    # looked up while another thread holds the import lock can fail (CPython bpo-29288): the
    # server's getaddrinfo then raised "LookupError: unknown encoding: idna" and the process
    # exited, in 1 of about 40 starts.  Using the codec once here caches it before the race.
    "localhost".encode("idna")
    thread = threading.Thread(target=run, name="alloc-warm-up", daemon=True)
    thread.start()
    return thread
