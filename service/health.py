"""Vehicle health: what has failed on each effector, and the problem it implies.

Per effector the health holds a jam position, a floating flag, an effectiveness
fraction, reduced position limits and reduced rate limits.  Events change it:

``jam``            held at ``position`` (must lie within the *nominal* limits: a reduced
                   limit restricts commands, not where a failed surface can stick)
``effectiveness``  its column of ``B`` scaled by ``fraction`` in [0, 1] (replaces, does not
                   compound, an earlier fraction)
``limits``         reduced position limits ``[lo, hi]`` within the nominal ones
``rate_limits``    reduced rate limits within the nominal ones
``float``          a floating surface: see below
``repair``         back to healthy (clears every failure of that effector)

A floating surface trails with the flow: it produces no controlled moment and cannot
be commanded.  It is modelled as effectiveness 0 *and* held at its preferred position,
so allocators neither count on it nor move it; its reported command is that position.
A jam overrides reduced limits and floating overrides a jam (the latest wins between
the two).  :func:`to_problem` applies the health with :meth:`alloc.Problem.with_effectiveness`,
:meth:`~alloc.Problem.with_jam` and :meth:`~alloc.Problem.with_limits`.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, replace
from typing import Any

import numpy as np

import alloc

from .errors import InvalidRequest, field_error
from .schemas import (
    EffectivenessEvent, EffectorHealthOut, EventIn, FloatEvent, JamEvent, LimitsEvent,
    RateLimitsEvent, RepairEvent,
)

__all__ = ["EffectorHealth", "Health", "apply_event", "to_problem", "health_out", "load_health", "dump_health"]


@dataclass(frozen=True, slots=True)
class EffectorHealth:
    jam_position: float | None = None
    floating: bool = False
    effectiveness: float = 1.0
    limits: tuple[float, float] | None = None
    rate_limits: tuple[float, float] | None = None

    @property
    def status(self) -> str:
        if self.floating:
            return "floating"
        if self.jam_position is not None:
            return "jammed"
        if self.effectiveness != 1.0 or self.limits is not None or self.rate_limits is not None:
            return "degraded"
        return "healthy"


HEALTHY = EffectorHealth()
#: effector name -> health; healthy effectors are absent
Health = dict[str, EffectorHealth]


def _reject(field: str, reason: str) -> InvalidRequest:
    return InvalidRequest(f"{field}: {reason}", [field_error(field, reason)])


def apply_event(nominal: alloc.Problem, health: Health, event: EventIn) -> tuple[str, Health, dict[str, Any]]:
    """Validate ``event`` against the vehicle and return ``(effector name, new health, params)``.

    Raises
    ------
    alloc.ProblemError
        unknown effector name or index.
    InvalidRequest
        a value outside the nominal limits (jam position, reduced limits, rate limits).
    """
    i = nominal.index(event.effector)
    name = nominal.names[i]
    lo0, hi0 = float(nominal.umin[i]), float(nominal.umax[i])
    old = health.get(name, HEALTHY)
    params: dict[str, Any]
    if isinstance(event, JamEvent):
        if not lo0 <= event.position <= hi0:
            raise _reject("position", f"jam position {event.position:g} of {name!r} outside its limits "
                                      f"[{lo0:g}, {hi0:g}]")
        new, params = replace(old, jam_position=event.position, floating=False), {"position": event.position}
    elif isinstance(event, EffectivenessEvent):
        new, params = replace(old, effectiveness=event.fraction), {"fraction": event.fraction}
    elif isinstance(event, LimitsEvent):
        if event.lo > event.hi:
            raise _reject("hi", f"limits out of order: lo = {event.lo:g} > hi = {event.hi:g}")
        if event.lo < lo0 or event.hi > hi0:
            raise _reject("lo" if event.lo < lo0 else "hi",
                          f"reduced limits [{event.lo:g}, {event.hi:g}] of {name!r} must lie within "
                          f"its nominal limits [{lo0:g}, {hi0:g}]")
        new, params = replace(old, limits=(event.lo, event.hi)), {"lo": event.lo, "hi": event.hi}
    elif isinstance(event, RateLimitsEvent):
        rmin0, rmax0 = float(nominal.rate_min[i]), float(nominal.rate_max[i])
        if event.rate_min < rmin0 or event.rate_max > rmax0:
            raise _reject("rate_min" if event.rate_min < rmin0 else "rate_max",
                          f"reduced rate limits [{event.rate_min:g}, {event.rate_max:g}] of {name!r} must "
                          f"lie within its nominal rate limits [{rmin0:g}, {rmax0:g}]")
        new = replace(old, rate_limits=(event.rate_min, event.rate_max))
        params = {"rate_min": event.rate_min, "rate_max": event.rate_max}
    elif isinstance(event, FloatEvent):
        new, params = replace(old, floating=True, jam_position=None), {}
    elif isinstance(event, RepairEvent):
        new, params = HEALTHY, {}
    else:  # pragma: no cover - the schema's discriminator admits nothing else
        raise TypeError(f"unknown event {event!r}")
    out = dict(health)
    if new == HEALTHY:
        out.pop(name, None)
    else:
        out[name] = new
    return name, out, params


def to_problem(nominal: alloc.Problem, health: Health) -> alloc.Problem:
    """The problem of the vehicle at ``health`` (nominal when everything is healthy)."""
    p = nominal
    rate_min, rate_max = nominal.rate_min.copy(), nominal.rate_max.copy()
    for name, h in health.items():
        i = nominal.index(name)
        if h.effectiveness != 1.0 or h.floating:
            p = p.with_effectiveness(i, 0.0 if h.floating else h.effectiveness)
        if h.floating:
            p = p.with_jam(i, float(p.up[i]))
        elif h.jam_position is not None:
            p = p.with_jam(i, h.jam_position)
        elif h.limits is not None:
            p = p.with_limits(i, *h.limits)
        if h.rate_limits is not None:
            rate_min[i], rate_max[i] = h.rate_limits
    if not (np.array_equal(rate_min, p.rate_min) and np.array_equal(rate_max, p.rate_max)):
        p = p.replace(rate_min=rate_min, rate_max=rate_max)
    return p


def health_out(nominal: alloc.Problem, health: Health) -> list[EffectorHealthOut]:
    """Every effector's health, healthy ones included, in effector order."""
    out = []
    for name in nominal.names:
        h = health.get(name, HEALTHY)
        out.append(EffectorHealthOut(effector=name, status=h.status, **asdict(h)))  # type: ignore[arg-type]
    return out


def dump_health(health: Health) -> dict[str, Any]:
    """JSON form stored in the database."""
    return {name: asdict(h) for name, h in health.items()}


def load_health(data: dict[str, Any] | None) -> Health:
    out: Health = {}
    for name, h in (data or {}).items():
        out[name] = EffectorHealth(
            jam_position=h.get("jam_position"), floating=bool(h.get("floating", False)),
            effectiveness=float(h.get("effectiveness", 1.0)),
            limits=tuple(h["limits"]) if h.get("limits") else None,  # type: ignore[arg-type]
            rate_limits=tuple(h["rate_limits"]) if h.get("rate_limits") else None,  # type: ignore[arg-type]
        )
    return out
