"""A vehicle as this process holds it (its nominal problem, health and effective problem at
one ``health_version``), the states this process holds, and the probe that reads the
committed version (see :mod:`service.store`)."""

from __future__ import annotations

import sqlite3
import threading
from collections import OrderedDict
from dataclasses import dataclass, replace
from datetime import datetime
from typing import Any

import numpy as np
from sqlalchemy import text
from sqlalchemy.engine import Engine

import alloc

from .db import VehicleRow
from .health import Health, load_health, to_problem

__all__ = ["VehicleState", "StateCache", "VersionProbe", "method_defaults", "problem_from_dict", "state_from_row"]

#: vehicle states kept per process: a state holds two problems, at most ~70 KiB at m = 64
#: (Wu is m x m), so at most ~70 MiB; part of the documented memory bound
STATE_ENTRIES = 1024


@dataclass(frozen=True, slots=True)
class VehicleState:
    id: str
    name: str | None
    created_at: datetime
    nominal: alloc.Problem
    health: Health
    version: int
    problem: alloc.Problem  # the effective problem at this health
    # method -> options: the vehicle document's [methods.<method>] defaults (daisy groups, gang
    # matrix, priorities), applied under a request's own options as `alloc allocate --vehicle` does
    defaults: dict[str, dict[str, Any]]
    # whether the document declares a [schedule] (B a function of named variables); the
    # evaluators are held apart, in service.schedule.Schedules, bounded on their own
    scheduled: bool = False

    def with_health(self, health: Health, version: int) -> VehicleState:
        """This vehicle at a new health and version (everything read from its document kept)."""
        return replace(self, health=health, version=version, problem=to_problem(self.nominal, health))


def problem_from_dict(d: dict[str, Any]) -> alloc.Problem:
    return alloc.Problem(
        d["B"], d["umin"], d["umax"], up=d["up"], Wu=d["Wu"], Wv=d["Wv"],
        rate_min=[-np.inf if r is None else r for r in d["rate_min"]],
        rate_max=[np.inf if r is None else r for r in d["rate_max"]],
        names=d["names"], axes=d["axes"],
    )


def method_defaults(document: dict[str, Any] | None) -> dict[str, dict[str, Any]]:
    """The per-method defaults of a stored vehicle document (read by the library's reader: the
    document was validated by it when the vehicle was created); ``{}`` for an effector suite."""
    return document_parts(document)[0]


def document_parts(document: dict[str, Any] | None) -> tuple[dict[str, dict[str, Any]], bool]:
    """A stored document's per-method defaults and whether it declares a ``[schedule]``, the
    document read once; ``({}, False)`` for an effector suite."""
    if document is None:
        return {}, False
    from alloc.vehicle_file.vehicle import vehicle_from_dict

    vehicle = vehicle_from_dict(document)
    return {method: vehicle.method_options(method) for method in vehicle.methods}, vehicle.schedule is not None


def state_from_row(row: VehicleRow, nominal: alloc.Problem | None = None) -> VehicleState:
    nominal = nominal or problem_from_dict(row.problem)
    health = load_health(row.health)
    defaults, scheduled = document_parts(row.problem.get("document"))
    return VehicleState(row.id, row.name, row.created_at, nominal, health, row.health_version,
                        to_problem(nominal, health), defaults, scheduled)


class StateCache:
    """The vehicle states this process holds, newest version per vehicle, an LRU of
    :data:`STATE_ENTRIES` (thread-safe).  Only a cache: the database's version decides."""

    def __init__(self, entries: int = STATE_ENTRIES) -> None:
        self._entries = entries
        self._states: OrderedDict[str, VehicleState] = OrderedDict()
        self._lock = threading.Lock()

    def __contains__(self, vehicle_id: str) -> bool:
        return vehicle_id in self._states

    def held(self, vehicle_id: str) -> VehicleState | None:
        with self._lock:
            return self._states.get(vehicle_id)

    def remember(self, state: VehicleState) -> VehicleState:
        """Keep ``state`` unless a newer version is already held; return ``state``."""
        with self._lock:
            current = self._states.get(state.id)
            if current is None or current.version <= state.version:
                self._states[state.id] = state
            self._states.move_to_end(state.id)
            while len(self._states) > self._entries:
                self._states.popitem(last=False)
        return state

    def forget(self, vehicle_id: str) -> None:
        with self._lock:
            self._states.pop(vehicle_id, None)


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
