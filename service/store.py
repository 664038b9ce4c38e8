"""Vehicles, their health and the allocators built for them.

The database is the one truth.  Every read of a vehicle (allocation, health, AMS) first
reads its ``health_version`` from the database's committed state (one primary-key
``SELECT``, a few microseconds on SQLite through a dedicated connection; one round trip
on PostgreSQL); only when that version differs from the one this process holds is the
row loaded again.  So any number of worker processes and replicas on one database give
the same answer: an allocation that starts after an event's response has returned,
from any process, uses that event.  A vehicle that is no longer in the database is
gone for every process at its next request.

Writes are serialised per vehicle: recording an event updates the vehicle row on the
condition that its ``health_version`` is the one read (optimistic, retried), under a
row lock on PostgreSQL (``SELECT ... FOR UPDATE``) and the database-wide write lock on
SQLite, and inserts the event in the same transaction; deleting takes the same lock.
An event racing a delete either commits first (and is deleted with the vehicle) or
finds the row gone (404): a deleted vehicle stays deleted.

Publishing a failure never waits for optional work: the event commits, the new state
is published in this process, the rebuilds of the allocators that were in use for the
old health are submitted (at most :data:`PREBUILD_LIMIT`, that vehicle only, on the
builder's ``rebuild`` lane, which no request can use, or first in the build process's
queue), and the response returns; the next allocation finds its rebuild in flight
(other processes rebuild lazily on their next request, keyed by the new version).

Writes sent with an ``Idempotency-Key`` happen once: the key, the fingerprint of the
request and the answer are inserted in the write's own transaction
(:mod:`service.idempotency`), so a retry, through any process and after any
crash, either finds the committed answer or finds nothing committed at all.

Batches are priced before they start (rows x the method's declared per-call cost, and
the size of their answer: :func:`~service.builds.check_batch_cost`), their answer bytes
reserved in :class:`~service.responses.AnswerBudget`, run and serialised off the event
loop, and streamed.

Allocators are cached in a :class:`~service.allocator_cache.AllocatorCache` bounded in entries and in bytes
(measured by :func:`service.cost.estimate_bytes`); inline problems share a smaller byte
budget and an allocator larger than :data:`INLINE_ENTRY_BYTES` built for an inline
problem is used once and not kept.  Builds run on :class:`service.builds.Builder` (costly
ones in a low-priority build process, cheap ones on threads, both bounded in concurrency
and queue) after :func:`check_build_cost` refused anything predicted to exceed the build
budget (see :mod:`service.cost`).
"""

from __future__ import annotations

import asyncio
import json
import logging
import os
import signal
import threading
import uuid
from collections import OrderedDict
from collections.abc import Callable, Hashable
from concurrent.futures import Future, ThreadPoolExecutor
from typing import Any

import numpy as np
from sqlalchemy import delete, func, insert, select, update
from sqlalchemy.exc import IntegrityError
from sqlalchemy.engine import Engine
from sqlalchemy.orm import Session, sessionmaker

import alloc

from . import timing
from .allocator_cache import INLINE_ENTRY_BYTES, AllocatorCache
from .builds import (
    REBUILD, REQUEST, TRANSFER_BYTES, Builder, Built, Call, build, build_allocator, check_batch_cost, check_build_cost,
)
from .cost import answer_bytes, is_costly, is_costly_batch
from .db import EventRow, VehicleRow, utcnow
from .errors import Conflict, NotFound, ServiceError
from .idempotency import Answer, Idempotency, remember_answer, replay_answer
from .responses import AnswerBudget, StreamedAnswer
from .health import apply_event, dump_health, to_problem
from .schemas import EventIn, VehicleCreate
from .vehicle_state import VehicleState, VersionProbe, state_from_row

__all__ = ["VehicleState", "Idempotency", "Answer", "AllocatorCache", "Builder", "VehicleStore", "VersionProbe", "build_allocator",
           "check_build_cost", "options_key", "PREBUILD_LIMIT", "INLINE_ENTRY_BYTES"]  # the build API re-exported

_log = logging.getLogger("service")
_MAX_RETRIES = 100
#: allocators rebuilt after an event, per vehicle (the most recently used ones)
PREBUILD_LIMIT = 4
#: vehicle states kept per process: a state holds two problems, at most ~70 KiB at m = 64
#: (Wu is m x m), so at most ~70 MiB; part of the documented memory bound
_STATE_ENTRIES = 1024


