"""Scheduled effectiveness: ``B`` as a declared function of named scheduling variables.

A tiltrotor's rotor columns turn with the tilt angle; a surface's effect grows with dynamic
pressure.  Format ``alloc-vehicle/1.2`` declares that dependence in a ``[schedule]`` section::

    [schedule]
    variables = [
      { name = "tilt", unit = "deg", min = 0.0, max = 90.0, nominal = 0.0 },
      { name = "airspeed", unit = "m/s", min = 0.0, max = 40.0, nominal = 15.0 },
    ]

    [[schedule.terms]]            # B(x) += (f(x) - f(nominal)) * B_term
    factor = "sin"                # sin | cos | linear | square
    variable = "tilt"
    scale = 1.0                   # f = sin(scale * x + offset), the angle in the variable's unit
    offset = 0.0
    B = [[...], ...]              # axes x effectors

    [[schedule.terms]]
    factor = "square"             # f = (scale * clamp(x, lo, hi) + offset)^2
    variable = "airspeed"
    scale = 0.0666667
    clamp = [7.0, 20.0]
    B = [[...], ...]

The effectiveness at ``x`` is::

    B(x) = B + sum_t (f_t(x) - f_t(nominal)) B_t

with ``B`` the file's own effectiveness, which is therefore the effectiveness at the nominal
values: every tool that knows nothing of schedules (the simulator, ``problem()``) sees the
vehicle at its nominal point; the service evaluates ``B`` at a request's ``at``.  Angles are read in the variable's unit: ``deg`` means
degrees, anything else radians.  Every term is linear in its ``B_t``, so a rotor whose axis
turns, ``a(t) = sin(t) h + cos(t) v``, is two terms: PX4's rotor column is linear in the axis
(:func:`alloc.vehicle_file.rotor_wrench`).

:class:`ScheduledEffectiveness` evaluates ``B(x)`` per call without building anything: the
terms are stacked once, a call computes the few factors and one matrix-vector product into a
buffer it owns (``benchmarks/bench_schedule.py`` measures it against a rebuild).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..exceptions import ProblemError
from ..problem import MAX_MAGNITUDE, short_repr
from .fields import Matrix, _fail, _keys, _list, _matrix, _real, _table, _text, _unique

__all__ = ["FACTORS", "MAX_TERMS", "MAX_VARIABLES", "Variable", "Term", "Schedule", "ScheduledEffectiveness"]

#: the factor functions a term may declare
FACTORS = ("sin", "cos", "linear", "square")
#: bounds checked on the document before any term is read (a tiltrotor needs 2 per tilt group + 1)
MAX_VARIABLES = 8
MAX_TERMS = 32


@dataclass(frozen=True)
class Variable:
    """A scheduling variable: its name, unit, admissible range and nominal value."""

    name: str
    unit: str
    min: float
    max: float
    nominal: float

    @classmethod
    def from_dict(cls, value: Any, path: str) -> Variable:
        t = _table(value, path)
        _keys(t, path, ("name", "unit", "min", "max", "nominal"), required=("name", "min", "max", "nominal"))
        name = _text(t["name"], f"{path}.name", name=True)
        lo, hi = _real(t["min"], f"{path}.min"), _real(t["max"], f"{path}.max")
        if not lo <= hi:
            raise _fail(f"{path}.max", f"must be >= min ({lo:g}), got {hi:g}")
        nominal = _real(t["nominal"], f"{path}.nominal")
        if not lo <= nominal <= hi:
            raise _fail(f"{path}.nominal", f"must be in [{lo:g}, {hi:g}], got {nominal:g}")
        return cls(name, _text(t.get("unit", ""), f"{path}.unit"), lo, hi, nominal)

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.name, "unit": self.unit, "min": self.min, "max": self.max, "nominal": self.nominal}


@dataclass(frozen=True)
class Term:
    """One term ``f(x) * B_t`` of a schedule (see the module docstring for ``f``)."""

    factor: str
    variable: str
    B: Matrix
    scale: float = 1.0
    offset: float = 0.0
    clamp: tuple[float, float] | None = None

    def value(self, x: float, unit: str) -> float:
        """``f(x)`` for a value ``x`` of the term's variable (whose unit is ``unit``)."""
        if self.clamp is not None:
            x = min(max(x, self.clamp[0]), self.clamp[1])
        y = self.scale * x + self.offset
        if self.factor == "sin":
            return math.sin(math.radians(y) if unit == "deg" else y)
        if self.factor == "cos":
            return math.cos(math.radians(y) if unit == "deg" else y)
        return y if self.factor == "linear" else y * y

    @classmethod
    def from_dict(cls, value: Any, path: str, variables: Sequence[str], k: int, m: int) -> Term:
        t = _table(value, path)
        _keys(t, path, ("factor", "variable", "scale", "offset", "clamp", "B"), required=("factor", "variable", "B"))
        factor = t["factor"]
        if factor not in FACTORS:
            raise _fail(f"{path}.factor", f"expected one of {', '.join(FACTORS)}, got {short_repr(factor)}")
        variable = t["variable"]
        if variable not in variables:
            raise _fail(f"{path}.variable", f"unknown {short_repr(variable)}; declared: {', '.join(variables)}")
        clamp = None
        if "clamp" in t:
            lo, hi = (_real(x, f"{path}.clamp[{i}]") for i, x in enumerate(_list(t["clamp"], f"{path}.clamp", 2)))
            if not lo <= hi:
                raise _fail(f"{path}.clamp", f"expected [low, high] with low <= high, got [{lo:g}, {hi:g}]")
            clamp = (lo, hi)
        return cls(factor, variable, _matrix(t["B"], f"{path}.B", k, m), _real(t.get("scale", 1.0), f"{path}.scale"),
                   _real(t.get("offset", 0.0), f"{path}.offset"), clamp)

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"factor": self.factor, "variable": self.variable, "scale": self.scale,
                               "offset": self.offset}
        if self.clamp is not None:
            out["clamp"] = list(self.clamp)
        out["B"] = [list(r) for r in self.B]
        return out


