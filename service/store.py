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
is published in this process, the response returns; only then are the allocators that
were in use for the old health rebuilt, at most :data:`PREBUILD_LIMIT` of them, for
that vehicle only, on the build pool (other processes rebuild lazily on their next
request, keyed by the new version).

Allocators are cached in a :class:`AllocatorCache` bounded in entries and in bytes
(measured by :func:`service.cost.estimate_bytes`); inline problems share a smaller byte
budget and an allocator larger than :data:`INLINE_ENTRY_BYTES` built for an inline
problem is used once and not kept.  Builds run on :class:`Builder`, a bounded pool of
threads with a bounded queue, after :func:`check_build_cost` refused anything predicted
to exceed the build budget (see :mod:`service.cost`).
"""

from __future__ import annotations

import asyncio
import json
import logging
import sqlite3
import threading
import time
import uuid
from collections import OrderedDict
from collections.abc import Callable, Hashable
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass
from datetime import datetime
from typing import Any

import numpy as np
from sqlalchemy import delete, func, select, text, update
from sqlalchemy.engine import Engine
from sqlalchemy.orm import Session, sessionmaker

import alloc

from .config import OPTION_CAPS
from .cost import FACET_SECONDS, build_seconds, estimate_bytes
from .db import EventRow, VehicleRow, utcnow
from .errors import Conflict, InvalidRequest, NotFound, ServiceError, TooManyRequests, field_error
from .health import Health, apply_event, dump_health, load_health, to_problem
from .schemas import EventIn, VehicleCreate

__all__ = ["VehicleState", "AllocatorCache", "Builder", "VehicleStore", "VersionProbe", "build_allocator",
           "check_build_cost", "options_key", "PREBUILD_LIMIT", "INLINE_ENTRY_BYTES"]

_log = logging.getLogger("service")
_MAX_RETRIES = 100
#: allocators rebuilt after an event, per vehicle (the most recently used ones)
PREBUILD_LIMIT = 4
#: an allocator built for an inline problem larger than this is not cached
INLINE_ENTRY_BYTES = 4 * 1024 * 1024
#: builds predicted faster than this (seconds) run in the fast lane of the Builder
FAST_BUILD_S = 0.05
#: vehicle states kept per process: a state holds two problems, at most ~70 KiB at m = 64
#: (Wu is m x m), so at most ~70 MiB; part of the documented memory bound
_STATE_ENTRIES = 1024


def options_key(options: dict[str, Any]) -> str:
    return json.dumps(options, sort_keys=True, separators=(",", ":"))


def _not_found(vehicle_id: str) -> NotFound:
    return NotFound(f"vehicle {vehicle_id!r} does not exist",
                    [{"loc": ["path", "vehicle_id"], "pointer": None, "reason": "unknown vehicle"}])


def _reject(field: str, reason: str) -> InvalidRequest:
    return InvalidRequest(f"{field}: {reason}", [field_error(field, reason)])


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


class _Lane:
    """One bounded pool of build threads with a bounded queue."""

    def __init__(self, name: str, workers: int, queue: int) -> None:
        self.name, self.workers, self.limit = name, workers, workers + queue
        self.pool: ThreadPoolExecutor | None = None
        self.inflight = 0


class Builder:
    """Bounded build pools with bounded queues, and single-flight per key.

    Two lanes, so that a flood of expensive builds never delays a cheap one (the
    allocation that must follow a failure is usually a millisecond build):

    * ``slow``: builds predicted (:func:`service.cost.build_seconds`) above
      :data:`FAST_BUILD_S`; ``workers`` threads, ``queue`` more waiting, then 429;
    * ``fast``: everything else (an SVD, a QP set-up); 2 threads, 64 waiting, then 429.
    """

    def __init__(self, workers: int, queue: int) -> None:
        self._lanes = {"slow": _Lane("slow", workers, queue), "fast": _Lane("fast", 2, 64)}
        self._inflight: dict[Hashable, Future[Any]] = {}
        self._lock = threading.Lock()

    def submit(self, key: Hashable, build: Callable[[], Any], seconds: float = 0.0) -> Future[Any]:
        lane = self._lanes["slow" if seconds > FAST_BUILD_S else "fast"]
        with self._lock:
            fut = self._inflight.get(key)
            if fut is not None:
                return fut
            if lane.inflight >= lane.limit:
                raise TooManyRequests(f"the service is running {lane.inflight} {lane.name} builds (the most it "
                                      f"queues); retry shortly")
            if lane.pool is None:
                lane.pool = ThreadPoolExecutor(max_workers=lane.workers, thread_name_prefix=f"alloc-{lane.name}")
            fut = lane.pool.submit(build)
            self._inflight[key] = fut
            lane.inflight += 1

        def done(_: Future[Any]) -> None:
            with self._lock:
                self._inflight.pop(key, None)
                lane.inflight -= 1
        fut.add_done_callback(done)
        return fut

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
            if pool is not None:
                pool.shutdown(wait=False, cancel_futures=True)


class AllocatorCache:
    """A thread-safe LRU of built allocators, bounded in entries and in bytes.

    ``inline_bytes`` bounds the share of entries keyed ``("inline", ...)``.
    """

    def __init__(self, size: int, max_bytes: int, inline_bytes: int) -> None:
        self._size, self._max_bytes, self._inline_max = size, max_bytes, inline_bytes
        self._items: OrderedDict[Hashable, tuple[alloc.Allocator, int]] = OrderedDict()
        self._lock = threading.Lock()
        self.bytes = 0
        self.inline_bytes = 0
        self.builds = 0

    def __len__(self) -> int:
        return len(self._items)

    def lookup(self, key: Hashable) -> alloc.Allocator | None:
        with self._lock:
            found = self._items.get(key)
            if found is None:
                return None
            self._items.move_to_end(key)
            return found[0]

    @staticmethod
    def _inline(key: Hashable) -> bool:
        return isinstance(key, tuple) and bool(key) and key[0] == "inline"

    def _pop(self, key: Hashable) -> None:
        item = self._items.pop(key, None)
        if item is not None:
            self.bytes -= item[1]
            if self._inline(key):
                self.inline_bytes -= item[1]

    def put(self, key: Hashable, allocator: alloc.Allocator, nbytes: int) -> bool:
        """Cache ``allocator`` (``nbytes`` held); ``False`` when it is too large to keep."""
        inline = self._inline(key)
        with self._lock:
            self.builds += 1
            if nbytes > self._max_bytes // 4 or (inline and nbytes > min(INLINE_ENTRY_BYTES, self._inline_max)):
                return False
            self._pop(key)
            self._items[key] = (allocator, nbytes)
            self.bytes += nbytes
            if inline:
                self.inline_bytes += nbytes
            while len(self._items) > self._size or self.bytes > self._max_bytes:
                self._pop(next(iter(self._items)))
            while self.inline_bytes > self._inline_max:
                self._pop(next(k for k in self._items if self._inline(k)))
            return True

    def keys_where(self, predicate: Callable[[Hashable], bool]) -> list[Hashable]:
        """Matching keys, least recently used first."""
        with self._lock:
            return [k for k in self._items if predicate(k)]

    def drop(self, keys: list[Hashable]) -> None:
        with self._lock:
            for k in keys:
                self._pop(k)


class VersionProbe:
    """``health_version`` of a vehicle from the database's committed state (``None``: absent).

    SQLite: one dedicated autocommit connection (each ``SELECT`` its own read
    transaction, so it sees every commit made before it, by any process); PostgreSQL and
    others: a pooled connection, autocommit.
    """

    _SQL = "SELECT health_version FROM vehicles WHERE id = ?"

    def __init__(self, engine: Engine) -> None:
        self._engine = engine
        self._lock = threading.Lock()
        self._sqlite_path = (engine.url.database if engine.dialect.name == "sqlite"
                             and engine.url.database not in (None, "", ":memory:") else None)
        self._sqlite: sqlite3.Connection | None = None

    def version(self, vehicle_id: str) -> int | None:
        if self._sqlite_path is not None:
            with self._lock:
                if self._sqlite is None:
                    self._sqlite = sqlite3.connect(self._sqlite_path, isolation_level=None, check_same_thread=False)
                    self._sqlite.execute("PRAGMA busy_timeout=5000")
                row = self._sqlite.execute(self._SQL, (vehicle_id,)).fetchone()
            return None if row is None else int(row[0])
        with self._engine.connect() as conn:
            value = conn.execute(text("SELECT health_version FROM vehicles WHERE id = :id"),
                                 {"id": vehicle_id}).scalar()
        return None if value is None else int(value)

    def close(self) -> None:
        with self._lock:
            if self._sqlite is not None:
                self._sqlite.close()
                self._sqlite = None


@dataclass(frozen=True, slots=True)
class VehicleState:
    id: str
    name: str | None
    created_at: datetime
    nominal: alloc.Problem
    health: Health
    version: int
    problem: alloc.Problem  # the effective problem at this health


def _problem_from_dict(d: dict[str, Any]) -> alloc.Problem:
    return alloc.Problem(
        d["B"], d["umin"], d["umax"], up=d["up"], Wu=d["Wu"], Wv=d["Wv"],
        rate_min=[-np.inf if r is None else r for r in d["rate_min"]],
        rate_max=[np.inf if r is None else r for r in d["rate_max"]],
        names=d["names"], axes=d["axes"],
    )


def _state(row: VehicleRow, nominal: alloc.Problem | None = None) -> VehicleState:
    nominal = nominal or _problem_from_dict(row.problem)
    health = load_health(row.health)
    return VehicleState(row.id, row.name, row.created_at, nominal, health, row.health_version,
                        to_problem(nominal, health))


class VehicleStore:
    """Vehicles in the database; their states and allocators cached per version in this process."""

    def __init__(self, engine: Engine, sessions: sessionmaker[Session], *, cache_size: int, cache_bytes: int,
                 inline_cache_bytes: int, build_budget: float, build_workers: int, build_queue: int) -> None:
        self._sessions = sessions
        self._probe = VersionProbe(engine)
        self._states: OrderedDict[str, VehicleState] = OrderedDict()
        self._states_lock = threading.Lock()
        self.allocators = AllocatorCache(cache_size, cache_bytes, inline_cache_bytes)
        self.builder = Builder(build_workers, build_queue)
        self.build_budget = build_budget
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
        return await asyncio.wrap_future(pool.submit(fn, *args))

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
        nominal = body.to_problem()
        row = VehicleRow(id=str(uuid.uuid4()), name=body.name, problem=nominal.to_dict(), health={},
                         health_version=0, created_at=utcnow())
        with self._sessions.begin() as session:
            session.add(row)
        return self._remember(_state(row, nominal))

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
            fresh = _state(row)
        self._remember(fresh)
        return fresh

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
        for _ in range(_MAX_RETRIES):
            with self._sessions() as session:
                row = session.get(VehicleRow, vehicle_id, with_for_update=True)
                if row is None:
                    self._forget(vehicle_id)
                    raise _not_found(vehicle_id)
                with self._states_lock:
                    old = self._states.get(vehicle_id)
                if old is None or old.version != row.health_version:
                    old = _state(row)
                name, health, params = apply_event(old.nominal, old.health, event)
                version = row.health_version + 1
                updated = session.execute(
                    update(VehicleRow)
                    .where(VehicleRow.id == vehicle_id, VehicleRow.health_version == row.health_version)
                    .values(health=dump_health(health), health_version=version)
                )
                if updated.rowcount != 1:  # another writer got there first: re-read and re-apply
                    session.rollback()
                    continue
                ev = EventRow(vehicle_id=vehicle_id, seq=version, effector=name, kind=event.kind,
                              params=params, note=event.note, recorded_at=utcnow())
                session.add(ev)
                session.commit()
            new = VehicleState(old.id, old.name, old.created_at, old.nominal, health, version,
                               to_problem(old.nominal, health))
            self._remember(new)
            return ev, new, old.version
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
                self.builder.submit(key, self._build_and_cache(key, new.problem, method, options), seconds)
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
    def _build_and_cache(self, key: Hashable, problem: alloc.Problem, method: str,
                         options: dict[str, Any]) -> Callable[[], alloc.Allocator]:
        def build() -> alloc.Allocator:
            t0 = time.perf_counter()
            allocator = build_allocator(problem, method, options, self.build_budget)
            seconds = time.perf_counter() - t0
            if seconds > self.build_budget:
                _log.warning("build of %s took %.2f s, over the budget of %.2f s (cost model under-predicted)",
                             method, seconds, self.build_budget)
            self.allocators.put(key, allocator, estimate_bytes(allocator))
            return allocator
        return build

    async def _allocator(self, key: Hashable, problem: Callable[[], alloc.Problem], method: str,
                         options: dict[str, Any]) -> alloc.Allocator:
        found = self.allocators.lookup(key)
        if found is not None:
            return found
        p = problem()
        seconds = check_build_cost(p, method, options, self.build_budget)  # refuse before queueing
        return await asyncio.wrap_future(
            self.builder.submit(key, self._build_and_cache(key, p, method, options), seconds))

    async def vehicle_allocator(self, state: VehicleState, method: str, options: dict[str, Any]) -> alloc.Allocator:
        key = (state.id, state.version, method, options_key(options))
        return await self._allocator(key, lambda: state.problem, method, options)

    async def inline_allocator(self, problem_key: str, build_problem: Callable[[], alloc.Problem],
                               method: str, options: dict[str, Any]) -> alloc.Allocator:
        key = ("inline", problem_key, method, options_key(options))
        return await self._allocator(key, build_problem, method, options)

    async def fresh_allocator(self, problem: alloc.Problem, method: str, options: dict[str, Any]) -> alloc.Allocator:
        """A private allocator (batches mutate nothing shared but run off the loop): built on the pool, not cached."""
        seconds = check_build_cost(problem, method, options, self.build_budget)
        key = ("private", uuid.uuid4().hex)
        return await asyncio.wrap_future(self.builder.submit(
            key, lambda: build_allocator(problem, method, options, self.build_budget), seconds))

    async def run_bounded(self, work: Callable[[], Any]) -> Any:
        """Run ``work`` in the slow lane of the build pool (bounded concurrency and queue, 429 beyond)."""
        return await asyncio.wrap_future(self.builder.submit(("work", uuid.uuid4().hex), work, float("inf")))

    def ping(self) -> None:
        """A committed read through the version probe (raises if the database is unreachable)."""
        self._probe.version("")
