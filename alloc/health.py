"""Effector health: failure kinds defined once, in one specification table.

This is the single definition of "what failed" used by the library
(:meth:`alloc.Problem.with_health`), the simulator (what a failure does to an actuator,
and the problem a told allocator gets), the service (vehicle health events and their JSON
schema) and the comparison sweep (its failure catalogue).  Each of them iterates the table
(:data:`FAILURE_KINDS`) and dispatches on its columns; none of them lists the kinds.

One entry (:class:`KindSpec`) per failure kind gives

``name``        the kind's one name, everywhere (library, simulator, service, sweep);
``params``      its parameters (from :data:`PARAMETERS`: unit, range) and whether each is
                required or what it defaults to (:class:`Default`);
``effects``     what it does to the actuator (:class:`Effect`: an effect the simulator
                executes, e.g. hold at a position, run to a stop, trail, scale effectiveness);
``told``        what an allocator is told (:class:`Told`: how the effector's
                :class:`EffectorHealth`, hence ``Problem.with_health``, changes);
``example``     the parameters of an example event (an effector with limits ``[-1, 1]`` and
                rate limits ``[-20, 20]`` or wider).

The built-in kinds (see :data:`FAILURE_KINDS` for their parameters):

``jam``            the surface is stuck at ``position`` (within the nominal limits); the
                   allocator holds it there: ``umin = umax = position``.  A simulator may omit
                   ``position``: it is then the surface's position at the instant of failure,
                   and a told allocator is told that same number.
``hardover``       the surface runs to a stop at its rate limit and stays there: a jam at
                   ``position``, by default the nominal upper limit (seed section 4.7).
``float``          the surface trails with the flow: it produces no controlled moment and
                   cannot be commanded.  Told: effectiveness 0 *and* held at its preferred
                   position ``up``, so allocators neither count on it nor move it.
``effectiveness``  loss of effectiveness: its column of ``B`` scaled by ``fraction`` in
                   [0, 1] (replaces, does not compound, an earlier fraction).
``limits``         reduced position limits ``[lo, hi]`` within the nominal ones.
``rate_limits``    reduced rate limits ``[rate_min, rate_max]`` within the nominal ones.
``repair``         back to healthy: clears every failure of that effector.

Precedence when several apply to one effector: ``float`` overrides a jam and a jam
overrides reduced limits (between ``float`` and a jam the latest event wins);
effectiveness and rate limits combine with any of them.

A new kind is one :func:`register_failure_kind` call with its :class:`KindSpec`; an entry
without an effect or a told rule, a parameter no effect or rule reads, or an example that
misses a required parameter raises :class:`FailureKindError` there, at registration
(the built-in entries are registered at import), never later at run time.

Changes of actuator *dynamics* (reduced bandwidth, added delay) are not expressible in a
static allocation problem: they have their own small table, :data:`SIMULATOR_ONLY`, whose
entries the simulator executes and which are never told to an allocator.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field, fields, replace
from enum import Enum
from types import MappingProxyType
from typing import Any, ClassVar

import numpy as np

from .domain import as_real, short_repr
from .effector_health import (
    EFFECTOR_HEALTH_SCHEMA, HEALTHY, EffectorHealth, Health, _checked_health, health_from_dict, health_to_dict,
)
from .exceptions import AllocError, ProblemError
from .problem import Problem

__all__ = [
    "FailureKind", "FailureEvent", "EffectorHealth", "HEALTHY", "Health",
    "apply_event", "apply_health", "health_to_dict", "health_from_dict", "EFFECTOR_HEALTH_SCHEMA",
    "FAILURE_KINDS", "SIMULATOR_ONLY", "PARAMETERS", "KindSpec", "SimulatorOnlySpec", "Parameter", "Range",
    "Default", "Effect", "Told", "EFFECT_READS", "TOLD_READS", "FailureKindError", "register_failure_kind",
    "resolve_event", "check_parameters",
]


class FailureKindError(AllocError, ValueError):
    """A failure kind's table entry is incomplete or inconsistent, or a kind is registered twice."""


