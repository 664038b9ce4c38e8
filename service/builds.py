"""Allocator builds off the event loop: a low-priority build process, and threads for cheap builds.

Why a process.  Measured with ``benchmarks/bench_service.py``'s option flood on the shared
2-core machine (2026-11-30, load 5-8; server ``Server-Timing`` phases): while ``da_table``
builds ran on a thread of the service process, an event's commit on the writer thread took
p50 30-53 ms instead of 4-23 ms and waited up to 55 ms for the GIL before it started; the
event's p99 was 140-414 ms.  A build thread cannot be given a lower priority (the GIL
holder would then stall everybody), a build process can: it holds no lock the service
needs and runs at niceness +:data:`BUILD_NICE` under ``SCHED_IDLE`` (Linux), so the kernel
gives the event's threads the CPU first.

Two lanes, each bounded in concurrency and queue (429 beyond):

* ``process``: builds predicted costly (:func:`service.cost.is_costly`:
  facet enumerations, direction tables) and other bounded work (AMS summaries), in
  ``ALLOC_BUILD_WORKERS`` spawned processes;
* ``thread``: every other build (an SVD or a QP set-up of at most 6 x 64: milliseconds),
  2 threads of the service process.

The build processes start with the first costly build (a few seconds: imports, and the
numba kernels the service compiled at its start-up, loaded from numba's cache) and stop
with the store (terminated, not waited for) or with the service process.

An allocator comes back from the build process only when it is small enough to be worth
keeping (at most :data:`TRANSFER_BYTES`, and what the cache would keep for its key):
unpickling a ``da_facet`` allocator of k = 6, m = 20 (31,055 arrays, 75 MB) held the
service's GIL for 234-350 ms.  A larger one answers the request's demand (or batch) in
the build process and only the result comes back.
"""

from __future__ import annotations

import asyncio
import logging
import os
import pickle
import threading
import time
import uuid
from collections.abc import Callable, Hashable
from concurrent.futures import Future, ProcessPoolExecutor, ThreadPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, field
from multiprocessing import get_context
from typing import Any

import numpy as np

import alloc

from .config import OPTION_CAPS
from .cost import FACET_SECONDS, build_seconds, estimate_bytes
from .errors import InvalidRequest, ServiceUnavailable, TooManyRequests, field_error

__all__ = ["Builder", "Built", "Call", "build", "build_allocator", "check_build_cost", "BUILD_NICE",
           "TRANSFER_BYTES"]

_log = logging.getLogger("service")
#: niceness added to the build processes (over the service's own)
BUILD_NICE = 10
#: largest allocator (estimate_bytes) sent back from a build process (~25 ms to unpickle)
TRANSFER_BYTES = 4 * 1024 * 1024


def _reject(field_name: str, reason: str) -> InvalidRequest:
    return InvalidRequest(f"{field_name}: {reason}", [field_error(field_name, reason)])


def check_build_cost(problem: alloc.Problem, method: str, options: dict[str, Any], budget: float) -> float:
    """Refuse, before it starts, a build predicted to exceed ``budget`` seconds; return the prediction.

    Per-call option caps (``OPTION_CAPS``: iterations a single allocation may run) are
    checked too.  The prediction is :func:`service.cost.build_seconds`.
    """
    for name, value in options.items():
        cap = OPTION_CAPS.get((method, name))
        if cap is not None and isinstance(value, (int, float)) and not isinstance(value, bool) and value > cap:
            raise _reject(f"options/{name}", f"{method}: option {name} = {value} exceeds the service's cap of {cap}")
    if method not in alloc.methods():
        return 0.0  # the library names the unknown method
    seconds = build_seconds(problem, method, options)
    if seconds <= budget:
        return seconds
    cls = alloc.registry.get_method(method)
    subsets = cls.facet_subsets(problem, dict(options)) if cls.needs_ams else 0
    facet_part = FACET_SECONDS * subsets
    cost = (f"{method}: predicted build time {seconds:.3g} s exceeds the service's build budget of {budget:g} s "
            f"(cap; {subsets:,} facet subsets C(m_free, k-1) x {FACET_SECONDS * 1e6:g} us")
    if seconds > facet_part * 1.0001 and "resolution" in cls.options:
        res = options.get("resolution", 64)
        raise _reject("options/resolution", f"{cost}, plus a {res} x {2 * res} direction table); "
                                            f"use a smaller resolution or 'da_facet'")
    raise _reject("method", f"{cost}); use 'da' (the same allocation as an LP)")


