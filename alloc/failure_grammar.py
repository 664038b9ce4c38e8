"""One way to write a failure as text: ``<kind>:<effector>[@<value>[:<value>...]]``, several joined by ``+``.

Beside the failure-kind table (:mod:`alloc.health`), and read from it: a ``kind`` is a row
of :data:`alloc.health.FAILURE_KINDS` (registered kinds included) or a per-actuator row of
:data:`alloc.health.SIMULATOR_ONLY` (``bandwidth``); the values after ``@`` fill the row's
parameters in its order, and a parameter left out takes the row's default.  So

* ``float:motor1`` -- rotor 1 trails (no control power);
* ``jam:elevon_l@5`` -- the left elevon stuck at 5 (a jam with no value holds where the
  surface is at the instant of failure: a simulator's default);
* ``effectiveness:elevon_l@0.25+limits:lef_l@-10:10`` -- two failures at once;
* ``bandwidth:pitch_tv@10`` -- a slower actuator (simulator only, never told).

Every tool that names a failure by text (``alloc sim --failure``, a vehicle file, the
comparison sweep's catalogue, the service's events) parses it here and writes it with
:func:`format_failure`; none of them re-lists the kinds.  An error is an
:class:`~alloc.exceptions.AllocError` (``ProblemError``) whose field is ``failure`` and whose
message names the part, the reason and what is known (kinds, effector names).
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

from .domain import short_repr
from .exceptions import ProblemError
from .health import SIMULATOR_ONLY, FailureKind, check_parameters

__all__ = ["GRAMMAR", "MAX_PARTS", "MAX_TEXT", "EffectorFailure", "failure_kinds", "format_failure", "parse_failure"]

#: the grammar, as messages and help texts quote it
GRAMMAR = "<kind>:<effector>[@<value>[:<value>...]] (several joined by '+'), e.g. jam:elevon_l@5, float:motor1"
#: the longest failure text read (a failure names a few effectors; a megabyte of text is no failure)
MAX_TEXT = 4096
#: the most effector failures one text joins
MAX_PARTS = 64
FIELD = "failure"

# ASCII digits only: float() also reads "1_0", " 5", "inf", "nan" and other scripts' digits
_NUMBER = re.compile(r"[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?")
_SEPARATORS = ("+", "@")


@dataclass(frozen=True)
class EffectorFailure:
    """One failure of one effector as text names it: ``kind``, ``effector`` (a name) and the values given.

    ``params`` maps the kind's parameters to values, in the row's order, the first ones only
    (what the text gave; the rest take their defaults where the failure is applied).
    """

    kind: str
    effector: str
    params: Mapping[str, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        object.__setattr__(self, "params", MappingProxyType(dict(self.params)))

    def text(self) -> str:
        """This failure in the grammar (:func:`format_failure` of it alone)."""
        return format_failure((self,))


def _error(part: str, reason: str) -> ProblemError:
    where = f"{short_repr(part)}: " if part else ""
    return ProblemError(f"failure: {where}{reason}", field=FIELD)


def failure_kinds() -> tuple[str, ...]:
    """Every kind the grammar takes: the table's (registered ones included), then the per-actuator simulator-only."""
    return (*(k.value for k in FailureKind), *(k for k, s in SIMULATOR_ONLY.items() if s.per_actuator))


def _spec(kind: str, part: str) -> Any:
    if kind in SIMULATOR_ONLY and SIMULATOR_ONLY[kind].per_actuator:
        return SIMULATOR_ONLY[kind]
    if kind in FailureKind:
        return FailureKind(kind).spec
    raise _error(part, f"unknown kind {short_repr(kind)}; kinds: {', '.join(failure_kinds())}; expected {GRAMMAR}")


def _number(text: str, param: str, part: str) -> float:
    if not _NUMBER.fullmatch(text):  # fullmatch: '$' would let a trailing newline through
        raise _error(part, f"{param} {short_repr(text)} is not a finite number (digits, optional sign, "
                           "decimal point and exponent)")
    value = float(text)
    if not math.isfinite(value):  # 1e999
        raise _error(part, f"{param} {short_repr(text)} is not finite")
    return value


def _check(failure: EffectorFailure, part: str, spec: Any, names: Sequence[str] | None,
           limits: Sequence[tuple[float, float]] | None, rate_limits: Sequence[tuple[float, float]] | None) -> None:
    """The effector is one of ``names`` and each value inside its range (the effector's limits when given)."""
    i = None
    if names is not None:
        if failure.effector not in names:
            raise _error(part, f"unknown effector {short_repr(failure.effector)}; effectors: {', '.join(names)}")
        i = list(names).index(failure.effector)

    def pair(bounds: Sequence[tuple[float, float]] | None) -> tuple[float, float] | None:
        return None if bounds is None or i is None else (float(bounds[i][0]), float(bounds[i][1]))

    try:
        check_parameters(spec.name, failure.params, effector=failure.effector, limits=pair(limits),
                         rate_limits=pair(rate_limits))
    except ProblemError as exc:
        raise _error(part, str(exc)) from None