# ------------------------------------------------------------------- the columns' vocabularies
class Range(str, Enum):
    """Where a parameter's value must lie; the ``POSITION`` and ``RATE_*`` ranges need the
    effector's nominal problem (checked by :func:`check_parameters`)."""

    POSITION = "within the effector's nominal position limits"
    FRACTION = "[0, 1]"
    RATE_MIN = "[nominal rate_min, 0]"
    RATE_MAX = "[0, nominal rate_max]"
    POSITIVE = "> 0"
    NON_NEGATIVE = ">= 0"


class Default(str, Enum):
    """What an omitted parameter means (a parameter with no default is required)."""

    #: the effector's nominal upper position limit
    UPPER_LIMIT = "the nominal upper limit"
    #: the actuator's position when the failure happens.  Only a simulator knows it (it records
    #: the number and tells the allocator that number); an event given to the library or the
    #: service must carry it.
    AT_FAILURE = "the position at the instant of failure (simulator only; required elsewhere)"


class Effect(str, Enum):
    """What a failure does to the actuator: each is an effect the simulator executes
    (:meth:`sim.blocks.ActuatorBank.apply_failure`), reading the parameters in :data:`EFFECT_READS`."""

    HOLD = "held at position, rate 0, from the instant of failure"
    RUN_TO_STOP = "commanded to position, reached at its rate limit, and stays there"
    TRAIL = "trails with the flow: no control power (effectiveness 0), moves freely"
    SCALE = "control power times fraction"
    LIMITS = "position limits [lo, hi]"
    RATE_LIMITS = "rate limits [rate_min, rate_max]"
    REPAIR = "nominal again: every failure of the actuator cleared"
    #: simulator only (:data:`SIMULATOR_ONLY`): a change of dynamics, never told
    BANDWIDTH = "natural frequency wn, same damping"
    #: simulator only (:data:`SIMULATOR_ONLY`): a change of dynamics, never told
    DELAY = "added actuator time delay"


#: the parameters each effect reads
EFFECT_READS: Mapping[Effect, tuple[str, ...]] = MappingProxyType({
    Effect.HOLD: ("position",), Effect.RUN_TO_STOP: ("position",), Effect.TRAIL: (), Effect.SCALE: ("fraction",),
    Effect.LIMITS: ("lo", "hi"), Effect.RATE_LIMITS: ("rate_min", "rate_max"), Effect.REPAIR: (),
    Effect.BANDWIDTH: ("wn",), Effect.DELAY: ("delay",),
})
#: effects a static allocation problem cannot express (only :data:`SIMULATOR_ONLY` entries use them)
_DYNAMICS = frozenset({Effect.BANDWIDTH, Effect.DELAY})


class Told(str, Enum):
    """What an allocator is told: how the effector's :class:`EffectorHealth` changes (and so
    what :meth:`alloc.Problem.with_health` gives), reading the parameters in :data:`TOLD_READS`."""

    HELD = "held at position: umin = umax = position (a jam; clears floating)"
    FLOATING = "floating: effectiveness 0 and held at its preferred position up (clears a jam)"
    EFFECTIVENESS = "its column of B scaled by fraction"
    LIMITS = "position limits [lo, hi]"
    RATE_LIMITS = "rate limits [rate_min, rate_max]"
    HEALTHY = "healthy: every failure cleared"


#: the parameters each told rule reads
TOLD_READS: Mapping[Told, tuple[str, ...]] = MappingProxyType({
    Told.HELD: ("position",), Told.FLOATING: (), Told.EFFECTIVENESS: ("fraction",), Told.LIMITS: ("lo", "hi"),
    Told.RATE_LIMITS: ("rate_min", "rate_max"), Told.HEALTHY: (),
})


@dataclass(frozen=True)
class Parameter:
    """One failure parameter: its unit, range and meaning (``after``: must be >= that one)."""

    name: str
    unit: str
    range: Range
    description: str
    after: str | None = None