def build_allocator(problem: alloc.Problem, method: str, options: dict[str, Any], budget: float) -> alloc.Allocator:
    """``alloc.make_allocator`` after the cost check, with bad option *values* reported as 422.

    Library errors keep their field (``exc.field``, mapped by the handler); a method
    constructor given an option of the wrong shape or type that raises a plain
    ``ValueError``/``TypeError`` from numpy is reported against ``options``.
    """
    check_build_cost(problem, method, options, budget)
    try:
        return alloc.make_allocator(problem, method, **options)
    except alloc.AllocError as exc:
        if exc.field in options:  # an option value the method rejected, e.g. "G: expected shape"
            raise _reject(f"options/{exc.field}", str(exc)) from exc
        raise
    except (ValueError, TypeError, ArithmeticError, IndexError, KeyError, np.linalg.LinAlgError) as exc:
        raise _reject("options", f"{method}: invalid option value ({type(exc).__name__}: {exc})") from exc


@dataclass(frozen=True)
class Call:
    """What a request wants of an allocator: one demand, or a batch (``V``)."""

    v: np.ndarray | None = None
    u_prev: np.ndarray | None = None
    dt: float | None = None
    V: np.ndarray | None = None
    token: str = field(default_factory=lambda: uuid.uuid4().hex)

    def run(self, allocator: alloc.Allocator) -> Any:
        if self.V is not None:
            return allocator.batch(self.V)
        return allocator(self.v, u_prev=self.u_prev, dt=self.dt)


@dataclass(frozen=True)
class Built:
    """A build's outcome: the allocator (to cache and call), or only the answer to ``token``'s call."""

    allocator: alloc.Allocator | None
    nbytes: int
    token: str | None = None
    result: Any = None


def build(problem: alloc.Problem, method: str, options: dict[str, Any], budget: float, keep_bytes: int,
          call: Call | None) -> Built:
    """Build; return the allocator if it is at most ``keep_bytes``, else only ``call``'s answer.

    A batch is always answered here (off the event loop), its allocator not returned.
    """
    t0 = time.perf_counter()
    allocator = build_allocator(problem, method, options, budget)
    seconds = time.perf_counter() - t0
    if seconds > budget:
        _log.warning("build of %s took %.2f s, over the budget of %.2f s (cost model under-predicted)",
                     method, seconds, budget)
    nbytes = estimate_bytes(allocator)
    if _in_build_process and nbytes <= keep_bytes and not _picklable(allocator):
        keep_bytes = -1  # it cannot come back to the service: answer here
    if call is not None and (call.V is not None or nbytes > keep_bytes):
        return Built(None, nbytes, call.token, call.run(allocator))
    return Built(allocator if nbytes <= keep_bytes else None, nbytes)


def _picklable(allocator: alloc.Allocator) -> bool:
    try:
        pickle.dumps(allocator)  # the methods with a build cost today all pickle (checked by the tests)
    except (pickle.PicklingError, TypeError, AttributeError):
        return False
    return True


def _exit_with_parent(parent: int) -> None:
    """Exit this build process once the service process is gone (even killed with SIGKILL)."""
    while os.getppid() == parent:
        time.sleep(0.5)
    os._exit(0)


_in_build_process = False


