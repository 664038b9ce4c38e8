"""Effector health: one closed set of failure kinds, one meaning each.

This is the single definition of "what failed" used by the library
(:meth:`alloc.Problem.with_health`), the simulator (failure injection and the
problem an allocator is told) and the service (vehicle health events).

Failure kinds (:class:`FailureKind`) and what each means *to an allocator*:

``jam``            the surface is stuck at ``position`` (within the nominal limits);
                   the allocator holds it there: ``umin = umax = position``.
``hardover``       the surface ran to a stop and stays there: a jam at ``position``,
                   by default the nominal upper limit (seed section 4.7 failure list).
``float``          the surface trails with the flow: it produces no controlled moment
                   and cannot be commanded.  Effectiveness 0 *and* held at its
                   preferred position ``up``, so allocators neither count on it nor move it.
``effectiveness``  loss of effectiveness: its column of ``B`` scaled by ``fraction`` in
                   [0, 1] (replaces, does not compound, an earlier fraction).
``limits``         reduced position limits ``[lo, hi]`` within the nominal ones.
``rate_limits``    reduced rate limits ``[rate_min, rate_max]`` within the nominal ones.
``repair``         back to healthy: clears every failure of that effector.

Precedence when several apply to one effector: ``float`` overrides a jam and a jam
overrides reduced limits (between ``float`` and a jam the latest event wins);
effectiveness and rate limits combine with any of them.

Changes of actuator *dynamics* (reduced bandwidth, added delay) are not expressible
in a static allocation problem; the simulator models them in its actuators and
they are never "told" to an allocator.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace
from enum import Enum
from typing import TYPE_CHECKING, Any

import numpy as np

from .exceptions import ProblemError
from .problem import as_real, short_repr

if TYPE_CHECKING:
    from .problem import Problem

__all__ = [
    "FailureKind", "FailureEvent", "EffectorHealth", "HEALTHY", "Health",
    "apply_event", "apply_health", "health_to_dict", "health_from_dict", "EFFECTOR_HEALTH_SCHEMA",
]


class FailureKind(str, Enum):
    """The closed set of effector failure kinds (see the module docstring for their meaning)."""

    JAM = "jam"
    HARDOVER = "hardover"
    FLOAT = "float"
    EFFECTIVENESS = "effectiveness"
    LIMITS = "limits"
    RATE_LIMITS = "rate_limits"
    REPAIR = "repair"


_KINDS = frozenset(k.value for k in FailureKind)


@dataclass(frozen=True, slots=True)
class FailureEvent:
    """One failure (or repair) of one effector.

    Parameters by kind: ``jam`` needs ``position``; ``hardover`` takes an optional
    ``position`` (default the nominal upper limit); ``effectiveness`` needs ``fraction``;
    ``limits`` needs ``lo`` and ``hi``; ``rate_limits`` needs ``rate_min`` and ``rate_max``
    (``rate_min <= 0 <= rate_max``); ``float`` and ``repair`` take none.
    """

    effector: int | str
    kind: FailureKind
    position: float | None = None
    fraction: float | None = None
    lo: float | None = None
    hi: float | None = None
    rate_min: float | None = None
    rate_max: float | None = None

    def __post_init__(self) -> None:
        if not (isinstance(self.kind, str) and self.kind in _KINDS):  # no repr of an arbitrary object
            kinds = ", ".join(k.value for k in FailureKind)
            raise ProblemError(f"kind: unknown failure kind {short_repr(self.kind)}; expected one of {kinds}")
        object.__setattr__(self, "kind", FailureKind(self.kind))
        need = {
            FailureKind.JAM: ("position",), FailureKind.EFFECTIVENESS: ("fraction",),
            FailureKind.LIMITS: ("lo", "hi"), FailureKind.RATE_LIMITS: ("rate_min", "rate_max"),
        }.get(self.kind, ())
        for name in need:
            if getattr(self, name) is None:
                raise ProblemError(f"{name}: required for a {self.kind.value!r} failure")
        if isinstance(self.effector, (bool, np.bool_)) or not isinstance(self.effector, (int, np.integer, str)):
            raise ProblemError(f"effector: expected an index or a name, got {short_repr(self.effector)}")
        for name in ("position", "fraction", "lo", "hi", "rate_min", "rate_max"):
            value = getattr(self, name)
            if value is not None:
                object.__setattr__(self, name, as_real(name, value))


@dataclass(frozen=True, slots=True)
class EffectorHealth:
    """What has failed on one effector (healthy: every field at its default)."""

    jam_position: float | None = None
    floating: bool = False
    effectiveness: float = 1.0
    limits: tuple[float, float] | None = None
    rate_limits: tuple[float, float] | None = None

    def __post_init__(self) -> None:
        """Each field checked and normalised (floats, tuples); ProblemError naming it otherwise.

        Only what needs no problem is checked here (types, ``effectiveness`` in [0, 1],
        ordered limits, ``rate_min <= 0 <= rate_max``); positions against the nominal limits
        are :func:`apply_health`'s to check.
        """
        setter = object.__setattr__
        if self.jam_position is not None:
            setter(self, "jam_position", as_real("jam_position", self.jam_position))
        if not isinstance(self.floating, (bool, np.bool_)):
            raise ProblemError(f"floating: expected true or false, got {short_repr(self.floating)}")
        setter(self, "floating", bool(self.floating))
        eff = as_real("effectiveness", self.effectiveness)
        if not 0.0 <= eff <= 1.0:
            raise ProblemError(f"effectiveness: {eff:g} must be in [0, 1]")
        setter(self, "effectiveness", eff)
        if self.limits is not None:
            lo, hi = _pair("limits", self.limits)
            if lo > hi:
                raise ProblemError(f"limits: [{lo:g}, {hi:g}] is not an ordered interval")
            setter(self, "limits", (lo, hi))
        if self.rate_limits is not None:
            rmin, rmax = _pair("rate_limits", self.rate_limits)
            if rmin > 0.0 or rmax < 0.0:
                raise ProblemError(f"rate_limits: [{rmin:g}, {rmax:g}] must satisfy rate_min <= 0 <= rate_max")
            setter(self, "rate_limits", (rmin, rmax))

    @property
    def status(self) -> str:
        """``healthy``, ``degraded`` (effectiveness or limits), ``jammed`` or ``floating``."""
        if self.floating:
            return "floating"
        if self.jam_position is not None:
            return "jammed"
        if self.effectiveness != 1.0 or self.limits is not None or self.rate_limits is not None:
            return "degraded"
        return "healthy"

    def to_dict(self) -> dict[str, Any]:
        """JSON form (see :data:`EFFECTOR_HEALTH_SCHEMA`)."""
        return {
            "jam_position": self.jam_position, "floating": self.floating, "effectiveness": self.effectiveness,
            "limits": None if self.limits is None else list(self.limits),
            "rate_limits": None if self.rate_limits is None else list(self.rate_limits),
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> EffectorHealth:
        """Inverse of :meth:`to_dict`; strict (see :data:`EFFECTOR_HEALTH_SCHEMA`): unknown
        keys, text for numbers and anything but ``true``/``false`` for ``floating`` raise
        ProblemError naming the field."""
        if not isinstance(data, Mapping):
            raise ProblemError(f"health: an effector's health must be an object, got {short_repr(data)}")
        unknown = sorted(set(data) - set(EFFECTOR_HEALTH_SCHEMA["properties"]), key=str)
        if unknown:
            known = ", ".join(EFFECTOR_HEALTH_SCHEMA["properties"])
            raise ProblemError(f"health: unknown field(s) {unknown}; accepted: {known}")
        return cls(**data)


def _pair(name: str, value: Any) -> tuple[float, float]:
    """``[a, b]`` as two floats (each a real number in the domain), or ProblemError naming ``name``."""
    if isinstance(value, (str, bytes, Mapping)) or not hasattr(value, "__len__") or len(value) != 2:
        raise ProblemError(f"{name}: expected a pair [lo, hi], got {short_repr(value)}")
    return as_real(name, value[0]), as_real(name, value[1])


HEALTHY = EffectorHealth()
#: effector name -> health; healthy effectors are absent
Health = dict[str, EffectorHealth]

#: JSON schema of one effector's health (shared with the service's OpenAPI document).
EFFECTOR_HEALTH_SCHEMA: dict[str, Any] = {
    "title": "EffectorHealth",
    "type": "object",
    "properties": {
        "jam_position": {"type": ["number", "null"], "description": "held position of a jam or hard-over"},
        "floating": {"type": "boolean", "description": "trails with the flow: no moment, held at up"},
        "effectiveness": {"type": "number", "minimum": 0, "maximum": 1,
                          "description": "fraction of the nominal column of B"},
        "limits": {"type": ["array", "null"], "items": {"type": "number"}, "minItems": 2, "maxItems": 2,
                   "description": "reduced position limits [lo, hi]"},
        "rate_limits": {"type": ["array", "null"], "items": {"type": "number"}, "minItems": 2, "maxItems": 2,
                        "description": "reduced rate limits [rate_min, rate_max], units per second"},
    },
    "additionalProperties": False,
}


def apply_event(nominal: Problem, health: Mapping[str, EffectorHealth], event: FailureEvent) -> tuple[str, Health]:
    """Validate ``event`` against the nominal problem; return ``(effector name, new health)``.

    Raises
    ------
    ProblemError
        unknown effector, or a value outside the nominal limits (jam position, reduced
        limits, rate limits) or an effectiveness outside [0, 1]; the message names the field.
    """
    if not isinstance(event, FailureEvent):
        raise ProblemError(f"event: expected an alloc.health.FailureEvent, got {type(event).__name__}")
    health = _checked_health(health)
    i = nominal.index(event.effector)
    name = nominal.names[i]
    lo0, hi0 = float(nominal.umin[i]), float(nominal.umax[i])
    old = health.get(name, HEALTHY)
    kind = event.kind
    if kind in (FailureKind.JAM, FailureKind.HARDOVER):
        pos = hi0 if event.position is None else event.position
        if not lo0 <= pos <= hi0:
            raise ProblemError(f"position: {kind.value} position {pos:g} of {name!r} outside its limits "
                               f"[{lo0:g}, {hi0:g}]")
        new = replace(old, jam_position=pos, floating=False)
    elif kind is FailureKind.EFFECTIVENESS:
        assert event.fraction is not None
        if not 0.0 <= event.fraction <= 1.0:
            raise ProblemError(f"fraction: effectiveness {event.fraction:g} of {name!r} must be in [0, 1]")
        new = replace(old, effectiveness=event.fraction)
    elif kind is FailureKind.LIMITS:
        assert event.lo is not None and event.hi is not None
        if event.lo > event.hi:
            raise ProblemError(f"hi: limits out of order: lo = {event.lo:g} > hi = {event.hi:g}")
        if event.lo < lo0 or event.hi > hi0:
            raise ProblemError(f"{'lo' if event.lo < lo0 else 'hi'}: reduced limits [{event.lo:g}, {event.hi:g}] "
                               f"of {name!r} must lie within its nominal limits [{lo0:g}, {hi0:g}]")
        new = replace(old, limits=(event.lo, event.hi))
    elif kind is FailureKind.RATE_LIMITS:
        assert event.rate_min is not None and event.rate_max is not None
        rmin0, rmax0 = float(nominal.rate_min[i]), float(nominal.rate_max[i])
        if event.rate_min > 0.0 or event.rate_max < 0.0:
            raise ProblemError(f"{'rate_min' if event.rate_min > 0 else 'rate_max'}: rate limits "
                               f"[{event.rate_min:g}, {event.rate_max:g}] must satisfy rate_min <= 0 <= rate_max")
        if event.rate_min < rmin0 or event.rate_max > rmax0:
            raise ProblemError(f"{'rate_min' if event.rate_min < rmin0 else 'rate_max'}: reduced rate limits "
                               f"[{event.rate_min:g}, {event.rate_max:g}] of {name!r} must lie within its "
                               f"nominal rate limits [{rmin0:g}, {rmax0:g}]")
        new = replace(old, rate_limits=(event.rate_min, event.rate_max))
    elif kind is FailureKind.FLOAT:
        new = replace(old, floating=True, jam_position=None)
    else:  # REPAIR
        new = HEALTHY
    out = dict(health)
    if new == HEALTHY:
        out.pop(name, None)
    else:
        out[name] = new
    return name, out


def _checked_health(health: Any) -> Mapping[Any, EffectorHealth]:
    """``health`` if it maps effectors to :class:`EffectorHealth`; ProblemError naming it otherwise."""
    if not isinstance(health, Mapping):
        raise ProblemError(f"health: expected a mapping of effector to EffectorHealth, got {type(health).__name__}")
    for key, h in health.items():
        if not isinstance(h, EffectorHealth):
            raise ProblemError(f"health: the health of {short_repr(key)} must be an alloc.health.EffectorHealth, "
                               f"got {type(h).__name__}")
    return health


def apply_health(nominal: Problem, health: Mapping[int | str, EffectorHealth]) -> Problem:
    """The problem of a vehicle at ``health`` (``nominal`` itself when all are healthy).

    Keys are effector names or indices.  See the module docstring for each kind's meaning.
    Reduced position and rate limits act within the nominal ones (their intersection: a
    failure never widens a limit); reduced limits that do not meet the nominal ones, or a
    jam outside them, raise ProblemError.
    """
    p = nominal
    rate_min, rate_max = nominal.rate_min.copy(), nominal.rate_max.copy()
    for key, h in _checked_health(health).items():
        i = nominal.index(key)
        if h.effectiveness != 1.0 or h.floating:
            p = p.with_effectiveness(i, 0.0 if h.floating else h.effectiveness)
        if h.floating:
            p = p.with_jam(i, float(nominal.up[i]))
        elif h.jam_position is not None:
            p = p.with_jam(i, h.jam_position)
        elif h.limits is not None:
            lo0, hi0 = float(nominal.umin[i]), float(nominal.umax[i])
            lo, hi = max(h.limits[0], lo0), min(h.limits[1], hi0)
            if lo > hi:
                raise ProblemError(f"limits: reduced limits [{h.limits[0]:g}, {h.limits[1]:g}] of "
                                   f"{nominal.names[i]!r} do not meet its nominal limits [{lo0:g}, {hi0:g}]")
            p = p.with_limits(i, lo, hi)
        if h.rate_limits is not None:  # rate_min <= 0 <= rate_max on both sides: never empty
            rate_min[i] = max(h.rate_limits[0], nominal.rate_min[i])
            rate_max[i] = min(h.rate_limits[1], nominal.rate_max[i])
    if not (np.array_equal(rate_min, p.rate_min) and np.array_equal(rate_max, p.rate_max)):
        p = p.replace(rate_min=rate_min, rate_max=rate_max)
    return p


def health_to_dict(health: Mapping[str, EffectorHealth]) -> dict[str, Any]:
    """JSON form of a vehicle's health: ``{effector name: EffectorHealth.to_dict()}``."""
    return {name: h.to_dict() for name, h in health.items()}


def health_from_dict(data: Mapping[str, Any] | None) -> Health:
    """Inverse of :func:`health_to_dict`; ProblemError naming the field for anything else."""
    if data is None:
        return {}
    if not isinstance(data, Mapping):
        raise ProblemError(f"health: expected an object of effector name to health, got {type(data).__name__}")
    out = {}
    for name, h in data.items():
        if not isinstance(name, str):
            raise ProblemError(f"health: effector names must be strings, got {short_repr(name)}")
        try:
            out[name] = EffectorHealth.from_dict(h)
        except ProblemError as exc:
            raise ProblemError(f"{exc} (effector {name!r})", field=exc.field) from None
    return out
