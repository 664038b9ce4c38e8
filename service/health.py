"""Vehicle health over HTTP: a thin adapter over :mod:`alloc.health`.

The failure kinds, their parameters, meanings and precedence are defined once, in
the table of :mod:`alloc.health` (``FAILURE_KINDS``, ``EffectorHealth``, ``apply_event``,
``apply_health``).  This module only maps the JSON event bodies of
:mod:`service.schemas` (derived from that table, or written as text in the library's failure grammar,
:mod:`alloc.failure_grammar`) to :class:`alloc.health.FailureEvent`, reports the library's
validation errors as 422 against the field they name (``exc.field``), and shapes the
health for responses and for the database (``health_to_dict``).
"""

from __future__ import annotations

from typing import Any

import alloc
from alloc.health import (
    HEALTHY, EffectorHealth, FailureEvent, FailureKind, Health, apply_health, health_from_dict, health_to_dict,
    resolve_event,
)
from alloc.failure_grammar import EffectorFailure, format_failure
from alloc.health import apply_event as _apply_event

from .errors import InvalidRequest, field_error
from .schemas import EffectorHealthOut, EventIn

__all__ = ["EffectorHealth", "Health", "apply_event", "to_problem", "health_out", "load_health", "dump_health",
           "to_failure_event", "failure_text"]


def to_failure_event(event: EventIn) -> FailureEvent:
    """The library's :class:`~alloc.health.FailureEvent` for a JSON event body (its kind's parameters)."""
    kind = FailureKind(event.kind)
    return FailureEvent(event.effector, kind,
                        **{p: getattr(event, p) for p in kind.spec.params if getattr(event, p) is not None})


def failure_text(effector: str, kind: str, params: dict[str, Any]) -> str | None:
    """A recorded event in the failure grammar (``hardover:elevon_l@30``), None for a kind no longer registered.

    The parameters are written in the kind's order (:func:`alloc.failure_grammar.format_failure`).
    """
    if kind not in FailureKind:
        return None
    order = FailureKind(kind).spec.params
    return format_failure(EffectorFailure(kind, effector, {p: params[p] for p in order if p in params}))


def apply_event(nominal: alloc.Problem, health: Health, event: EventIn) -> tuple[str, Health, dict[str, Any]]:
    """Validate ``event`` against the vehicle; return ``(effector name, new health, params)``.

    ``params`` are the event's parameters as applied, defaults resolved (a hard-over records the
    stop it ran to), for the event history.

    Raises
    ------
    InvalidRequest
        anything :func:`alloc.health.apply_event` rejects (unknown effector, a value
        outside the nominal limits), reported against the field the library names.
    """
    failure = to_failure_event(event)
    try:
        applied = resolve_event(nominal, failure)
        name, new = _apply_event(nominal, health, applied)
    except alloc.AllocError as exc:
        field = exc.field or "effector"
        raise InvalidRequest(str(exc), [field_error(field, str(exc))]) from exc
    return name, new, applied.params


def to_problem(nominal: alloc.Problem, health: Health) -> alloc.Problem:
    """The problem of the vehicle at ``health`` (:func:`alloc.health.apply_health`)."""
    return apply_health(nominal, health)


def health_out(nominal: alloc.Problem, health: Health) -> list[EffectorHealthOut]:
    """Every effector's health, healthy ones included, in effector order."""
    out = []
    for name in nominal.names:
        h = health.get(name, HEALTHY)
        out.append(EffectorHealthOut(effector=name, status=h.status, jam_position=h.jam_position,  # type: ignore[arg-type]
                                     effectiveness=h.effectiveness, limits=h.limits, rate_limits=h.rate_limits))
    return out


def dump_health(health: Health) -> dict[str, Any]:
    """JSON form stored in the database (:func:`alloc.health.health_to_dict`)."""
    return health_to_dict(health)


def load_health(data: dict[str, Any] | None) -> Health:
    """Inverse of :func:`dump_health`."""
    return health_from_dict(data)
