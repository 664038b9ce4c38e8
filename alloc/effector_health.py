"""What has failed on each effector, and the allocation problem that health gives.

:class:`EffectorHealth` is an effector's state after its failure events (what
:mod:`alloc.health`'s told rules write); ``Problem.with_health`` is what an allocator is told,
with the precedence stated in :mod:`alloc.health`.  Import these names
from :mod:`alloc.health`, which defines the failure kinds and re-exports them.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from .domain import as_real, short_repr
from .exceptions import ProblemError

__all__ = ["EffectorHealth", "HEALTHY", "Health", "EFFECTOR_HEALTH_SCHEMA", "health_to_dict", "health_from_dict"]


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
        are ``Problem.with_health``'s to check.
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


def _checked_health(health: Any) -> Mapping[Any, EffectorHealth]:
    """``health`` if it maps effectors to :class:`EffectorHealth`; ProblemError naming it otherwise."""
    if not isinstance(health, Mapping):
        raise ProblemError(f"health: expected a mapping of effector to EffectorHealth, got {type(health).__name__}")
    for key, h in health.items():
        if not isinstance(h, EffectorHealth):
            raise ProblemError(f"health: the health of {short_repr(key)} must be an alloc.health.EffectorHealth, "
                               f"got {type(h).__name__}")
    return health


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