def _init_build_process(parent: int, nice: int) -> None:
    """Build process start-up: lower priority, numba kernels loaded before the first build."""
    global _in_build_process
    _in_build_process = True
    threading.Thread(target=_exit_with_parent, args=(parent,), daemon=True, name="alloc-parent").start()
    from .main import warm_up
    warm_up()  # at normal priority: a process starved in its initializer is of no use and cannot be stopped
    os.nice(nice)
    try:  # run only when the service's threads do not want the CPU (Linux; lowering needs no privilege)
        os.sched_setscheduler(0, os.SCHED_IDLE, os.sched_param(0))
    except (AttributeError, OSError):
        pass  # niceness alone


class _Lane:
    """One bounded pool (threads or processes) with a bounded queue."""

    def __init__(self, name: str, workers: int, queue: int) -> None:
        self.name, self.workers, self.limit = name, workers, workers + queue
        self.pool: ThreadPoolExecutor | ProcessPoolExecutor | None = None
        self.inflight = 0

    def executor(self) -> ThreadPoolExecutor | ProcessPoolExecutor:
        if self.pool is None:
            if self.name == "process":
                self.pool = ProcessPoolExecutor(self.workers, mp_context=get_context("spawn"),
                                                initializer=_init_build_process,
                                                initargs=(os.getpid(), BUILD_NICE))
            else:
                self.pool = ThreadPoolExecutor(self.workers, thread_name_prefix=f"alloc-{self.name}")
        return self.pool


class Builder:
    """The two lanes (module docstring), single-flight per key."""

    def __init__(self, processes: int, queue: int) -> None:
        self._lanes = {"process": _Lane("process", processes, queue), "thread": _Lane("thread", 2, 64)}
        self._inflight: dict[Hashable, Future[Any]] = {}
        self._lock = threading.Lock()

    def submit(self, key: Hashable, lane_name: str, fn: Callable[..., Any], *args: Any,
               then: Callable[[Future[Any]], None] | None = None) -> Future[Any]:
        """``fn(*args)`` on lane ``"process"`` (``fn`` and ``args`` picklable) or ``"thread"``;
        a second submit of a ``key`` in flight gets the first one's future.  ``then(future)``
        runs once when it is done (only for the submit that started it)."""
        lane = self._lanes[lane_name]
        with self._lock:
            fut = self._inflight.get(key)
            if fut is not None:
                return fut
            if lane.inflight >= lane.limit:
                raise TooManyRequests(f"the service is running {lane.inflight} builds in its {lane.name} lane "
                                      f"(the most it queues); retry shortly")
            try:
                fut = lane.executor().submit(fn, *args)
            except BrokenProcessPool:  # a build process died (killed, out of memory): start new ones
                lane.pool = None
                fut = lane.executor().submit(fn, *args)
            self._inflight[key] = fut
            lane.inflight += 1

        def done(finished: Future[Any]) -> None:
            if then is not None:
                then(finished)
            with self._lock:
                self._inflight.pop(key, None)
                lane.inflight -= 1
        fut.add_done_callback(done)
        return fut

    @staticmethod
    async def outcome(fut: Future[Any]) -> Any:
        """The future's result, awaited; a build process that died is reported as 503."""
        try:
            return await asyncio.wrap_future(fut)
        except BrokenProcessPool as exc:
            raise ServiceUnavailable("the build process stopped during this build; retry") from exc

    def wait_idle(self, timeout: float) -> bool:
        """Wait until no build is queued or running (tests, benchmarks); ``False`` on timeout."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            with self._lock:
                if not self._inflight:
                    return True
            time.sleep(0.005)
        return False

    def shutdown(self) -> None:
        """Stop the pools (queued builds are cancelled); a later submit starts new ones."""
        with self._lock:
            pools = [lane.pool for lane in self._lanes.values()]
            for lane in self._lanes.values():
                lane.pool = None
        for pool in pools:
            if pool is None:
                continue
            # a build process still in its initializer (warming kernels at idle priority on a busy
            # machine) never reads the shutdown sentinel: stop the processes, do not wait for them
            processes = list((getattr(pool, "_processes", None) or {}).values())
            pool.shutdown(wait=False, cancel_futures=True)
            for proc in processes:
                proc.terminate()
            for proc in processes:
                proc.join(timeout=2.0)
