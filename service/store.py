"""Vehicles, their health and the allocators built for them.

The database is the record: a vehicle's nominal problem, its current health, a
``health_version`` counter and the event history.  In front of it, this process keeps

* the current state of each vehicle it has seen (nominal and effective problem), and
* an LRU cache of built allocators keyed by ``(vehicle, health_version, method, options)``
  (or, for inline problems, by the problem itself).

Recording an event commits the new health and the event in one transaction (optimistic
on ``health_version``, retried on conflict), then swaps the in-memory state and rebuilds
the allocators that were in use for the old health *before* the response returns, so
the next allocation finds them built.  The in-memory state is authoritative for this
process: run one service process per database (any number of threads).
"""

from __future__ import annotations

import json
import threading
import uuid
from collections import OrderedDict
from collections.abc import Callable, Hashable
from dataclasses import dataclass
from datetime import datetime
from functools import cache
from math import comb
from typing import Any

import numpy as np
from anyio import to_thread
from sqlalchemy import delete, func, select, update
from sqlalchemy.orm import Session, sessionmaker

import alloc

from .config import MAX_FACET_SUBSETS, OPTION_CAPS
from .db import EventRow, VehicleRow, utcnow
from .errors import Conflict, InvalidRequest, NotFound, field_error
from .health import Health, apply_event, dump_health, load_health, to_problem
from .schemas import EventIn, VehicleCreate

__all__ = ["VehicleState", "AllocatorCache", "VehicleStore", "build_allocator", "options_key"]

_MAX_RETRIES = 20


def options_key(options: dict[str, Any]) -> str:
    return json.dumps(options, sort_keys=True, separators=(",", ":"))


@cache
def _enumerates_facets(method: str) -> bool:
    from alloc.registry import get_method

    return get_method(method).__module__.startswith("alloc.ams")


def check_build_cost(problem: alloc.Problem, method: str, options: dict[str, Any]) -> None:
    """Refuse builds that would take minutes (a request must never stall the service):
    options above ``OPTION_CAPS`` and methods of ``alloc.ams`` on problems above
    ``MAX_FACET_SUBSETS`` get 422."""
    for name, value in options.items():
        cap = OPTION_CAPS.get((method, name))
        if cap is not None and isinstance(value, (int, float)) and value > cap:
            reason = f"{method}: option {name} = {value} exceeds the service's cap of {cap}"
            raise InvalidRequest(f"options/{name}: {reason}", [field_error(f"options/{name}", reason)])
    if method not in alloc.methods() or not _enumerates_facets(method):
        return
    moving = int((problem.umax > problem.umin).sum())
    subsets = comb(moving, problem.k - 1)
    if subsets > MAX_FACET_SUBSETS:
        reason = (f"{method} enumerates the attainable set's facets: C({moving}, {problem.k - 1}) = {subsets} "
                  f"exceeds the service's cap of {MAX_FACET_SUBSETS}; use 'da' (the same allocation as an LP)")
        raise InvalidRequest(f"method: {reason}", [field_error("method", reason)])


def build_allocator(problem: alloc.Problem, method: str, options: dict[str, Any]) -> alloc.Allocator:
    """``alloc.make_allocator`` with malformed option *values* reported as 422, not 500.

    Unknown methods and options raise the library's own errors (mapped by the handler);
    a method constructor given an option of the wrong shape or type raises a plain
    ``ValueError``/``TypeError`` from numpy, reported here against ``options``.  Builds
    too large to finish in about a second are refused (:func:`check_build_cost`).
    """
    check_build_cost(problem, method, options)
    try:
        return alloc.make_allocator(problem, method, **options)
    except alloc.ProblemError as exc:  # an option value the method rejected, e.g. "G: expected shape"
        field = str(exc).split(":", 1)[0]
        if field in options:
            raise InvalidRequest(str(exc), [field_error(f"options/{field}", str(exc))]) from exc
        raise
    except alloc.AllocError:
        raise
    except (ValueError, TypeError, ArithmeticError, IndexError, KeyError, np.linalg.LinAlgError) as exc:
        reason = f"{method}: invalid option value ({type(exc).__name__}: {exc})"
        raise InvalidRequest(f"options: {reason}", [field_error("options", reason)]) from exc


