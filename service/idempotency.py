"""Writes sent with an ``Idempotency-Key`` happen once: the key, the request's fingerprint
and the answer are stored in the write's own transaction (:class:`~service.db.IdempotencyRow`),
so a retry finds either the committed answer or nothing committed (see :mod:`service.store`)."""

from __future__ import annotations

from dataclasses import dataclass
from datetime import timedelta

from sqlalchemy import delete
from sqlalchemy.orm import Session

from .db import IdempotencyRow, utcnow
from .errors import Conflict
from .vehicle_state import VehicleState

__all__ = ["Idempotency", "Answer", "replay_answer", "remember_answer"]


@dataclass(frozen=True, slots=True)
class Idempotency:
    """A write's ``Idempotency-Key`` (per ``scope``: its method and path) and the fingerprint
    of its body (SHA-256 over the scope and the validated body)."""

    scope: str
    key: str
    fingerprint: str


@dataclass(frozen=True, slots=True)
class Answer:
    """A write's answer as sent: its status and JSON body; ``state`` is the new vehicle state
    when the write happened now (``None``: the answer was replayed for a retried key)."""

    status: int
    body: bytes
    state: VehicleState | None

    @property
    def replayed(self) -> bool:
        return self.state is None


def replay_answer(session: Session, once: Idempotency | None) -> Answer | None:
    """The stored answer to ``once``'s key, or ``None`` (409 when the key came with another body)."""
    if once is None:
        return None
    row = session.get(IdempotencyRow, (once.scope, once.key))
    if row is None:
        return None
    if row.fingerprint != once.fingerprint:
        raise Conflict(f"Idempotency-Key {once.key!r} was used for a different request to {once.scope}; "
                       f"a retry must repeat the request unchanged, a new request needs a new key",
                       [{"loc": ["header", "Idempotency-Key"], "pointer": None,
                         "reason": "key reused with a different body"}])
    return Answer(row.status, row.body.encode(), None)


def remember_answer(session: Session, once: Idempotency | None, status: int, body: bytes, ttl_s: float) -> None:
    """Store the answer in the write's own transaction (and drop keys older than ``ttl_s``)."""
    if once is None:
        return
    now = utcnow()
    session.execute(delete(IdempotencyRow).where(IdempotencyRow.created_at < now - timedelta(seconds=ttl_s)))
    session.add(IdempotencyRow(scope=once.scope, key=once.key, fingerprint=once.fingerprint, status=status,
                               body=body.decode(), created_at=now))