#: every parameter a told failure kind can take (the fields of :class:`FailureEvent`)
PARAMETERS: Mapping[str, Parameter] = MappingProxyType({p.name: p for p in (
    Parameter("position", "effector unit (deg for a surface)", Range.POSITION, "where the surface stays"),
    Parameter("fraction", "1", Range.FRACTION, "fraction of the nominal column of B left"),
    Parameter("lo", "effector unit", Range.POSITION, "reduced lower position limit"),
    Parameter("hi", "effector unit", Range.POSITION, "reduced upper position limit", after="lo"),
    Parameter("rate_min", "effector unit/s", Range.RATE_MIN, "reduced lower rate limit"),
    Parameter("rate_max", "effector unit/s", Range.RATE_MAX, "reduced upper rate limit"),
)})

#: the parameters of the simulator-only effects (never told, so never a :class:`FailureEvent` field)
SIMULATOR_PARAMETERS: Mapping[str, Parameter] = MappingProxyType({p.name: p for p in (
    Parameter("wn", "rad/s", Range.POSITIVE, "new natural frequency of the actuator"),
    Parameter("delay", "s", Range.NON_NEGATIVE, "actuator time delay after the failure (scalar or per effector)"),
)})


# ------------------------------------------------------------------------------ the table
@dataclass(frozen=True)
class KindSpec:
    """One row of the specification table (see the module docstring for each column).

    ``params`` maps each parameter (a key of :data:`PARAMETERS`) to its :class:`Default`, or to
    ``None`` when it is required.  ``effects`` and ``told`` apply in order.
    """

    name: str
    meaning: str
    params: Mapping[str, Default | None]
    effects: tuple[Effect, ...]
    told: tuple[Told, ...]
    example: Mapping[str, float] = field(default_factory=dict)

    @property
    def required(self) -> tuple[str, ...]:
        """Parameters an event given to the library or the service must carry."""
        return tuple(n for n, d in self.params.items() if d is None or d is Default.AT_FAILURE)

    def parameter(self, name: str) -> Parameter:
        return PARAMETERS[name]


@dataclass(frozen=True)
class SimulatorOnlySpec:
    """One row of :data:`SIMULATOR_ONLY`: an effect on actuator dynamics that a static allocation
    problem cannot express, executed by the simulator and never told to an allocator.

    ``per_actuator``: a kind of :class:`sim.blocks.ActuatorFailure` (else a field of the whole
    failure, :class:`sim.model.Failure`)."""

    name: str
    meaning: str
    params: Mapping[str, Default | None]
    effects: tuple[Effect, ...]
    per_actuator: bool

    @property
    def required(self) -> tuple[str, ...]:
        return tuple(n for n, d in self.params.items() if d is None)

    def parameter(self, name: str) -> Parameter:
        return SIMULATOR_PARAMETERS[name]


_NAME = re.compile(r"^[a-z][a-z0-9_]{1,30}$")


def _refuse(spec: Any, reason: str) -> FailureKindError:
    return FailureKindError(f"kind: failure kind {getattr(spec, 'name', spec)!r}: {reason}", field="kind")


def _check_columns(spec: Any, known: Mapping[str, Parameter], reads: Mapping[Any, tuple[str, ...]],
                   rules: tuple[Any, ...]) -> None:
    """The consistency of one entry: a name, a meaning, effects, parameters that exist and are read."""
    if not (isinstance(spec.name, str) and _NAME.match(spec.name)):
        raise _refuse(spec, "a name is 2-31 lower-case letters, digits or underscores, first a letter")
    if not (isinstance(spec.meaning, str) and spec.meaning.strip()):
        raise _refuse(spec, "no meaning: say in one sentence what failed")
    if not (isinstance(spec.effects, tuple) and spec.effects and all(isinstance(e, Effect) for e in spec.effects)):
        raise _refuse(spec, "no actuator effect: give a non-empty tuple of alloc.health.Effect (what the "
                            "simulator does to the actuator)")
    if not isinstance(spec.params, Mapping):
        raise _refuse(spec, "params must map parameter names to a Default or None (required)")
    for name, default in spec.params.items():
        if name not in known:
            raise _refuse(spec, f"unknown parameter {short_repr(name)}; known: {', '.join(known)}")
        if default is not None and not isinstance(default, Default):
            raise _refuse(spec, f"parameter {name!r}: its default must be an alloc.health.Default or None")
        after = known[name].after
        if after is not None and after not in spec.params:
            raise _refuse(spec, f"parameter {name!r} is ordered after {after!r}, which the kind does not take")
    read = {p for e in spec.effects for p in EFFECT_READS[e]} | {p for r in rules for p in reads[r]}
    missing = sorted(read - set(spec.params))
    if missing:
        raise _refuse(spec, f"its effects or told rules read {missing}, which are not among its params")
    unused = sorted(set(spec.params) - read)
    if unused:
        raise _refuse(spec, f"parameter(s) {unused} read by none of its effects or told rules")


