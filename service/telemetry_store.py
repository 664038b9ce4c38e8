"""Telemetry in the database: each vehicle's detector state, its policy, and the proposals.

Every write is one transaction, with the guarantees of a posted event (:mod:`service.store`):

* A batch (:meth:`TelemetryStore.ingest`) reads the vehicle's committed health and its
  telemetry row, runs the detector (:func:`service.telemetry.run_batch`, no lock held), then
  writes the new detector state on the condition that the row's ``revision`` is the one read
  and, under policy ``auto``, the detections as events on the condition that the vehicle's
  ``health_version`` is the one read (the event rows' ``seq`` are the new versions, as a posted
  event's); under ``confirm`` it inserts the proposals.  A writer that got there first makes
  the batch run again on what it wrote (bounded retries, 409 beyond).  Batches, settings and
  decisions of one vehicle are serialised in this process (a lock per vehicle), so only another
  process's telemetry write can make a batch run again; an *event* committed during the run
  only makes its detections (``auto``) run again, at most :data:`_MAX_RUNS` runs in all, after
  which they are recorded after that event, as if posted then (the next batch realigns): an
  event never costs a batch or a detection (issue 39: 13 of 20 batches got 409 while events
  arrived, with a client that did not retry).  So every worker and
  replica sees one sequence of samples per vehicle, each sample processed once, and a
  detection applied is visible to every process when the answer returns; a refused batch
  (bad sample, out of order, over its price) changes nothing.
* Accepting a proposal commits its event and its new status together; rejecting one
  commits the status and marks the detector for realignment (its belief drops the proposal).
* A withdrawal the detector makes (its probation, :mod:`alloc.estimation.probation`) commits
  with the batch that made it: under ``auto`` as the events restoring the effector's health
  before the detection (a repair, then that health's failures: :func:`service.telemetry.restoring_events`),
  in the order the detector made them among the batch's detections, under the same health
  condition as they; under ``confirm`` the pending proposal of the detection withdrawn takes
  the status ``withdrawn`` (a decided one is left as it is: the answer reports the withdrawal).

Work runs on :class:`TelemetryRunner` threads (two, a bounded queue: 429 beyond), never on the
event loop nor on the writer threads events use.
"""

from __future__ import annotations

import asyncio
import threading
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from concurrent.futures import ThreadPoolExecutor
from typing import Any

from sqlalchemy import delete, func, insert, select, update
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session, sessionmaker

import alloc
from alloc.health import FailureEvent, resolve_event
from alloc.health import apply_event as apply_health_event

from .db import EventRow, ProposalRow, TelemetryRow, VehicleRow, utcnow
from .errors import Conflict, InvalidRequest, NotFound, TooManyRequests, field_error
from .health import dump_health
from .store import VehicleStore
from .telemetry import (
    BatchOutcome, DetectorSettings, Policy, Samples, batch_seconds, belief, detection_out, event_of,
    restoring_events, run_batch, segments_of, withdrawal_out,
)
from .vehicle_state import VehicleState

__all__ = ["TelemetryStore", "TelemetryRunner", "MAX_PROPOSALS"]

#: proposals kept per vehicle (the newest; decided ones are dropped first)
MAX_PROPOSALS = 64
#: runs of one write when other writers to the same vehicle keep getting there first (409 beyond):
#: a batch's CPU is at most this many times its price
_MAX_RETRIES = 3
#: runs of a batch whose detections meet events committed during its run; then they are
#: recorded after those events (no 409)
_MAX_RUNS = 3
#: commits of one run's outcome on top of events committed meanwhile (each a few ms: no rerun)
_MAX_COMMITS = 100
#: why a commit did not happen: another telemetry write (run again) or an event (health moved)
_REVISION, _HEALTH = "revision", "health"
#: the tables themselves: Core statements (as service.store's) skip the ORM's bookkeeping
_TELEMETRY, _PROPOSALS = TelemetryRow.__table__, ProposalRow.__table__
_VEHICLES, _EVENTS = VehicleRow.__table__, EventRow.__table__