@dataclass(frozen=True)
class Schedule:
    """The variables and terms of a ``[schedule]`` section."""

    variables: tuple[Variable, ...]
    terms: tuple[Term, ...]

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(v.name for v in self.variables)

    @classmethod
    def from_dict(cls, value: Any, path: str, k: int, m: int) -> Schedule:
        t = _table(value, path)
        _keys(t, path, ("variables", "terms"), required=("variables", "terms"))
        variables = tuple(Variable.from_dict(v, f"{path}.variables[{i}]") for i, v in
                          enumerate(_list(t["variables"], f"{path}.variables", low=1, high=MAX_VARIABLES)))
        _unique([v.name for v in variables], f"{path}.variables")
        names = [v.name for v in variables]
        terms = tuple(Term.from_dict(x, f"{path}.terms[{i}]", names, k, m) for i, x in
                      enumerate(_list(t["terms"], f"{path}.terms", low=1, high=MAX_TERMS)))
        schedule = cls(variables, terms)
        schedule.check_range(f"{path}.terms")
        return schedule

    def to_dict(self) -> dict[str, Any]:
        return {"variables": [v.to_dict() for v in self.variables], "terms": [t.to_dict() for t in self.terms]}

    def check_range(self, path: str) -> None:
        """Refuse a term whose factor leaves ``|f| <= 1e50`` somewhere in its variable's range (only a
        linear or square factor can: theirs is largest at an end of the range or the clamp)."""
        units = {v.name: v for v in self.variables}
        for i, term in enumerate(self.terms):
            var = units[term.variable]
            with np.errstate(over="ignore"):
                peak = max(abs(term.value(x, var.unit)) for x in (var.min, var.max, var.nominal))
            if not peak <= MAX_MAGNITUDE or not (np.abs(np.array(term.B)) * peak <= MAX_MAGNITUDE).all():
                raise _fail(f"{path}[{i}]", f"f * B exceeds |x| <= {MAX_MAGNITUDE:g} within {term.variable}'s range")


class ScheduledEffectiveness:
    """``B(x)`` of a vehicle with a schedule, evaluated per call with no rebuilding.

    ``evaluate(values)`` takes the variables by name (a mapping) or in declared order (a
    sequence), each finite and within its declared range, and returns the ``(k, m)`` matrix in a
    buffer this object owns (overwritten by the next call: copy it to keep it; one thread per
    object), or in the caller's ``out``.
    """

    def __init__(self, B: Matrix | np.ndarray, schedule: Schedule) -> None:
        B0 = np.array(B, dtype=float)
        self.shape = B0.shape
        self.schedule = schedule
        self._variables = schedule.variables
        self._index = {v.name: i for i, v in enumerate(self._variables)}
        self._terms = [(t, self._index[t.variable], self._variables[self._index[t.variable]].unit)
                       for t in schedule.terms]
        self._stack = np.array([np.array(t.B, dtype=float).ravel() for t in schedule.terms])  # (T, k m)
        nominal = np.array([t.value(self._variables[i].nominal, unit) for t, i, unit in self._terms])
        self._base = B0.ravel() - nominal @ self._stack
        self._factors = np.empty(len(self._terms))
        self._x = [v.nominal for v in self._variables]
        self._out = np.empty(B0.size)

    def values(self, values: Mapping[str, float] | Sequence[float]) -> list[float]:
        """The variables' values in declared order, each checked (ProblemError naming the variable)."""
        if isinstance(values, Mapping):
            unknown = [n for n in values if n not in self._index]
            if unknown:
                raise ProblemError(f"schedule: unknown variable {short_repr(unknown[0])}; declared: "
                                   f"{', '.join(self._index)}", field="schedule")
            x = [values.get(v.name, v.nominal) for v in self._variables]
        else:
            x = list(values)
            if len(x) != len(self._variables):
                raise ProblemError(f"schedule: expected {len(self._variables)} values ({', '.join(self._index)}), "
                                   f"got {len(x)}", field="schedule")
        for v, value in zip(self._variables, x):
            if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)):
                raise ProblemError(f"{v.name}: expected a number, got {short_repr(value)}", field=v.name)
            if not v.min <= value <= v.max:  # NaN fails too
                raise ProblemError(f"{v.name}: must be in [{v.min:g}, {v.max:g}] {v.unit}, got {short_repr(value)}",
                                   field=v.name)
        return [float(value) for value in x]

    def evaluate(self, values: Mapping[str, float] | Sequence[float], out: np.ndarray | None = None) -> np.ndarray:
        """``B(x)``, shape ``(k, m)``: in this object's buffer, or in ``out`` (a C-contiguous float64
        array of that shape; then no state of this object is touched, so threads may share it)."""
        x = self.values(values)
        f = self._factors if out is None else np.empty(len(self._terms))
        for j, (term, i, unit) in enumerate(self._terms):
            f[j] = term.value(x[i], unit)
        flat = self._out if out is None else out.reshape(-1)
        np.dot(f, self._stack, out=flat)
        flat += self._base
        return flat.reshape(self.shape)

    __call__ = evaluate