def _check_spec(spec: Any) -> KindSpec:
    if not isinstance(spec, KindSpec):
        raise _refuse(spec, f"expected an alloc.health.KindSpec, got {type(spec).__name__}")
    if not (isinstance(spec.told, tuple) and spec.told and all(isinstance(t, Told) for t in spec.told)):
        raise _refuse(spec, "no told rule: give a non-empty tuple of alloc.health.Told (what an allocator is "
                            "told); a change of dynamics that cannot be told belongs in SIMULATOR_ONLY")
    _check_columns(spec, PARAMETERS, TOLD_READS, spec.told)
    dynamics = sorted(e.name for e in spec.effects if e in _DYNAMICS)
    if dynamics:
        raise _refuse(spec, f"effect(s) {dynamics} change actuator dynamics: simulator-only (SIMULATOR_ONLY)")
    if Default.AT_FAILURE in spec.params.values() and not {Effect.HOLD, Effect.RUN_TO_STOP} & set(spec.effects):
        raise _refuse(spec, "a position at the instant of failure is a default only for a held or run-to effect")
    if not isinstance(spec.example, Mapping) or set(spec.required) - set(spec.example) \
            or set(spec.example) - set(spec.params):
        raise _refuse(spec, f"its example must give every required parameter {list(spec.required)} and no other "
                            f"than {list(spec.params)}, got {short_repr(spec.example)}")
    for name, value in spec.example.items():
        try:
            as_real(name, value)
        except ProblemError as exc:
            raise _refuse(spec, f"example: {exc}") from None
    return spec


#: the specification table: kind name -> its entry (see :func:`register_failure_kind`)
_TABLE: dict[str, KindSpec] = {}


class _KindsMeta(type):
    """Iterating :class:`FailureKind` lists the registered kinds, in table order."""

    def __iter__(cls) -> Iterator[FailureKind]:
        return iter([spec.name for spec in _TABLE.values()])  # type: ignore[misc]

    def __len__(cls) -> int:
        return len(_TABLE)

    def __contains__(cls, value: object) -> bool:
        return isinstance(value, str) and value in _TABLE


class FailureKind(str, metaclass=_KindsMeta):
    """A registered failure kind's name: a ``str`` that only takes the table's names.

    ``FailureKind("jam")`` is the registered kind (the same object every time) or ValueError;
    ``list(FailureKind)`` is every registered kind; ``kind.spec`` is its :class:`KindSpec`.
    The built-in kinds are also ``FailureKind.JAM``, ``FailureKind.HARDOVER``, ...
    """

    __slots__ = ()
    JAM: ClassVar[FailureKind]
    HARDOVER: ClassVar[FailureKind]
    FLOAT: ClassVar[FailureKind]
    EFFECTIVENESS: ClassVar[FailureKind]
    LIMITS: ClassVar[FailureKind]
    RATE_LIMITS: ClassVar[FailureKind]
    REPAIR: ClassVar[FailureKind]

    def __new__(cls, value: object) -> FailureKind:
        spec = _TABLE.get(value) if isinstance(value, str) else None
        if spec is None:
            raise ValueError(f"{short_repr(value)} is not a failure kind; registered: {', '.join(_TABLE)}")
        return spec.name  # type: ignore[return-value]

    @property
    def value(self) -> str:
        """The plain name (as an Enum's ``value``)."""
        return str.__str__(self)

    @property
    def spec(self) -> KindSpec:
        """The kind's row of the specification table."""
        return _TABLE[self]

    def __repr__(self) -> str:  # as its name, so messages read "a 'jam' failure"
        return repr(self.value)

    def __reduce__(self) -> tuple[Any, ...]:
        return FailureKind, (self.value,)