def parse_failure(text: object, effectors: Sequence[str] | None = None, *,
                  limits: Sequence[tuple[float, float]] | None = None,
                  rate_limits: Sequence[tuple[float, float]] | None = None) -> tuple[EffectorFailure, ...]:
    """The effector failures ``text`` names (:data:`GRAMMAR`), in its order.

    Parameters
    ----------
    text : str
        ``kind:effector@v1:v2+kind:effector...``; surrounding blanks are ignored.
    effectors : sequence of str, optional
        The vehicle's effector names: an effector not among them is refused (the message lists them).
    limits, rate_limits : sequence of (lo, hi), optional
        Each effector's nominal position and rate limits (in ``effectors`` order): a position
        or a reduced limit outside them is refused.

    Raises
    ------
    ProblemError
        field ``failure``: not a string, empty or too long, an unknown kind or effector, too
        many values, a value that is no finite number or lies outside its range.
    """
    if not isinstance(text, str):
        raise _error("", f"expected text, {GRAMMAR}; got {type(text).__name__} {short_repr(text)}")
    if len(text) > MAX_TEXT:
        raise _error("", f"{len(text)} characters; a failure text has at most {MAX_TEXT}")
    text = text.strip()
    if not text:
        raise _error("", f"empty; expected {GRAMMAR}")
    parts = text.split("+")
    if len(parts) > MAX_PARTS:
        raise _error("", f"{len(parts)} failures joined; at most {MAX_PARTS}")
    out = []
    for part in parts:
        kind, sep, rest = part.partition(":")
        spec = _spec(kind, part)
        effector, at, values = rest.partition("@")
        if not sep or not effector:
            raise _error(part, f"no effector; expected {GRAMMAR}")
        given = values.split(":") if at else []
        if len(given) > len(spec.params):
            takes = ", ".join(spec.params) or "no value"
            raise _error(part, f"{len(given)} values; {kind} takes {takes}")
        params = {p: _number(v, p, part) for p, v in zip(spec.params, given, strict=False)}
        failure = EffectorFailure(spec.name, effector, params)
        _check(failure, part, spec, effectors, limits, rate_limits)
        for name, default in spec.params.items():
            if default is None and name not in params:
                raise _error(part, f"{name} is required: {kind} takes {', '.join(spec.params)}")
        out.append(failure)
    return tuple(out)


def _format_number(value: float) -> str:
    """The shortest text that reads back as the same float (``15`` for 15.0, ``30.000000000000004`` kept)."""
    if value == int(value) and abs(value) < 1e15:
        return "-0" if value == 0.0 and math.copysign(1.0, value) < 0 else str(int(value))
    return repr(value)


def format_failure(failures: Sequence[EffectorFailure] | EffectorFailure) -> str:
    """``failures`` as :data:`GRAMMAR` text; :func:`parse_failure` reads it back to equal failures.

    Raises
    ------
    ProblemError
        field ``failure``: no failures, an unknown kind, an effector name the grammar cannot
        write (empty, or holding ``+`` or ``@``), parameters that are not the first ones of the
        kind's row in its order, or a value that is no finite number.
    """
    if isinstance(failures, EffectorFailure):
        failures = (failures,)
    if not isinstance(failures, Sequence) or not failures:
        raise _error("", f"nothing to write: expected one or more alloc.failure_grammar.EffectorFailure, got "
                         f"{short_repr(failures)}")
    if len(failures) > MAX_PARTS:
        raise _error("", f"{len(failures)} failures joined; at most {MAX_PARTS}")
    parts = []
    for f in failures:
        if not isinstance(f, EffectorFailure):
            raise _error("", f"expected an alloc.failure_grammar.EffectorFailure, got {type(f).__name__}")
        spec = _spec(f.kind, str(f.kind))
        name = f.effector
        if not isinstance(name, str) or not name or any(s in name for s in _SEPARATORS):
            raise _error(str(f.kind), f"effector {short_repr(name)} cannot be written: a name is non-empty "
                                      "and has no '+' or '@'")
        order = list(spec.params)
        if list(f.params) != order[:len(f.params)]:
            raise _error(str(f.kind), f"parameters {list(f.params)} are not the first of {order}, in that order")
        values = []
        for p, v in f.params.items():
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise _error(str(f.kind), f"{p} {short_repr(v)} is not a finite number")
            values.append(_format_number(float(v)))
        parts.append(f"{spec.name}:{name}" + (f"@{':'.join(values)}" if values else ""))
    return "+".join(parts)
