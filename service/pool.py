"""The allocators of this process: cached, built, priced and rebuilt after events.

An allocation is one hand-off: the route gives the pool its vehicle id and validated body
(:meth:`AllocatorPool.allocate`); the pool reads the vehicle's committed state from the
repository (:meth:`service.store.VehicleStore.get`, its version from the database now),
applies the vehicle's method defaults under the request's options, and answers from the
allocator cached under ``(vehicle, health_version, method, options)``, built if missing; at a
scheduled vehicle's ``at``, under the same key and the variables' values, one such per vehicle,
method and options (:meth:`AllocatorPool._forget_other_at`).

Allocators are cached in a :class:`~service.allocator_cache.AllocatorCache` bounded in
entries and in bytes (measured by :func:`service.cost.estimate_bytes`); inline problems
share a smaller byte budget and an allocator larger than
:data:`~service.allocator_cache.INLINE_ENTRY_BYTES` built for an inline problem is used
once and not kept.  Builds run on :class:`service.builds.Builder` (costly ones in a
low-priority build process, cheap ones on threads, both bounded in concurrency and queue)
after :func:`~service.builds.check_build_cost` refused anything predicted to exceed the
build budget (see :mod:`service.cost`).

Batches are priced before they start (rows x the method's declared per-call cost, and
the size of their answer: :func:`~service.builds.check_batch_cost`), their answer bytes
reserved in :class:`~service.responses.AnswerBudget`, run and serialised off the event
loop, and streamed.  AMS summaries run in the build process, bounded like a build.

After an event this process committed, the repository tells the pool the new state
(:meth:`service.store.VehicleStore.subscribe`) and the pool submits the rebuilds of the
allocators that were in use for the old health (at most :data:`PREBUILD_LIMIT`, that
vehicle only, on the builder's ``rebuild`` lane, which no request can use, or first in
the build process's queue) without waiting for them; the next allocation finds its
rebuild in flight (other processes rebuild lazily on their next request, keyed by the
new version).  A vehicle found gone has its allocators dropped.
"""

from __future__ import annotations

import json
import uuid
from collections.abc import Callable, Hashable
from concurrent.futures import Future
from typing import Any

import numpy as np
from fastapi import Response

import alloc

from . import ams
from .allocator_cache import AllocatorCache
from .builds import (
    REBUILD,
    REQUEST,
    TRANSFER_BYTES,
    Builder,
    Built,
    Call,
    build,
    check_batch_cost,
    check_build_cost,
)
from .cost import answer_bytes, is_costly, is_costly_batch
from .errors import ServiceError
from .responses import AnswerBudget, StreamedAnswer, allocation_response
from .schedule import Schedules, at_values, problem_at_values
from .schemas import (
    AllocateRequest,
    AmsOut,
    AmsRequest,
    AmsVehicleRequest,
    BatchAllocateRequest,
    ProblemIn,
    VehicleAllocateRequest,
    VehicleBatchRequest,
)
from .store import VehicleStore
from .vehicle_state import VehicleState

__all__ = ["PREBUILD_LIMIT", "AllocatorPool", "options_key"]

#: allocators rebuilt after an event, per vehicle (the most recently used ones)
PREBUILD_LIMIT = 4

_PROBLEM_FIELDS = set(ProblemIn.model_fields)


def options_key(options: dict[str, Any]) -> str:
    return json.dumps(options, sort_keys=True, separators=(",", ":"))


def _demand_rows(V: Any, k: int) -> np.ndarray:
    """A batch's demands as an N x k array, or the library's error naming ``V`` (a ragged or
    mis-shaped batch is the caller's error, found before it is priced)."""
    try:
        rows = np.asarray(V, dtype=float)
    except ValueError as exc:
        raise alloc.DemandError(f"V: not a numeric array of consistent shape ({exc})", field="V") from exc
    if rows.ndim != 2 or rows.shape[1] != k:
        raise alloc.DemandError(f"V: expected shape (N, {k}), got {rows.shape}", field="V")
    return rows


def _options(state: VehicleState, method: str, options: dict[str, Any]) -> dict[str, Any]:
    """The request's options over the vehicle document's defaults for ``method``."""
    return {**state.defaults.get(method, {}), **options}