def register_failure_kind(spec: KindSpec) -> FailureKind:
    """Add one row to the specification table; return its :class:`FailureKind`.

    Every consumer (``Problem.with_health``, the simulator's actuators and told allocators, the
    service's event schema, the sweep's catalogue) reads the table, so this is the whole of
    adding a kind.  Raises :class:`FailureKindError` naming the gap for an incomplete or
    inconsistent entry (no effect, no told rule, an unread or unknown parameter, an example
    without a required parameter) or a name already taken, here and not at run time.
    """
    spec = _check_spec(spec)
    if spec.name in _TABLE or spec.name in SIMULATOR_ONLY:
        raise _refuse(spec, "already registered")
    kind = str.__new__(FailureKind, spec.name)
    _TABLE[spec.name] = replace(spec, name=kind, params=MappingProxyType(dict(spec.params)),
                                example=MappingProxyType(dict(spec.example)))
    return kind


def _kind(value: Any) -> FailureKind:
    if not (isinstance(value, str) and value in _TABLE):  # no repr of an arbitrary object
        raise ProblemError(f"kind: unknown failure kind {short_repr(value)}; expected one of {', '.join(_TABLE)}")
    return FailureKind(value)


#: simulator-only effects, never told to an allocator (no told rule: a static problem cannot express them)
SIMULATOR_ONLY: Mapping[str, SimulatorOnlySpec] = MappingProxyType({s.name: s for s in (
    SimulatorOnlySpec("bandwidth", "the actuator is slower: natural frequency wn (seed section 4.7 failure list)",
                      {"wn": None}, (Effect.BANDWIDTH,), per_actuator=True),
    SimulatorOnlySpec("delay", "an added actuator time delay (sim.model.Failure.delay: scalar or one per effector)",
                      {"delay": None}, (Effect.DELAY,), per_actuator=False),
)})
for _spec in SIMULATOR_ONLY.values():
    _check_columns(_spec, SIMULATOR_PARAMETERS, {}, ())
    if not set(_spec.effects) <= _DYNAMICS:
        raise _refuse(_spec, "a simulator-only entry changes dynamics only")


# ------------------------------------------------------------------------ parameter checks
def check_parameters(kind: FailureKind | str, params: Mapping[str, float], *, effector: str = "",
                     limits: tuple[float, float] | None = None,
                     rate_limits: tuple[float, float] | None = None) -> None:
    """Each given parameter inside its :class:`Range` (ProblemError naming it otherwise).

    ``limits`` and ``rate_limits`` are the effector's nominal ones; without them only what needs
    no problem is checked (fractions, signs of rate limits, order).  ``kind`` may also be a
    :data:`SIMULATOR_ONLY` name.
    """
    spec: Any = SIMULATOR_ONLY[kind] if kind in SIMULATOR_ONLY else _kind(kind).spec
    of = f" of {effector!r}" if effector else ""
    for name, value in params.items():
        p = spec.parameter(name)
        if p.after is not None and params.get(p.after) is not None and params[p.after] > value:
            raise ProblemError(f"{name}: {spec.name} out of order: {p.after} = {params[p.after]:g} > "
                               f"{name} = {value:g}")
        r = p.range
        if r is Range.FRACTION and not 0.0 <= value <= 1.0:
            raise ProblemError(f"{name}: {spec.name} {name} {value:g}{of} must be in [0, 1]")
        if r is Range.POSITIVE and not value > 0.0:
            raise ProblemError(f"{name}: {spec.name} {name} {value:g}{of} must be > 0")
        if r is Range.NON_NEGATIVE and not value >= 0.0:
            raise ProblemError(f"{name}: {spec.name} {name} {value:g}{of} must be >= 0")
        if r is Range.RATE_MIN and value > 0.0 or r is Range.RATE_MAX and value < 0.0:
            raise ProblemError(f"{name}: {spec.name} {name} {value:g}{of} must satisfy rate_min <= 0 <= rate_max")
        if r is Range.POSITION and limits is not None and not limits[0] <= value <= limits[1]:
            raise ProblemError(f"{name}: {spec.name} {name} {value:g}{of} outside its nominal limits "
                               f"[{limits[0]:g}, {limits[1]:g}]")
        if rate_limits is not None and (r is Range.RATE_MIN and value < rate_limits[0]
                                        or r is Range.RATE_MAX and value > rate_limits[1]):
            raise ProblemError(f"{name}: {spec.name} {name} {value:g}{of} outside its nominal rate limits "
                               f"[{rate_limits[0]:g}, {rate_limits[1]:g}]")