class TelemetryRunner:
    """Two threads for telemetry work and a bounded queue (429 when ``queue`` are waiting)."""

    def __init__(self, threads: int = 2, queue: int = 8) -> None:
        self._pool = ThreadPoolExecutor(max_workers=threads, thread_name_prefix="alloc-telemetry")
        self._slots = threading.BoundedSemaphore(threads + queue)

    async def run(self, fn: Callable[..., Any], *args: Any) -> Any:
        """``fn(*args)`` on a telemetry thread; 429 when the threads and the queue are taken."""
        if not self._slots.acquire(blocking=False):
            raise TooManyRequests("telemetry work is at its limit (2 running, 8 waiting); retry shortly")
        try:
            future = self._pool.submit(fn, *args)
        except BaseException:
            self._slots.release()
            raise
        # the slot is the job's, not the request's: a client that goes away does not free it
        # while its job still runs or waits
        future.add_done_callback(lambda _: self._slots.release())
        return await asyncio.wrap_future(future)

    def close(self) -> None:
        self._pool.shutdown(wait=False, cancel_futures=True)


def _not_configured(vehicle_id: str) -> Conflict:
    return Conflict(f"vehicle {vehicle_id!r} has no telemetry settings: PUT /v1/vehicles/{vehicle_id}/telemetry first",
                    [{"loc": ["path", "vehicle_id"], "pointer": None, "reason": "telemetry not configured"}])


def _proposal_not_found(pid: int) -> NotFound:
    return NotFound(f"proposal {pid} does not exist for this vehicle",
                    [{"loc": ["path", "pid"], "pointer": None, "reason": "unknown proposal"}])


_PROPOSAL_FIELDS = ("id", "status", "effector", "kind", "params", "detection", "health_version", "event_seq",
                    "created_at", "decided_at")


def proposal_out(row: Mapping[str, Any]) -> dict[str, Any]:
    """A proposal's row (its columns but the vehicle id) as the service answers it."""
    return {name: row[name] for name in _PROPOSAL_FIELDS}


def check_price(settings: DetectorSettings, m: int, n: int, budget: float) -> None:
    """Refuse (422 on ``t``) a batch of ``n`` samples predicted over ``budget`` seconds."""
    seconds = batch_seconds(settings, m, n)
    if seconds > budget:
        fit = int(n * budget / seconds)
        reason = (f"{n} samples are predicted to take up to {seconds:.2f} s (the declared worst case at m = {m}, "
                  f"a window of {settings.window_samples()} samples), over ALLOC_BATCH_BUDGET_S = {budget:g} s; "
                  f"{fit} fit")
        raise InvalidRequest(f"t: {reason}", [field_error("t", reason)])


def append_events(db: Any, vehicle: VehicleState, events: list[tuple[FailureEvent, str]]
                  ) -> tuple[VehicleState, list[dict[str, Any]]] | None:
    """Record ``events`` (each with its note) for ``vehicle`` as posted events are recorded
    (:mod:`alloc.health` rules, ``seq`` = the new health version), in the open transaction, on
    the condition that the vehicle's ``health_version`` is still the one read; returns the new
    state and the event rows, or ``None`` when another writer got there first."""
    health, version = vehicle.health, vehicle.version
    rows = []
    for failure, note in events:
        applied = resolve_event(vehicle.nominal, failure)
        name, health = apply_health_event(vehicle.nominal, health, applied)
        version += 1
        rows.append({"vehicle_id": vehicle.id, "seq": version, "effector": name, "kind": applied.kind.value,
                     "params": applied.params, "note": note, "recorded_at": utcnow()})
    done = db.execute(update(_VEHICLES).where(_VEHICLES.c.id == vehicle.id,
                                              _VEHICLES.c.health_version == vehicle.version)
                      .values(health=dump_health(health), health_version=version))
    if done.rowcount != 1:
        return None
    db.execute(insert(_EVENTS), rows)
    return vehicle.with_health(health, version), rows


