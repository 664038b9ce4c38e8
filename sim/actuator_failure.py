"""An effector failure for the simulator: one row of the failure-kind tables with its parameters.

:class:`ActuatorFailure` takes the kinds of :data:`alloc.health.FAILURE_KINDS` and the
per-actuator rows of :data:`alloc.health.SIMULATOR_ONLY`; :class:`sim.blocks.ActuatorBank`
executes their effects.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from alloc.domain import as_real, short_repr
from alloc.exceptions import ProblemError
from alloc.health import PARAMETERS, SIMULATOR_ONLY, SIMULATOR_PARAMETERS, Effect, FailureKind, check_parameters

__all__ = ["ActuatorFailure"]


def _actuator_kind(kind: object) -> Any:
    """The table row of an actuator failure kind: a registered :class:`alloc.health.FailureKind`
    or a per-actuator :data:`alloc.health.SIMULATOR_ONLY` entry; ProblemError naming ``kind`` otherwise."""
    if isinstance(kind, str) and kind in SIMULATOR_ONLY and SIMULATOR_ONLY[kind].per_actuator:
        return SIMULATOR_ONLY[kind]
    if isinstance(kind, str) and kind in FailureKind:
        return FailureKind(kind).spec
    raise ProblemError(f"kind: unknown actuator failure kind {short_repr(kind)}; expected one of "
                       f"{', '.join(ActuatorFailure.KINDS)}")


class _ActuatorKinds:
    """``ActuatorFailure.KINDS``: the kinds an actuator failure takes, read from the tables when asked."""

    def __get__(self, obj: object, owner: type | None = None) -> tuple[str, ...]:
        return (*(k.value for k in FailureKind), *(k for k, s in SIMULATOR_ONLY.items() if s.per_actuator))


class ActuatorFailure:
    """Failure of one effector, applied at the scenario's failure time.

    ``kind`` is a row of :data:`alloc.health.FAILURE_KINDS` (``jam``, ``hardover``, ``float``,
    ``effectiveness``, ``limits``, ``rate_limits``, ``repair`` and any registered kind) or a
    per-actuator simulator-only row of :data:`alloc.health.SIMULATOR_ONLY` (``bandwidth``, natural
    frequency ``wn``; never told to an allocator).  The keyword parameters are the row's, with its
    units, ranges and defaults: ``ActuatorFailure(0, "jam", position=5.0)``.  What the failure
    does to the actuator is the row's effects (:meth:`ActuatorBank.apply_failure`); a jam given no
    ``position`` holds the position the actuator has at the instant of failure.  A parameter
    not given reads as ``None`` (``failure.position``).

    The simulator's actuators have one symmetric rate limit, so ``rate_limits`` here needs
    ``rate_min == -rate_max``.
    """

    __slots__ = ("index", "kind", "params")
    #: every kind an actuator failure takes (the told kinds, then the per-actuator simulator-only ones)
    KINDS = _ActuatorKinds()
    index: int
    kind: str
    params: dict[str, float]

    def __init__(self, index: int, kind: str, **params: float) -> None:
        spec = _actuator_kind(kind)
        if isinstance(index, (bool, np.bool_)) or not isinstance(index, (int, np.integer)) or index < 0:
            raise ProblemError(f"index: expected an effector index >= 0, got {short_repr(index)}")
        unknown = sorted(set(params) - set(spec.params))
        if unknown:
            takes = ", ".join(spec.params) or "no parameters"
            raise ProblemError(f"{unknown[0]}: a {spec.name!r} failure does not take it (it takes {takes})")
        values = {name: as_real(name, value) for name, value in params.items() if value is not None}
        for name, default in spec.params.items():
            if default is None and name not in values:
                raise ProblemError(f"{name}: required for a {spec.name!r} failure")
        check_parameters(spec.name, values)
        if Effect.RATE_LIMITS in spec.effects and values["rate_min"] != -values["rate_max"]:
            raise ProblemError(f"rate_min: the simulator's actuators have one symmetric rate limit; a "
                               f"{spec.name!r} failure needs rate_min = -rate_max, got [{values['rate_min']:g}, "
                               f"{values['rate_max']:g}]")
        setattr_ = object.__setattr__
        setattr_(self, "index", int(index))
        setattr_(self, "kind", spec.name)
        setattr_(self, "params", values)

    @property
    def spec(self) -> Any:
        """The kind's row (:class:`alloc.health.KindSpec` or :class:`alloc.health.SimulatorOnlySpec`)."""
        return _actuator_kind(self.kind)

    def __getattr__(self, name: str) -> float | None:
        if name in PARAMETERS or name in SIMULATOR_PARAMETERS:
            return self.params.get(name)
        raise AttributeError(f"ActuatorFailure has no attribute {name!r}")

    def __setattr__(self, name: str, value: object) -> None:
        raise AttributeError("ActuatorFailure is immutable")

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, ActuatorFailure):
            return NotImplemented
        return (self.index, self.kind, self.params) == (other.index, other.kind, other.params)

    def __hash__(self) -> int:
        return hash((self.index, str(self.kind), tuple(sorted(self.params.items()))))

    def __repr__(self) -> str:
        params = "".join(f", {k}={v!r}" for k, v in self.params.items())
        return f"ActuatorFailure({self.index}, {str(self.kind)!r}{params})"

    def __reduce__(self) -> tuple[Any, ...]:
        return _actuator_failure, (self.index, str(self.kind), self.params)


def _actuator_failure(index: int, kind: str, params: dict[str, float]) -> ActuatorFailure:
    return ActuatorFailure(index, kind, **params)
