"""The repository: vehicles, their events and idempotency keys in the database, and the
vehicle states this process holds per version.  No allocator lives here: the allocators
are :class:`service.pool.AllocatorPool`'s, which listens to this store (:meth:`VehicleStore.subscribe`).

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
is published in this process (:meth:`VehicleStore.publish`: held, and told to the
listeners, where the pool submits its rebuilds without waiting for them), and the
response returns.  A vehicle found gone is told to the listeners too (``None``).

Writes sent with an ``Idempotency-Key`` happen once: the key, the fingerprint of the
request and the answer are inserted in the write's own transaction
(:mod:`service.idempotency`), so a retry, through any process and after any
crash, either finds the committed answer or finds nothing committed at all.
"""

from __future__ import annotations

import asyncio
import os
import signal
import threading
import uuid
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import Any

from sqlalchemy import delete, func, insert, select, update
from sqlalchemy.exc import IntegrityError
from sqlalchemy.engine import Engine
from sqlalchemy.orm import Session, sessionmaker

from . import timing
from .db import EventRow, VehicleRow, utcnow
from .errors import Conflict, NotFound
from .idempotency import Answer, Idempotency, remember_answer, replay_answer
from .health import apply_event, dump_health
from .schemas import EventIn, VehicleCreate
from .vehicle_state import StateCache, VehicleState, VersionProbe, state_from_row

__all__ = ["VehicleState", "Idempotency", "Answer", "VehicleStore", "VersionProbe", "StateListener"]

_MAX_RETRIES = 100

#: told ``(vehicle id, its new state)`` after a write of this process changed the vehicle's
#: health, ``(vehicle id, None)`` once the vehicle is found gone; called on the writing thread
StateListener = Callable[[str, VehicleState | None], None]


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


class VehicleStore:
    """The repository: vehicles, events and idempotency keys in the database; the vehicle
    states this process holds, per version."""

    def __init__(self, engine: Engine, sessions: sessionmaker[Session], *, idempotency_ttl_s: float = 86400.0) -> None:
        self._sessions = sessions
        self._probe = VersionProbe(engine)
        self._states = StateCache()
        self._listeners: list[StateListener] = []
        self.idempotency_ttl_s = idempotency_ttl_s
        # Writes (events, deletes) get threads of their own: they never queue behind the
        # shared thread pool of the sync routes or behind builds.
        self._writers: ThreadPoolExecutor | None = None
        self._writers_lock = threading.Lock()

    def subscribe(self, listener: StateListener) -> None:
        """Tell ``listener`` of every health change this process commits and of vehicles found gone."""
        self._listeners.append(listener)

    def publish(self, state: VehicleState) -> None:
        """A new health this process committed (an event, a telemetry detection): hold it, tell the listeners."""
        self._states.remember(state)
        for listener in self._listeners:
            listener(state.id, state)

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
        self._probe.close()
        with self._writers_lock:
            writers, self._writers = self._writers, None
        if writers is not None:
            writers.shutdown(wait=True)

    def _forget(self, vehicle_id: str) -> None:
        """The vehicle is gone (deleted by this or another process): drop it here and tell the listeners."""
        self._states.forget(vehicle_id)
        for listener in self._listeners:
            listener(vehicle_id, None)

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
            self._states.remember(state)
            return answer
        raise Conflict("too many concurrent writes with this Idempotency-Key; retry")

    def get(self, vehicle_id: str) -> VehicleState:
        """The vehicle at its committed health (the version read from the database now)."""
        version = self._probe.version(vehicle_id)
        if version is None:
            if vehicle_id in self._states:  # deleted by any process: drop what this one holds
                self._forget(vehicle_id)
            raise _not_found(vehicle_id)
        state = self._states.held(vehicle_id)
        if state is not None and state.version == version:
            return state
        with self._sessions() as session:
            row = session.get(VehicleRow, vehicle_id)
            if row is None:
                self._forget(vehicle_id)
                raise _not_found(vehicle_id)
            fresh = state_from_row(row)
        return self._states.remember(fresh)

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

        The new state is published (:meth:`publish`) once committed; the listeners do not
        wait for optional work (the pool only submits its rebuilds).
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
                old = self._states.held(vehicle_id)
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
                new = old.with_health(health, version)
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
            self.publish(new)
            return answer
        raise Conflict(f"vehicle {vehicle_id!r}: too many concurrent events; retry")

    def events(self, vehicle_id: str) -> list[EventRow]:
        with self._sessions() as session:
            if session.get(VehicleRow, vehicle_id) is None:
                self._forget(vehicle_id)
                raise _not_found(vehicle_id)
            return list(session.scalars(
                select(EventRow).where(EventRow.vehicle_id == vehicle_id).order_by(EventRow.seq)
            ).all())

    def ping(self) -> None:
        """A committed read through the version probe (raises if the database is unreachable)."""
        self._probe.version("")