class TelemetryStore:
    """Telemetry writes and reads for the vehicles of ``store`` (same database)."""

    def __init__(self, store: VehicleStore, sessions: sessionmaker[Session]) -> None:
        self.store = store
        self._sessions = sessions
        self.runner = TelemetryRunner()
        self._locks: dict[str, list[Any]] = {}  # vehicle id -> [lock, holders and waiters]
        self._locks_guard = threading.Lock()

    @contextmanager
    def _serialised(self, vehicle_id: str) -> Iterator[None]:
        """This process's telemetry writes to ``vehicle_id``, one at a time (an entry lives while used)."""
        with self._locks_guard:
            entry = self._locks.setdefault(vehicle_id, [threading.Lock(), 0])
            entry[1] += 1
        try:
            with entry[0]:
                yield
        finally:
            with self._locks_guard:
                entry[1] -= 1
                if entry[1] == 0:
                    del self._locks[vehicle_id]

    # -------------------------------------------------------------- settings
    def configure(self, vehicle_id: str, policy: Policy, settings: DetectorSettings,
                  reset: bool = False) -> dict[str, Any]:
        """Set the vehicle's policy and detector settings.  New detector settings, or ``reset``,
        start a new detector (the state is dropped: buffers, segments, counters); a change of
        policy alone keeps it."""
        with self._serialised(vehicle_id):
            return self._configure(vehicle_id, policy, settings, reset)

    def _configure(self, vehicle_id: str, policy: Policy, settings: DetectorSettings, reset: bool) -> dict[str, Any]:
        state = self.store.get(vehicle_id)
        try:
            settings.detector(state.nominal)
        except alloc.AllocError as exc:
            field = (exc.field or "noise_std").split("/", 1)[0]
            raise InvalidRequest(str(exc), [field_error(field, str(exc))]) from exc
        record = settings.record()
        for _ in range(_MAX_RETRIES):
            with self._sessions() as session:
                db = session.connection()
                row = db.execute(select(_TELEMETRY).where(_TELEMETRY.c.vehicle_id == vehicle_id)).one_or_none()
                if row is None:
                    try:
                        db.execute(insert(_TELEMETRY).values(vehicle_id=vehicle_id, policy=policy.value, config=record,
                                                             state=None, revision=1, synced_version=-1,
                                                             updated_at=utcnow()))
                        session.commit()
                    except IntegrityError:  # a concurrent first PUT, or the vehicle deleted meanwhile: read again
                        session.rollback()
                        self.store.get(vehicle_id)
                        continue
                    return self.read(vehicle_id)
                same = row.config == record
                values: dict[str, Any] = {"policy": policy.value, "revision": row.revision + 1, "updated_at": utcnow()}
                if reset or not same:
                    values.update(config=record, state=None, synced_version=-1)
                done = db.execute(update(_TELEMETRY).where(_TELEMETRY.c.vehicle_id == vehicle_id,
                                                           _TELEMETRY.c.revision == row.revision).values(**values))
                if done.rowcount != 1:
                    session.rollback()
                    continue
                session.commit()
            return self.read(vehicle_id)
        raise Conflict(f"vehicle {vehicle_id!r}: too many concurrent telemetry writes; retry")

    def read(self, vehicle_id: str) -> dict[str, Any]:
        """The vehicle's policy, settings and detector summary (409 when not configured)."""
        state = self.store.get(vehicle_id)
        with self._sessions() as session:
            row = session.get(TelemetryRow, vehicle_id)
            if row is None:
                raise _not_configured(vehicle_id)
            pending = session.scalar(select(func.count()).where(_PROPOSALS.c.vehicle_id == vehicle_id,
                                                             _PROPOSALS.c.status == "pending"))
        det = row.state or {}
        settings = DetectorSettings.from_record(row.config).record()  # the model of a record stored before it
        return {"vehicle_id": vehicle_id, "policy": row.policy, "settings": settings, "revision": row.revision,
                "samples": det.get("samples", 0), "last_time": det.get("last_time"),
                "alarms": det.get("alarm_count", 0), "unisolated_alarms": det.get("unisolated_count", 0),
                "segments": segments_of(det)["count"], "health_version": state.version,
                "pending_proposals": int(pending or 0), "withdrawals": list(det.get("withdrawals", []))}

    # ---------------------------------------------------------------- batches
    def ingest(self, vehicle_id: str, make_samples: Callable[[VehicleState, DetectorSettings], Samples],
               budget: float) -> dict[str, Any]:
        """Run one batch and commit its outcome (module docstring); the answer as a dict.

        The detector runs between two short sessions (no connection or snapshot held while it
        runs); the write commits only if nobody wrote the vehicle's telemetry since the read,
        and its events (``auto``) only on the health read, or after :data:`_MAX_RUNS` runs on
        the health committed meanwhile."""
        with self._serialised(vehicle_id):
            return self._ingest(vehicle_id, make_samples, budget)

    def _ingest(self, vehicle_id: str, make_samples: Callable[[VehicleState, DetectorSettings], Samples],
                budget: float) -> dict[str, Any]:
        revisions = runs = 0
        while revisions < _MAX_RETRIES:
            vehicle = self.store.get(vehicle_id)
            with self._sessions() as session:
                db = session.connection()
                row = db.execute(select(_TELEMETRY).where(_TELEMETRY.c.vehicle_id == vehicle_id)).one_or_none()
                if row is None:
                    raise _not_configured(vehicle_id)
                pending = db.execute(select(_PROPOSALS.c.detection).where(_PROPOSALS.c.vehicle_id == vehicle_id,
                                                                          _PROPOSALS.c.status == "pending")
                                     .order_by(_PROPOSALS.c.id)).scalars().all()
            settings = DetectorSettings.from_record(row.config)
            samples = make_samples(vehicle, settings)
            check_price(settings, vehicle.nominal.m, len(samples), budget)
            align = None
            if row.synced_version != vehicle.version or row.state is None:
                align = belief(vehicle.nominal, vehicle.health, [event_of(d) for d in pending])
            outcome = run_batch(vehicle.nominal, settings, row.state, align, samples)
            runs += 1
            policy = Policy(row.policy)
            target = vehicle
            for _ in range(_MAX_COMMITS):
                with self._sessions() as session:
                    applied = self._commit(session.connection(), target, row, policy, outcome)
                    if isinstance(applied, str):
                        session.rollback()
                    else:
                        session.commit()
                if applied == _HEALTH and runs >= _MAX_RUNS:  # on the health committed meanwhile
                    target = self.store.get(vehicle_id)
                    continue
                break
            if applied == _REVISION:
                revisions += 1
                continue
            if applied == _HEALTH:
                continue  # run again on the new health
            new_state, events, proposal_ids, w_seqs, w_ids = applied
            if new_state is not None:
                self.store.publish(new_state)
            detections = []
            for i, d in enumerate(outcome.detections):
                out = detection_out(d)
                out["applied"] = policy is Policy.AUTO
                out["event_seq"] = events[i] if policy is Policy.AUTO else None
                out["proposal_id"] = proposal_ids[i] if policy is Policy.CONFIRM else None
                detections.append(out)
            withdrawals = [{**withdrawal_out(w), "applied": w_seqs[i] is not None, "event_seq": w_seqs[i],
                            "proposal_id": w_ids[i]} for i, (w, _) in enumerate(outcome.withdrawals)]
            return {"vehicle_id": vehicle_id, "accepted": len(samples), "samples": outcome.samples,
                    "last_time": outcome.last_time, "policy": policy.value, "detections": detections,
                    "withdrawals": withdrawals,
                    "segment": outcome.segment, "segments": outcome.segments,
                    "health_version": vehicle.version if new_state is None else new_state.version}
        raise Conflict(f"vehicle {vehicle_id!r}: too many concurrent telemetry writes from other processes; retry")

    def _commit(self, db: Any, vehicle: VehicleState, row: Any, policy: Policy, outcome: BatchOutcome
                ) -> tuple[VehicleState | None, list[int], list[int], list[int | None], list[int | None]] | str:
        """Write a batch's outcome in the open transaction; :data:`_HEALTH` when an event moved
        the vehicle's health since ``vehicle`` was read (``auto`` detections and withdrawals
        only), :data:`_REVISION` when another telemetry write won.  Returns the new state, the
        detections' event seqs (auto) or proposal ids (confirm), and the withdrawals' last
        restoring event seq (auto) or withdrawn proposal id (confirm, None when none was pending)."""
        new_state: VehicleState | None = None
        seqs: list[int] = []
        ids: list[int] = []
        w_seqs: list[int | None] = [None] * len(outcome.withdrawals)
        w_ids: list[int | None] = [None] * len(outcome.withdrawals)
        synced = vehicle.version  # the belief is aligned with this version now (run_batch realigned it)
        if policy is Policy.AUTO and (outcome.detections or outcome.withdrawals):
            events, owners = [], []  # owners: which detection or withdrawal each event is of
            for what, i in outcome.order:
                if what == "detection":
                    d = outcome.detections[i]
                    events.append((d.event, f"telemetry: detected at t = {d.time:.4f} s, confidence "
                                            f"{d.confidence:.4f}, improvement {d.improvement or 0.0:.4f}"))
                    owners.append((what, i))
                else:
                    w, before = outcome.withdrawals[i]
                    note = (f"telemetry: withdrawn at t = {w.time:.4f} s the {w.kind} detected at t = "
                            f"{w.detection_time:.4f} s ({w.reason}; statistic {w.statistic or 0.0:.4g})")
                    for ev in restoring_events(w.effector, before):
                        events.append((ev, note))
                        owners.append((what, i))
            appended = append_events(db, vehicle, events)
            if appended is None:
                return _HEALTH
            new_state, rows = appended
            for (what, i), r in zip(owners, rows):
                if what == "detection":
                    seqs.append(r["seq"])
                else:
                    w_seqs[i] = r["seq"]  # the last of its events: the health before is restored there
            # the detector applies its findings as "replaces what was known"; a posted event may
            # combine with what was known instead: the next batch realigns when the two differ
            synced = new_state.version if dump_health(outcome.belief) == dump_health(new_state.health) else -1
        done = db.execute(update(_TELEMETRY).where(_TELEMETRY.c.vehicle_id == vehicle.id,
                                                   _TELEMETRY.c.revision == row.revision)
                          .values(state=outcome.state, revision=row.revision + 1, synced_version=synced,
                                  updated_at=utcnow()))
        if done.rowcount != 1:
            return _REVISION
        if policy is Policy.CONFIRM and outcome.detections:
            for d in outcome.detections:
                out = detection_out(d)
                ids.append(int(db.execute(insert(_PROPOSALS).values(
                    vehicle_id=vehicle.id, status="pending", effector=out["effector"], kind=out["kind"],
                    params=out["params"], detection=out, health_version=vehicle.version, event_seq=None,
                    created_at=utcnow(), decided_at=None)).inserted_primary_key[0]))
            self._trim(db, vehicle.id)
        if policy is Policy.CONFIRM and outcome.withdrawals:
            w_ids = self._withdraw_proposals(db, vehicle.id, outcome)
        return new_state, seqs, ids, w_seqs, w_ids

    def _withdraw_proposals(self, db: Any, vehicle_id: str, outcome: BatchOutcome) -> list[int | None]:
        """Mark ``withdrawn`` the pending proposal of each withdrawn detection (same effector and
        decision time), in the open transaction; the ids marked (None: no pending one)."""
        pending = db.execute(select(_PROPOSALS.c.id, _PROPOSALS.c.effector, _PROPOSALS.c.detection)
                             .where(_PROPOSALS.c.vehicle_id == vehicle_id, _PROPOSALS.c.status == "pending")
                             .order_by(_PROPOSALS.c.id)).all()
        out: list[int | None] = []
        for w, _ in outcome.withdrawals:
            match = next((p.id for p in reversed(pending) if p.effector == w.effector
                          and p.detection.get("time") == w.detection_time), None)
            if match is not None:
                db.execute(update(_PROPOSALS).where(_PROPOSALS.c.id == match, _PROPOSALS.c.status == "pending")
                           .values(status="withdrawn", decided_at=utcnow()))
                pending = [p for p in pending if p.id != match]
            out.append(match)
        return out

    def _trim(self, db: Any, vehicle_id: str) -> None:
        """Keep the newest :data:`MAX_PROPOSALS` proposals of the vehicle (decided ones go first)."""
        rows = db.execute(select(_PROPOSALS.c.id, _PROPOSALS.c.status).where(_PROPOSALS.c.vehicle_id == vehicle_id)
                          .order_by(_PROPOSALS.c.id)).all()
        excess = len(rows) - MAX_PROPOSALS
        if excess <= 0:
            return
        order = [r.id for r in rows if r.status != "pending"] + [r.id for r in rows if r.status == "pending"]
        db.execute(delete(_PROPOSALS).where(_PROPOSALS.c.id.in_(order[:excess])))

    # -------------------------------------------------------------- proposals
    def proposals(self, vehicle_id: str, status: str | None) -> list[dict[str, Any]]:
        self.store.get(vehicle_id)
        query = select(_PROPOSALS).where(_PROPOSALS.c.vehicle_id == vehicle_id)
        if status is not None:
            query = query.where(_PROPOSALS.c.status == status)
        with self._sessions() as session:
            return [proposal_out(r._mapping) for r in session.execute(query.order_by(_PROPOSALS.c.id)).all()]

    def decide(self, vehicle_id: str, pid: int, accept: bool) -> tuple[dict[str, Any], VehicleState | None,
                                                                         dict[str, Any] | None]:
        """Accept (apply as an event, in the same transaction) or reject a pending proposal;
        returns ``(proposal, new vehicle state or None, event row values or None)``; 409 when
        it is no longer pending."""
        with self._serialised(vehicle_id):
            return self._decide(vehicle_id, pid, accept)

    def _decide(self, vehicle_id: str, pid: int, accept: bool) -> tuple[dict[str, Any], VehicleState | None,
                                                                          dict[str, Any] | None]:
        for _ in range(_MAX_RETRIES):
            vehicle = self.store.get(vehicle_id)
            with self._sessions() as session:
                db = session.connection()
                prop = db.execute(select(_PROPOSALS).where(_PROPOSALS.c.id == pid,
                                                           _PROPOSALS.c.vehicle_id == vehicle_id)).one_or_none()
                if prop is None:
                    raise _proposal_not_found(pid)
                if prop.status != "pending":
                    raise Conflict(f"proposal {pid} is {prop.status}, not pending",
                                   [{"loc": ["path", "pid"], "pointer": None, "reason": f"already {prop.status}"}])
                now = utcnow()
                event_row = None
                new_state = None
                values: dict[str, Any] = {"status": "accepted" if accept else "rejected", "decided_at": now}
                if accept:
                    appended = append_events(db, vehicle, [(FailureEvent(prop.effector, prop.kind, **prop.params),
                                                            f"telemetry proposal {pid} accepted")])
                    if appended is None:
                        session.rollback()
                        continue
                    new_state, (event_row,) = appended
                    values["event_seq"] = new_state.version
                else:  # the detector's belief drops the proposal at its next batch
                    db.execute(update(_TELEMETRY).where(_TELEMETRY.c.vehicle_id == vehicle_id)
                               .values(synced_version=-1, revision=_TELEMETRY.c.revision + 1, updated_at=now))
                done = db.execute(update(_PROPOSALS).where(_PROPOSALS.c.id == pid, _PROPOSALS.c.status == "pending")
                                  .values(**values))
                if done.rowcount != 1:
                    session.rollback()
                    continue
                session.commit()
            out = proposal_out({**prop._mapping, **values})
            if new_state is not None:
                self.store.publish(new_state)
            return out, new_state, event_row
        raise Conflict(f"vehicle {vehicle_id!r}: too many concurrent writes; retry")
