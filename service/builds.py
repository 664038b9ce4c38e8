"""Allocator builds off the event loop: a low-priority build process, and threads for cheap builds.

Why a process.  Measured with ``benchmarks/bench_service.py``'s option flood on the shared
2-core machine (2026-11-30, load 5-8; server ``Server-Timing`` phases): while ``da_table``
builds ran on a thread of the service process, an event's commit on the writer thread took
p50 30-53 ms instead of 4-23 ms and waited up to 55 ms for the GIL before it started; the
event's p99 was 140-414 ms.  A build thread cannot be given a lower priority (the GIL
holder would then stall everybody), a build process can: it holds no lock the service
needs and runs at niceness +:data:`BUILD_NICE` under ``SCHED_IDLE`` (Linux), so the kernel
gives the event's threads the CPU first.

Three lanes, each bounded in concurrency and queue (429 beyond), each served by priority
(:data:`REBUILD` before :data:`REQUEST`):

* ``process``: builds predicted costly (:func:`service.cost.is_costly`: facet enumerations,
  direction tables), batches predicted costly (:func:`service.cost.is_costly_batch`), and
  other bounded work (AMS summaries), in ``ALLOC_BUILD_WORKERS`` spawned processes.  A
  costly rebuild after an event waits for no queued request, only for the job running
  (at most ``ALLOC_BUILD_BUDGET_S`` or ``ALLOC_BATCH_BUDGET_S``, both priced before they start);
* ``thread``: every other build for a request (an SVD or a QP set-up of at most 6 x 64:
  milliseconds) and cheap batches, 2 threads of the service process;
* ``rebuild``: the cheap rebuilds after an event, 2 threads that no request can use, so
  the allocators an event invalidated are rebuilt however busy the other lanes are.

The build processes are started with the service, in the background (a few seconds:
imports, and the numba kernels loaded from their cache), and stop with the allocator pool
(terminated, not waited for) or with the service process.

An allocator comes back from the build process only when it is small enough to be worth
keeping (at most :data:`TRANSFER_BYTES`, and what the cache would keep for its key):
unpickling a ``da_facet`` allocator of k = 6, m = 20 (31,055 arrays, 75 MB) held the
service's GIL for 234-350 ms.  A larger one answers the request's demand (or batch) in
the build process and only the result comes back.
"""

from __future__ import annotations

import asyncio
import heapq
import itertools
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

from .cost import answer_bytes, batch_seconds, build_seconds, call_seconds, estimate_bytes
from .responses import batch_json
from .errors import InvalidRequest, ServiceUnavailable, TooManyRequests, field_error
from .warm import warm_up

__all__ = ["Builder", "Built", "Call", "build", "build_allocator", "check_build_cost", "check_batch_cost", "BUILD_NICE",
           "TRANSFER_BYTES", "REBUILD", "REQUEST"]

_log = logging.getLogger("service")
#: niceness added to the build processes (over the service's own)
BUILD_NICE = 10
#: largest allocator (estimate_bytes) sent back from a build process (~25 ms to unpickle)
TRANSFER_BYTES = 4 * 1024 * 1024


def _reject(field_name: str, reason: str) -> InvalidRequest:
    return InvalidRequest(f"{field_name}: {reason}", [field_error(field_name, reason)])


def check_build_cost(problem: alloc.Problem, method: str, options: dict[str, Any], budget: float) -> float:
    """Refuse, before it starts, a build predicted to exceed ``budget`` seconds; return the prediction.

    Per-call option caps (:attr:`alloc.options.Option.call_cap`, declared by the method:
    iterations a single allocation may run) are checked too.  The prediction is
    :func:`service.cost.build_seconds`.
    """
    specs = alloc.registry.get_method(method).options if method in alloc.methods() else {}
    for name, value in options.items():
        cap = specs[name].call_cap if name in specs else None
        if cap is not None and isinstance(value, (int, float)) and not isinstance(value, bool) and value > cap:
            raise _reject(f"options/{name}", f"{method}: option {name} = {value} exceeds the service's cap of {cap}")
    if method not in alloc.methods():
        return 0.0  # the library names the unknown method
    seconds = build_seconds(problem, method, options)
    if seconds <= budget:
        return seconds
    cls = alloc.registry.get_method(method)
    subsets = cls.facet_subsets(problem, dict(options)) if cls.needs_ams else 0
    facet_part = cls.enumeration_cost(problem, dict(options))[0] if hasattr(cls, "enumeration_cost") else 0.0
    cost = (f"{method}: predicted build time {seconds:.3g} s exceeds the service's build budget of {budget:g} s "
            f"(cap; {subsets:,} facet subsets C(m_free, k-1): {facet_part:.3g} s")
    if seconds > facet_part * 1.0001 and "resolution" in cls.options:
        res = options.get("resolution", 64)
        raise _reject("options/resolution", f"{cost}, plus a {res} x {2 * res} direction table); "
                                            f"use a smaller resolution or 'da_facet'")
    raise _reject("method", f"{cost}); use 'da' (the same allocation as an LP)")