def options_key(options: dict[str, Any]) -> str:
    return json.dumps(options, sort_keys=True, separators=(",", ":"))


def _not_found(vehicle_id: str) -> NotFound:
    return NotFound(f"vehicle {vehicle_id!r} does not exist",
                    [{"loc": ["path", "vehicle_id"], "pointer": None, "reason": "unknown vehicle"}])


#: the tables themselves: Core statements on them skip the ORM's per-statement bookkeeping
_VEHICLES, _EVENTS = VehicleRow.__table__, EventRow.__table__


def _failpoint(name: str) -> None:
    """Fault injection for the crash tests: ``ALLOC_FAILPOINT=<name>`` kills this process
    (SIGKILL, no clean-up) when it reaches ``name``.  Unset in production: one dict lookup."""
    if os.environ.get("ALLOC_FAILPOINT") == name:
        os.kill(os.getpid(), signal.SIGKILL)


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


class VehicleStore:
    """Vehicles in the database; their states and allocators cached per version in this process."""

    def __init__(self, engine: Engine, sessions: sessionmaker[Session], *, cache_size: int, cache_bytes: int,
                 inline_cache_bytes: int, build_budget: float, build_workers: int, build_queue: int,
                 idempotency_ttl_s: float = 86400.0, batch_budget: float = 2.0,
                 max_answer_bytes: int = 16 * 1024 * 1024, answer_bytes_in_flight: int = 96 * 1024 * 1024) -> None:
        self._sessions = sessions
        self._probe = VersionProbe(engine)
        self._states: OrderedDict[str, VehicleState] = OrderedDict()
        self._states_lock = threading.Lock()
        self.allocators = AllocatorCache(cache_size, cache_bytes, inline_cache_bytes)
        self.builder = Builder(build_workers, build_queue)
        self.build_budget = build_budget
        self.idempotency_ttl_s = idempotency_ttl_s
        self.batch_budget, self.max_answer_bytes = batch_budget, max_answer_bytes
        self.answers = AnswerBudget(answer_bytes_in_flight)
        # Writes (events, deletes) get threads of their own: they never queue behind the
        # shared thread pool of the sync routes or behind builds.
        self._writers: ThreadPoolExecutor | None = None
        self._writers_lock = threading.Lock()

    async def write(self, fn: Callable[..., Any], *args: Any) -> Any:
        """Run the write ``fn(*args)`` on the dedicated writer threads."""
        with self._writers_lock:
            if self._writers is None:
                self._writers = ThreadPoolExecutor(max_workers=4, thread_name_prefix="alloc-write")
            pool = self._writers
        timeline = timing.current()
        if timeline is None:
            return await asyncio.wrap_future(pool.submit(fn, *args))
        timeline.mark("route")

        def timed() -> Any:
            timeline.mark("write-queue")
            try:
                return fn(*args)
            finally:
                timeline.mark("write")
        try:
            return await asyncio.wrap_future(pool.submit(timed))
        finally:
            timeline.mark("resume")

    def close(self) -> None:
        self.builder.shutdown()
        self._probe.close()
        with self._writers_lock:
            writers, self._writers = self._writers, None
        if writers is not None:
            writers.shutdown(wait=True)

    # ------------------------------------------------------------ states
    def _remember(self, state: VehicleState) -> VehicleState:
        """Keep ``state`` unless a newer version is already held; return ``state``."""
        with self._states_lock:
            current = self._states.get(state.id)
            if current is None or current.version <= state.version:
                self._states[state.id] = state
            self._states.move_to_end(state.id)
            while len(self._states) > _STATE_ENTRIES:
                self._states.popitem(last=False)
        return state

    def _forget(self, vehicle_id: str) -> None:
        with self._states_lock:
            self._states.pop(vehicle_id, None)
        self.allocators.drop(self.allocators.keys_where(lambda k: k[0] == vehicle_id))

    # ----------------------------------------------------------- vehicles
    def create(self, body: VehicleCreate) -> VehicleState:
        answer = self.create_once(body, None, lambda state: b"")
        assert answer.state is not None
        return answer.state

    def create_once(self, body: VehicleCreate, once: Idempotency | None,
                    render: Callable[[VehicleState], bytes]) -> Answer:
        """Create a vehicle; with ``once``, at most once per key (a retry gets the first answer).

        ``render(state)`` is the answer's body, stored with the key in the same transaction.
        """
        nominal = body.to_problem()
        for _ in range(_MAX_RETRIES):
            row = VehicleRow(id=str(uuid.uuid4()), name=body.name, problem=body.stored_problem(nominal), health={},
                             health_version=0, created_at=utcnow())
            state = state_from_row(row, nominal)
            try:
                with self._sessions.begin() as session:
                    if (replayed := replay_answer(session, once)) is not None:
                        return replayed
                    session.add(row)
                    answer = Answer(201, render(state), state)
                    remember_answer(session, once, answer.status, answer.body, self.idempotency_ttl_s)
            except IntegrityError:
                if once is None:
                    raise
                continue  # the same key committed concurrently: replay its answer
            _failpoint("after-commit")
            self._remember(state)
            return answer
        raise Conflict("too many concurrent writes with this Idempotency-Key; retry")

    def get(self, vehicle_id: str) -> VehicleState:
        """The vehicle at its committed health (the version read from the database now)."""
        version = self._probe.version(vehicle_id)
        if version is None:
            if vehicle_id in self._states:  # deleted by any process: drop what this one holds
                self._forget(vehicle_id)
            raise _not_found(vehicle_id)
        with self._states_lock:
            state = self._states.get(vehicle_id)
        if state is not None and state.version == version:
            return state
        with self._sessions() as session:
            row = session.get(VehicleRow, vehicle_id)
            if row is None:
                self._forget(vehicle_id)
                raise _not_found(vehicle_id)
            fresh = state_from_row(row)
        self._remember(fresh)
        return fresh

    def document(self, vehicle_id: str) -> dict[str, Any] | None:
        """The vehicle document the vehicle was created from (``None``: created from a suite)."""
        with self._sessions() as session:
            row = session.get(VehicleRow, vehicle_id)
            if row is None:
                raise _not_found(vehicle_id)
            return row.problem.get("document")

    def list(self, limit: int, offset: int) -> tuple[list[VehicleRow], int]:
        with self._sessions() as session:
            total = session.scalar(select(func.count()).select_from(VehicleRow)) or 0
            rows = session.scalars(
                select(VehicleRow).order_by(VehicleRow.created_at, VehicleRow.id).limit(limit).offset(offset)
            ).all()
        return list(rows), int(total)

    def delete(self, vehicle_id: str) -> None:
        with self._sessions.begin() as session:
            row = session.get(VehicleRow, vehicle_id, with_for_update=True)
            if row is None:
                raise _not_found(vehicle_id)
            session.execute(delete(VehicleRow).where(VehicleRow.id == vehicle_id))
            session.execute(delete(EventRow).where(EventRow.vehicle_id == vehicle_id))
        self._forget(vehicle_id)

    # ------------------------------------------------------------- events
    def record_event(self, vehicle_id: str, event: EventIn) -> tuple[EventRow, VehicleState, int]:
        """Validate and commit (durably) one event; return ``(event, new state, old version)``.

        Nothing else happens before the caller can answer: allocators are rebuilt by
        :meth:`prebuild`, after the response.
        """
        written: list[tuple[EventRow, VehicleState, int]] = []

        def keep(ev: EventRow, new: VehicleState, old_version: int) -> bytes:
            written.append((ev, new, old_version))
            return b""
        self.record_event_once(vehicle_id, event, None, keep)
        return written[-1]

    def record_event_once(self, vehicle_id: str, event: EventIn, once: Idempotency | None,
                          render: Callable[[EventRow, VehicleState, int], bytes]) -> Answer:
        """:meth:`record_event`, at most once per ``once`` key (a retry gets the first answer).

        ``render(event, new state, old version)`` is the answer's body, stored with the key in
        the same transaction as the event: committed together or not at all.
        """
        for _ in range(_MAX_RETRIES):
            with self._sessions() as session:
                if (replayed := replay_answer(session, once)) is not None:
                    return replayed
                # Core statements on the session's connection: the ORM's identity map and
                # unit of work doubled the transaction's CPU time (measured at load 10: ORM
                # 16-20 ms, Core 8-14 ms, of which SQLite's fsync'd commit about 4 ms)
                db = session.connection()
                version = db.execute(select(_VEHICLES.c.health_version).where(_VEHICLES.c.id == vehicle_id)
                                     .with_for_update()).scalar()
                if version is None:
                    self._forget(vehicle_id)
                    raise _not_found(vehicle_id)
                with self._states_lock:
                    old = self._states.get(vehicle_id)
                if old is None or old.version != version:  # another process wrote: load the row
                    old = state_from_row(db.execute(select(_VEHICLES).where(_VEHICLES.c.id == vehicle_id)).one())
                name, health, params = apply_event(old.nominal, old.health, event)
                updated = db.execute(
                    update(_VEHICLES)
                    .where(_VEHICLES.c.id == vehicle_id, _VEHICLES.c.health_version == version)
                    .values(health=dump_health(health), health_version=version + 1)
                )
                if updated.rowcount != 1:  # another writer got there first: re-read and re-apply
                    session.rollback()
                    continue
                version += 1
                ev = EventRow(vehicle_id=vehicle_id, seq=version, effector=name, kind=event.kind,
                              params=params, note=event.note, recorded_at=utcnow())
                db.execute(insert(_EVENTS).values(vehicle_id=ev.vehicle_id, seq=ev.seq, effector=ev.effector,
                                                   kind=ev.kind, params=ev.params, note=ev.note,
                                                   recorded_at=ev.recorded_at))
                new = VehicleState(old.id, old.name, old.created_at, old.nominal, health, version,
                                   to_problem(old.nominal, health), old.defaults)
                answer = Answer(201, render(ev, new, old.version), new)
                remember_answer(session, once, answer.status, answer.body, self.idempotency_ttl_s)
                try:
                    session.commit()
                except IntegrityError:
                    if once is None:
                        raise
                    session.rollback()
                    continue  # the same key committed concurrently: its answer is replayed next round
            _failpoint("after-commit")
            self._remember(new)
            return answer
        raise Conflict(f"vehicle {vehicle_id!r}: too many concurrent events; retry")

    def prebuild(self, new: VehicleState) -> int:
        """After an event: rebuild (on the build pool) the allocators that were in use for an
        older version of this vehicle, at most :data:`PREBUILD_LIMIT`, most recent first;
        drop the stale ones.  Returns how many builds were started."""
        stale = self.allocators.keys_where(lambda k: k[0] == new.id and k[1] < new.version)
        started = 0
        seen: set[tuple[str, str]] = set()
        for key in reversed(stale):
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

    def events(self, vehicle_id: str) -> list[EventRow]:
        with self._sessions() as session:
            if session.get(VehicleRow, vehicle_id) is None:
                self._forget(vehicle_id)
                raise _not_found(vehicle_id)
            return list(session.scalars(
                select(EventRow).where(EventRow.vehicle_id == vehicle_id).order_by(EventRow.seq)
            ).all())

    # --------------------------------------------------------- allocators
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

    async def _allocate(self, key: Hashable, problem: Callable[[], alloc.Problem], method: str,
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

    async def vehicle_allocate(self, state: VehicleState, method: str, options: dict[str, Any],
                               call: Call) -> Any:
        """``call`` (one demand) at the vehicle's health ``state``."""
        key = (state.id, state.version, method, options_key(options))
        return await self._allocate(key, lambda: state.problem, method, options, call)

    async def vehicle_batch(self, state: VehicleState, method: str, options: dict[str, Any], V: Any) -> StreamedAnswer:
        """A batch at the vehicle's health ``state`` (:meth:`_batch`)."""
        return await self._batch(state.problem, method, options, V,
                                 {"vehicle_id": state.id, "health_version": state.version})

    async def inline_allocate(self, problem_key: str, build_problem: Callable[[], alloc.Problem],
                              method: str, options: dict[str, Any], call: Call) -> Any:
        """``call`` (one demand) for an inline problem (``problem_key`` identifies it in the cache)."""
        key = ("inline", problem_key, method, options_key(options))
        return await self._allocate(key, build_problem, method, options, call)

    async def inline_batch(self, problem: alloc.Problem, method: str, options: dict[str, Any], V: Any) -> StreamedAnswer:
        """A batch for an inline problem (:meth:`_batch`)."""
        return await self._batch(problem, method, options, V, {})

    async def run_bounded(self, work: Callable[..., Any], *args: Any) -> Any:
        """``work(*args)`` (picklable) in the build process (bounded concurrency and queue, 429 beyond)."""
        return await self.builder.outcome(self.builder.submit(("work", uuid.uuid4().hex), "process", work, *args))

    def ping(self) -> None:
        """A committed read through the version probe (raises if the database is unreachable)."""
        self._probe.version("")