class AllocatorCache:
    """A thread-safe LRU of built allocators."""

    def __init__(self, size: int) -> None:
        self._size = size
        self._items: OrderedDict[Hashable, alloc.Allocator] = OrderedDict()
        self._lock = threading.Lock()
        self.builds = 0

    def lookup(self, key: Hashable) -> alloc.Allocator | None:
        with self._lock:
            found = self._items.get(key)
            if found is not None:
                self._items.move_to_end(key)
            return found

    async def get(self, key: Hashable, build: Callable[[], alloc.Allocator]) -> alloc.Allocator:
        """The cached allocator, or one built in a worker thread (the event loop keeps
        serving other requests meanwhile) and cached."""
        found = self.lookup(key)
        if found is not None:
            return found
        allocator = await to_thread.run_sync(build)
        self.put(key, allocator)
        return allocator

    def put(self, key: Hashable, allocator: alloc.Allocator) -> None:
        with self._lock:
            self.builds += 1
            self._items[key] = allocator
            self._items.move_to_end(key)
            while len(self._items) > self._size:
                self._items.popitem(last=False)

    def keys_where(self, predicate: Callable[[Hashable], bool]) -> list[Hashable]:
        with self._lock:
            return [k for k in self._items if predicate(k)]

    def drop(self, keys: list[Hashable]) -> None:
        with self._lock:
            for k in keys:
                self._items.pop(k, None)


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
    """Vehicles in the database, their current state in memory, their allocators cached."""

    def __init__(self, sessions: sessionmaker[Session], cache_size: int) -> None:
        self._sessions = sessions
        self._states: dict[str, VehicleState] = {}
        self.allocators = AllocatorCache(cache_size)

    # ----------------------------------------------------------- vehicles
    def create(self, body: VehicleCreate) -> VehicleState:
        nominal = body.to_problem()
        row = VehicleRow(id=str(uuid.uuid4()), name=body.name, problem=nominal.to_dict(), health={},
                         health_version=0, created_at=utcnow())
        with self._sessions.begin() as session:
            session.add(row)
        state = _state(row, nominal)
        self._states[row.id] = state
        return state

    def get(self, vehicle_id: str) -> VehicleState:
        state = self._states.get(vehicle_id)
        if state is not None:
            return state
        with self._sessions() as session:
            row = session.get(VehicleRow, vehicle_id)
            if row is None:
                raise NotFound(f"vehicle {vehicle_id!r} does not exist",
                               [{"loc": ["path", "vehicle_id"], "pointer": None, "reason": "unknown vehicle"}])
            state = _state(row)
        return self._states.setdefault(vehicle_id, state)

    def list(self, limit: int, offset: int) -> tuple[list[VehicleRow], int]:
        with self._sessions() as session:
            total = session.scalar(select(func.count()).select_from(VehicleRow)) or 0
            rows = session.scalars(
                select(VehicleRow).order_by(VehicleRow.created_at, VehicleRow.id).limit(limit).offset(offset)
            ).all()
        return list(rows), int(total)

    def delete(self, vehicle_id: str) -> None:
        self.get(vehicle_id)
        with self._sessions.begin() as session:
            session.execute(delete(EventRow).where(EventRow.vehicle_id == vehicle_id))
            session.execute(delete(VehicleRow).where(VehicleRow.id == vehicle_id))
        self._states.pop(vehicle_id, None)
        self.allocators.drop(self.allocators.keys_where(lambda k: k[0] == vehicle_id))

    # ------------------------------------------------------------- events
    def record_event(self, vehicle_id: str, event: EventIn) -> tuple[EventRow, VehicleState]:
        """Validate, commit (durably) and apply one event; rebuild the allocators in use."""
        for _ in range(_MAX_RETRIES):
            with self._sessions() as session:
                row = session.get(VehicleRow, vehicle_id)
                if row is None:
                    raise NotFound(f"vehicle {vehicle_id!r} does not exist",
                                   [{"loc": ["path", "vehicle_id"], "pointer": None, "reason": "unknown vehicle"}])
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
            self._swap(old, new)
            return ev, new
        raise Conflict(f"vehicle {vehicle_id!r}: too many concurrent events; retry")

    def _swap(self, old: VehicleState, new: VehicleState) -> None:
        """Publish ``new`` after building the allocators that were in use for ``old``."""
        # older versions only: a concurrent, later event may already have built its own
        stale = self.allocators.keys_where(lambda k: k[0] == old.id and k[1] < new.version)
        for key in stale:
            _, _, method, okey = key
            try:
                allocator = build_allocator(new.problem, method, json.loads(okey))
            except (alloc.AllocError, InvalidRequest):
                continue  # built fine for the old health; the next request reports the error
            self.allocators.put((new.id, new.version, method, okey), allocator)
        current = self._states.get(new.id)
        if current is None or current.version < new.version:
            self._states[new.id] = new
        self.allocators.drop(stale)

    def events(self, vehicle_id: str) -> list[EventRow]:
        self.get(vehicle_id)
        with self._sessions() as session:
            return list(session.scalars(
                select(EventRow).where(EventRow.vehicle_id == vehicle_id).order_by(EventRow.seq)
            ).all())

    # --------------------------------------------------------- allocators
    async def vehicle_allocator(self, state: VehicleState, method: str, options: dict[str, Any]) -> alloc.Allocator:
        okey = options_key(options)
        return await self.allocators.get((state.id, state.version, method, okey),
                                         lambda: build_allocator(state.problem, method, options))

    async def inline_allocator(self, problem_key: str, build_problem: Callable[[], alloc.Problem],
                               method: str, options: dict[str, Any]) -> alloc.Allocator:
        return await self.allocators.get(("inline", problem_key, method, options_key(options)),
                                         lambda: build_allocator(build_problem(), method, options))

    def ping(self) -> None:
        with self._sessions() as session:
            session.scalar(select(1))