def resolve_defaults(spec: Any, params: Mapping[str, float], *, limits: tuple[float, float],
                     position: float | None = None) -> dict[str, float]:
    """``params`` with every omitted parameter that has a :class:`Default` filled in.

    ``limits``: the effector's nominal position limits; ``position``: the actuator's position at
    the instant of failure (a simulator's; without it a parameter defaulting to it is required).
    """
    out = dict(params)
    for name, default in spec.params.items():
        if out.get(name) is not None or default is None:
            continue
        if default is Default.UPPER_LIMIT:
            out[name] = float(limits[1])
        elif position is not None:  # Default.AT_FAILURE
            out[name] = float(position)
        else:
            raise ProblemError(f"{name}: required for a {spec.name!r} failure ({default.value})")
    return out


#: what each told rule does to an effector's health (``p``: the event's resolved parameters)
_TELL: Mapping[Told, Callable[[EffectorHealth, Mapping[str, float]], EffectorHealth]] = MappingProxyType({
    Told.HELD: lambda old, p: replace(old, jam_position=p["position"], floating=False),
    Told.FLOATING: lambda old, p: replace(old, floating=True, jam_position=None),
    Told.EFFECTIVENESS: lambda old, p: replace(old, effectiveness=p["fraction"]),
    Told.LIMITS: lambda old, p: replace(old, limits=(p["lo"], p["hi"])),
    Told.RATE_LIMITS: lambda old, p: replace(old, rate_limits=(p["rate_min"], p["rate_max"])),
    Told.HEALTHY: lambda old, p: HEALTHY,
})

# Every effect and told rule has its reads, every told rule its change: a new member without
# them fails here, at import.
for _column, _members in ((EFFECT_READS, Effect), (TOLD_READS, Told), (_TELL, Told)):
    if set(_column) != set(_members):
        raise FailureKindError(f"kind: {sorted(m.name for m in set(_members) - set(_column))} have no entry "
                               f"in alloc.health's {'EFFECT_READS' if _column is EFFECT_READS else 'told columns'}")

#: the built-in kinds, in report order (the module docstring says what each means)
for _spec in (
    KindSpec("jam", "the surface is stuck at position", {"position": Default.AT_FAILURE},
             (Effect.HOLD,), (Told.HELD,), example={"position": 0.5}),
    KindSpec("hardover", "the surface ran to a stop and stays there (a jam at position, default the upper limit)",
             {"position": Default.UPPER_LIMIT}, (Effect.RUN_TO_STOP,), (Told.HELD,)),
    KindSpec("float", "the surface trails with the flow: no controlled moment, cannot be commanded",
             {}, (Effect.TRAIL,), (Told.FLOATING,)),
    KindSpec("effectiveness", "loss of effectiveness: its column of B scaled by fraction",
             {"fraction": None}, (Effect.SCALE,), (Told.EFFECTIVENESS,), example={"fraction": 0.6}),
    KindSpec("limits", "reduced position limits [lo, hi] within the nominal ones",
             {"lo": None, "hi": None}, (Effect.LIMITS,), (Told.LIMITS,), example={"lo": -0.5, "hi": 0.5}),
    KindSpec("rate_limits", "reduced rate limits [rate_min, rate_max] within the nominal ones",
             {"rate_min": None, "rate_max": None}, (Effect.RATE_LIMITS,), (Told.RATE_LIMITS,),
             example={"rate_min": -20.0, "rate_max": 20.0}),
    KindSpec("repair", "back to healthy: clears every failure of the effector", {}, (Effect.REPAIR,), (Told.HEALTHY,)),
):
    setattr(FailureKind, _spec.name.upper(), register_failure_kind(_spec))

#: the specification table, read-only and live (kind name -> :class:`KindSpec`, in registration order)
FAILURE_KINDS: Mapping[str, KindSpec] = MappingProxyType(_TABLE)