def check_batch_cost(problem: alloc.Problem, method: str, options: dict[str, Any], rows: int, budget: float,
                     max_answer: int) -> float:
    """Refuse, before it starts, a batch predicted to take over ``budget`` seconds (its build
    plus ``rows`` calls at the method's declared per-call cost) or to answer more than
    ``max_answer`` bytes; return the predicted seconds."""
    seconds = check_build_cost(problem, method, options, budget)
    if method not in alloc.methods():
        return seconds
    per_call = call_seconds(problem, method, options)
    seconds = batch_seconds(problem, method, options, rows)
    if seconds > budget:
        fits = max(0, int((budget - (seconds - rows * per_call)) / per_call))
        raise _reject("V", f"{method}: predicted batch time {seconds:.3g} s ({rows:,} rows x {per_call * 1e3:.3g} ms, "
                           f"the method's declared worst-case call at m = {problem.m}, k = {problem.k}) exceeds the "
                           f"service's batch budget of {budget:g} s (ALLOC_BATCH_BUDGET_S); send at most {fits:,} "
                           f"rows per request")
    size = answer_bytes(problem, rows)
    if size > max_answer:
        fits = max(0, int(rows * (max_answer - 1024) / (size - 1024)))
        raise _reject("V", f"predicted answer of {size:,} bytes for {rows:,} rows at m = {problem.m} exceeds the "
                           f"service's answer limit of {max_answer:,} bytes (ALLOC_MAX_ANSWER_BYTES); send at most "
                           f"{fits:,} rows per request")
    return seconds


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
    """What a request wants of an allocator: one demand, or a batch (``V``, answered as the
    JSON bytes of its :class:`~service.schemas.BatchOut` with the fields ``extra``)."""

    v: np.ndarray | None = None
    u_prev: np.ndarray | None = None
    dt: float | None = None
    V: np.ndarray | None = None
    extra: dict[str, Any] = field(default_factory=dict)
    token: str = field(default_factory=lambda: uuid.uuid4().hex)

    def run(self, allocator: alloc.Allocator) -> Any:
        if self.V is not None:
            # serialised where it ran: a 16 MB answer built on the event loop stalled it
            return batch_json(allocator.batch(self.V), **self.extra)
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
    warm_up()  # at normal priority: a process starved in its initializer is of no use and cannot be stopped
    os.nice(nice)
    try:  # run only when the service's threads do not want the CPU (Linux; lowering needs no privilege)
        os.sched_setscheduler(0, os.SCHED_IDLE, os.sched_param(0))
    except (AttributeError, OSError):
        pass  # niceness alone


#: priorities of work in a lane's queue, most urgent first: the rebuild after an event is
#: authenticated work that every allocation of the vehicle waits for; everything else is not
REBUILD, REQUEST = 0, 1