class AllocatorPool:
    """Allocations, batches and AMS summaries, for stored vehicles (read from ``store``) and inline problems."""

    def __init__(self, store: VehicleStore, *, cache_size: int, cache_bytes: int, inline_cache_bytes: int,
                 build_budget: float, build_workers: int, build_queue: int, batch_budget: float = 2.0,
                 max_answer_bytes: int = 16 * 1024 * 1024, answer_bytes_in_flight: int = 96 * 1024 * 1024) -> None:
        self._store = store
        self.allocators = AllocatorCache(cache_size, cache_bytes, inline_cache_bytes)
        self.builder = Builder(build_workers, build_queue)
        self.build_budget = build_budget
        self.batch_budget, self.max_answer_bytes = batch_budget, max_answer_bytes
        self.answers = AnswerBudget(answer_bytes_in_flight)
        self.schedules = Schedules(store.document)
        store.subscribe(self._vehicle_changed)

    def close(self) -> None:
        self.builder.shutdown()

    # ------------------------------------------------------------ requests
    async def allocate(self, vehicle_id: str, body: VehicleAllocateRequest) -> Response:
        """One demand at the vehicle's current health (and its schedule's ``at``: :meth:`_forget_other_at`)."""
        state = self._store.get(vehicle_id)
        options = _options(state, body.method, body.options)
        call = Call(body.v, body.u_prev, body.dt)
        key: tuple[Any, ...] = (state.id, state.version, body.method, options_key(options))
        evaluator, values = self._at(state, body.at)
        if values is not None:
            key = (*key, values)
            if self.allocators.lookup(key) is None:
                self._forget_other_at(key)
        result = await self._answer(key, lambda: problem_at_values(state, evaluator, values), body.method, options,
                                    call)
        return allocation_response(result, vehicle_id=state.id, health_version=state.version)

    async def allocate_batch(self, vehicle_id: str, body: VehicleBatchRequest) -> StreamedAnswer:
        """Many demands at the vehicle's current health and ``at`` (:meth:`_batch`)."""
        state = self._store.get(vehicle_id)
        evaluator, values = self._at(state, body.at)
        return await self._batch(problem_at_values(state, evaluator, values), body.method,
                                 _options(state, body.method, body.options), body.V,
                                 {"vehicle_id": state.id, "health_version": state.version})

    async def allocate_inline(self, body: AllocateRequest) -> Response:
        """One demand for an inline problem (its JSON identifies it in the cache)."""
        key = ("inline", body.model_dump_json(include=_PROBLEM_FIELDS), body.method, options_key(body.options))
        result = await self._answer(key, body.to_problem, body.method, body.options,
                                    Call(body.v, body.u_prev, body.dt))
        return allocation_response(result)

    async def allocate_inline_batch(self, body: BatchAllocateRequest) -> StreamedAnswer:
        """Many demands for an inline problem (:meth:`_batch`)."""
        return await self._batch(body.to_problem(), body.method, body.options, body.V, {})

    async def ams_summary(self, body: AmsRequest) -> AmsOut:
        """AMS summary of an inline problem, in the build process (a facet enumeration is a build)."""
        return await self._run_bounded(ams.summarize, body.to_problem(), body.directions, self.build_budget)

    async def vehicle_ams_summary(self, vehicle_id: str, body: AmsVehicleRequest) -> AmsOut:
        """AMS summary at the vehicle's current health."""
        state = self._store.get(vehicle_id)
        out = await self._run_bounded(ams.summarize, state.problem, body.directions, self.build_budget)
        return out.model_copy(update={"vehicle_id": state.id, "health_version": state.version})

    # --------------------------------------------------------- after events
    def _vehicle_changed(self, vehicle_id: str, state: VehicleState | None) -> None:
        """The repository's news: a new health (rebuild) or the vehicle gone (drop its allocators)."""
        if state is None:
            self.allocators.drop(self.allocators.keys_where(lambda k: k[0] == vehicle_id))
            self.schedules.forget(vehicle_id)
        else:
            self.rebuild_after_event(state)

    def rebuild_after_event(self, new: VehicleState) -> int:
        """Rebuild (on the build pool) the allocators that were in use for an older version of
        this vehicle, at most :data:`PREBUILD_LIMIT`, most recent first; drop the stale ones.
        Returns how many builds were started."""
        stale = self.allocators.keys_where(lambda k: k[0] == new.id and k[1] < new.version)
        started = 0
        seen: set[tuple[str, str]] = set()
        for key in reversed(stale):
            if not isinstance(key, tuple) or len(key) != 4:
                continue  # an allocator at a request's `at`: the next request at that `at` builds it
            _, _, method, okey = key
            if (method, okey) in seen or started >= PREBUILD_LIMIT:
                continue
            seen.add((method, okey))
            options = json.loads(okey)
            key = (new.id, new.version, method, okey)
            try:
                seconds = check_build_cost(new.problem, method, options, self.build_budget)
                self._start_build(key, new.problem, method, options, None, seconds, rebuild=True)
                started += 1
            except ServiceError:
                continue  # refused or the pools are full: the next request builds it (or reports why)
        self.allocators.drop(stale)
        return started

    # -------------------------------------------------------------- builds
    def _start_build(self, key: Hashable, problem: alloc.Problem, method: str, options: dict[str, Any],
                     call: Call | None, seconds: float, *, rebuild: bool = False) -> Future[Built]:
        """Submit a build (a costly one to the build process, a cheap one to a thread; a cheap
        rebuild after an event to the rebuild threads); the allocator it returns is cached under
        ``key``.  A batch's ``seconds`` include its calls (:func:`service.cost.batch_seconds`)."""
        costly = is_costly_batch(seconds) if call is not None and call.V is not None else is_costly(seconds)
        lane = "process" if costly else "rebuild" if rebuild else "thread"
        keep = self.allocators.keep_limit(key)
        if lane == "process":
            keep = min(keep, TRANSFER_BYTES)

        def cache(fut: Future[Built]) -> None:
            if not fut.cancelled() and fut.exception() is None and (built := fut.result()).allocator is not None:
                self.allocators.put(key, built.allocator, built.nbytes)
        return self.builder.submit(key, lane, build, problem, method, options, self.build_budget, keep, call,
                                   then=cache, priority=REBUILD if rebuild else REQUEST)

    async def _answer(self, key: Hashable, problem: Callable[[], alloc.Problem], method: str,
                      options: dict[str, Any], call: Call) -> Any:
        """``call`` answered by the allocator cached under ``key``, built if missing.

        A cached allocator is called here, on the event loop (never concurrently); an
        allocator too large to keep is answered where it was built.
        """
        found = self.allocators.lookup(key)
        if found is not None:
            return call.run(found)
        p = problem()
        seconds = check_build_cost(p, method, options, self.build_budget)  # refuse before queueing
        built: Built = await self.builder.outcome(self._start_build(key, p, method, options, call, seconds))
        if built.token != call.token and built.allocator is None:
            # the build in flight answered another request (its allocator too large to keep): our own
            private = ("private", call.token)
            built = await self.builder.outcome(self._start_build(private, p, method, options, call, seconds))
        return built.result if built.allocator is None else call.run(built.allocator)

    def _at(self, state: VehicleState, at: dict[str, float] | None) -> tuple[Any, tuple[float, ...] | None]:
        """The vehicle's schedule evaluator and the values of a request's ``at`` (``(None, None)``
        when ``at`` is absent or empty); 422 naming ``at`` or ``at.<name>`` (:mod:`service.schedule`)."""
        if not at:
            return None, None
        evaluator = self.schedules.of(state)
        return evaluator, at_values(evaluator, at)

    def _forget_other_at(self, key: tuple[Any, ...]) -> None:
        """Drop the allocators cached for this vehicle, method and options at another ``at``.

        No method of the library follows a new ``B`` without a build (none declares it), so an
        allocation at ``at`` is answered by an allocator built for those values, priced as any
        build.  One is kept per vehicle, method and options (the last ``at`` built: a vehicle
        holding its tilt reuses it), not one per ``at``, which would fill the cache with values
        a flight never asks again and evict the allocators other vehicles use.  An allocator is
        keyed by its own values, so concurrent requests at different ``at`` never share one.
        """
        stem = key[:4]
        self.allocators.drop(self.allocators.keys_where(
            lambda k: isinstance(k, tuple) and len(k) == 5 and k[:4] == stem and k[4] != key[4]))

    async def _batch(self, problem: alloc.Problem, method: str, options: dict[str, Any], V: Any,
                     extra: dict[str, Any]) -> StreamedAnswer:
        """A batch, priced before it starts (rows x the method's declared per-call cost, and its
        answer's size: 422 naming the limit), its answer's bytes reserved (503 when the
        answer budget is spent), run and serialised off the event loop (a costly one in the
        build process), then streamed."""
        rows = _demand_rows(V, problem.k)
        seconds = check_batch_cost(problem, method, options, len(rows), self.batch_budget, self.max_answer_bytes)
        free = self.answers.reserve(answer_bytes(problem, len(rows)))
        try:
            call = Call(V=rows, extra=extra)
            built: Built = await self.builder.outcome(
                self._start_build(("private", call.token), problem, method, options, call, seconds))
        except BaseException:
            free()
            raise
        return StreamedAnswer(built.result, free)

    async def _run_bounded(self, work: Callable[..., Any], *args: Any) -> Any:
        """``work(*args)`` (picklable) in the build process (bounded concurrency and queue, 429 beyond)."""
        return await self.builder.outcome(self.builder.submit(("work", uuid.uuid4().hex), "process", work, *args))