@dataclass(frozen=True, slots=True)
class FailureEvent:
    """One failure (or repair) of one effector.

    ``kind`` is a registered :class:`FailureKind`; the parameters it takes, their units, ranges
    and defaults are its row of the table (:data:`FAILURE_KINDS`): ``jam`` needs ``position``;
    ``hardover`` takes an optional ``position`` (default the nominal upper limit);
    ``effectiveness`` needs ``fraction``; ``limits`` needs ``lo`` and ``hi``; ``rate_limits``
    needs ``rate_min`` and ``rate_max``; ``float`` and ``repair`` take none.  A parameter the
    kind does not take is refused.
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
        kind = _kind(self.kind)
        object.__setattr__(self, "kind", kind)
        spec = kind.spec
        for name in PARAMETERS:
            if getattr(self, name) is not None and name not in spec.params:
                takes = ", ".join(spec.params) or "no parameters"
                raise ProblemError(f"{name}: a {kind.value!r} failure does not take it (it takes {takes})")
        for name in spec.required:
            if getattr(self, name) is None:
                raise ProblemError(f"{name}: required for a {kind.value!r} failure")
        if isinstance(self.effector, (bool, np.bool_)) or not isinstance(self.effector, (int, np.integer, str)):
            raise ProblemError(f"effector: expected an index or a name, got {short_repr(self.effector)}")
        for name in PARAMETERS:
            value = getattr(self, name)
            if value is not None:
                object.__setattr__(self, name, as_real(name, value))

    @property
    def params(self) -> dict[str, float]:
        """The parameters given (name -> value)."""
        return {name: getattr(self, name) for name in self.kind.spec.params if getattr(self, name) is not None}


if set(PARAMETERS) != {f.name for f in fields(FailureEvent)} - {"effector", "kind"}:
    raise FailureKindError("kind: alloc.health.PARAMETERS and the fields of FailureEvent differ")


def apply_health(nominal: Problem, health: Mapping[int | str, EffectorHealth]) -> Problem:
    """The problem of a vehicle at ``health``: ``nominal.with_health(health)``, where the
    precedence of the kinds is applied (see :meth:`alloc.Problem.with_health`)."""
    return nominal.with_health(health)


def resolve_event(nominal: Problem, event: FailureEvent) -> FailureEvent:
    """``event`` checked against the nominal problem, its defaults filled in (a hard-over's stop).

    Raises
    ------
    ProblemError
        unknown effector, or a parameter outside its range (a position outside the nominal
        limits, reduced limits or rate limits outside the nominal ones, an effectiveness
        outside [0, 1]); the message names the field.
    """
    if not isinstance(event, FailureEvent):
        raise ProblemError(f"event: expected an alloc.health.FailureEvent, got {type(event).__name__}")
    i = nominal.index(event.effector)
    limits = float(nominal.umin[i]), float(nominal.umax[i])
    params = resolve_defaults(event.kind.spec, event.params, limits=limits)
    check_parameters(event.kind, params, effector=nominal.names[i], limits=limits,
                     rate_limits=(float(nominal.rate_min[i]), float(nominal.rate_max[i])))
    return replace(event, **params)


def apply_event(nominal: Problem, health: Mapping[str, EffectorHealth], event: FailureEvent) -> tuple[str, Health]:
    """Validate ``event`` against the nominal problem; return ``(effector name, new health)``.

    The new health is the old one changed by the kind's told rules, in order (:data:`FAILURE_KINDS`).

    Raises
    ------
    ProblemError
        anything :func:`resolve_event` rejects; the message names the field.
    """
    if not isinstance(event, FailureEvent):
        raise ProblemError(f"event: expected an alloc.health.FailureEvent, got {type(event).__name__}")
    health = _checked_health(health)
    event = resolve_event(nominal, event)
    name = nominal.names[nominal.index(event.effector)]
    new = health.get(name, HEALTHY)
    params = event.params
    for rule in event.kind.spec.told:
        new = _TELL[rule](new, params)
    out = dict(health)
    if new == HEALTHY:
        out.pop(name, None)
    else:
        out[name] = new
    return name, out