class _Lane:
    """One bounded pool (threads or processes) with a bounded queue, served by priority.

    At most ``workers`` jobs are handed to the pool at a time; the rest wait here in a heap
    (priority, arrival), so a :data:`REBUILD` job starts before every :data:`REQUEST` job
    queued ahead of it, as soon as a worker is free (a running job is not interrupted).
    """

    def __init__(self, name: str, kind: str, workers: int, queue: int) -> None:
        self.name, self.kind, self.workers, self.limit = name, kind, workers, workers + queue
        self.pool: ThreadPoolExecutor | ProcessPoolExecutor | None = None
        self.inflight = 0  # queued here + handed to the pool
        self.running = 0  # handed to the pool
        self._waiting: list[tuple[int, int, Future[Any], Callable[..., Any], tuple[Any, ...]]] = []
        self._arrivals = itertools.count()

    def executor(self) -> ThreadPoolExecutor | ProcessPoolExecutor:
        if self.pool is None:
            if self.kind == "process":
                self.pool = ProcessPoolExecutor(self.workers, mp_context=get_context("spawn"),
                                                initializer=_init_build_process,
                                                initargs=(os.getpid(), BUILD_NICE))
            else:
                self.pool = ThreadPoolExecutor(self.workers, thread_name_prefix=f"alloc-{self.name}")
        return self.pool

    def enqueue(self, priority: int, fn: Callable[..., Any], args: tuple[Any, ...]) -> Future[Any]:
        """Queue ``fn(*args)`` (the caller holds the builder's lock); its future resolves with the job."""
        outer: Future[Any] = Future()
        heapq.heappush(self._waiting, (priority, next(self._arrivals), outer, fn, args))
        self.inflight += 1
        return outer

    def dispatch(self, lock: Any) -> None:
        """Hand waiting jobs to free workers, most urgent first (the caller holds ``lock``)."""
        while self._waiting and self.running < self.workers:
            _, _, outer, fn, args = heapq.heappop(self._waiting)
            if not outer.set_running_or_notify_cancel():
                self.inflight -= 1
                continue
            try:
                inner = self.executor().submit(fn, *args)
            except BrokenProcessPool:  # a build process died (killed, out of memory): start new ones
                self.pool = None
                inner = self.executor().submit(fn, *args)
            self.running += 1

            def finished(done: Future[Any], outer: Future[Any] = outer) -> None:
                with lock:
                    self.running -= 1
                    self.inflight -= 1
                    self.dispatch(lock)
                if done.cancelled():
                    outer.set_exception(BrokenProcessPool("the pool stopped before the job ran"))
                elif (exc := done.exception()) is not None:
                    outer.set_exception(exc)
                else:
                    outer.set_result(done.result())
            inner.add_done_callback(finished)

    def drop_waiting(self) -> None:
        """Cancel the queued jobs (shutdown)."""
        for _, _, outer, _, _ in self._waiting:
            if outer.cancel():
                self.inflight -= 1
        self._waiting.clear()


class Builder:
    """The lanes (module docstring), single-flight per key.

    ``rebuild``: 2 threads that only the rebuilds after an event use (cheap ones), so no
    request can queue ahead of them; ``thread``: cheap builds and cheap batches for requests;
    ``process``: costly builds (a costly rebuild first), costly batches, AMS summaries.
    """

    def __init__(self, processes: int, queue: int) -> None:
        self._lanes = {"process": _Lane("process", "process", processes, queue),
                       "thread": _Lane("thread", "thread", 2, 64),
                       "rebuild": _Lane("rebuild", "thread", 2, 64)}
        self._inflight: dict[Hashable, Future[Any]] = {}
        self._lock = threading.RLock()  # a job done at once runs its callbacks under it

    def submit(self, key: Hashable, lane_name: str, fn: Callable[..., Any], *args: Any,
               then: Callable[[Future[Any]], None] | None = None, priority: int = REQUEST) -> Future[Any]:
        """``fn(*args)`` on lane ``"process"`` (``fn`` and ``args`` picklable), ``"thread"`` or
        ``"rebuild"``; a second submit of a ``key`` in flight gets the first one's future.
        ``then(future)`` runs once when it is done (only for the submit that started it)."""
        lane = self._lanes[lane_name]
        with self._lock:
            fut = self._inflight.get(key)
            if fut is not None:
                return fut
            if lane.inflight >= lane.limit:
                raise TooManyRequests(f"the service is running {lane.inflight} jobs in its {lane.name} lane "
                                      f"(the most it queues); retry shortly")
            fut = lane.enqueue(priority, fn, args)
            self._inflight[key] = fut

        def done(finished: Future[Any]) -> None:
            if then is not None:
                then(finished)
            with self._lock:
                self._inflight.pop(key, None)
        fut.add_done_callback(done)
        with self._lock:
            lane.dispatch(self._lock)
        return fut

    def start_processes(self) -> list[Future[int]]:
        """Start the build processes now (they warm up in the background, seconds under load),
        so the first costly build or batch does not wait for them; the futures resolve once
        they have (each to a build process's pid)."""
        with self._lock:
            lane = self._lanes["process"]
            pool = lane.executor()
        return [pool.submit(os.getpid) for _ in range(lane.workers)]

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
                lane.drop_waiting()
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
