"""Typed method options, validated once by the registry.

A method declares its options as a class attribute mapping names to :class:`Option`
specifications::

    options = {
        "rcond": real(RCOND, "relative singular-value cut-off of the inverse", low=0.0, high=1.0,
                      high_open=True),
        "incremental": flag(False, "bias at u_prev instead of up when u_prev is given"),
    }

:func:`alloc.registry.build` checks every given value against its specification before the
method is constructed; a bad value raises one :class:`~alloc.exceptions.OptionError`
naming the option and the reason (``rcond: must be in [0, 1), got 2.0``), with ``field``
set to the option's name.  Checks that need the problem (a matrix's shape, an effector
name) stay in the method, which raises :class:`~alloc.exceptions.ProblemError` naming the
option.  The defaults stated here are the constructor's defaults (a test compares them).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from numbers import Integral, Real
from typing import Any

import numpy as np

from .exceptions import OptionError
from .problem import MAX_MAGNITUDE, as_float_array, short_repr

__all__ = ["Option", "real", "integer", "flag", "choice", "matrix", "weight", "levels", "groups", "validate"]


@dataclass(frozen=True)
class Option:
    """One method option: its type, default, admissible values and meaning.

    Parameters
    ----------
    type : str
        What the value is, for people and the service's method listing (``"float"``,
        ``"int"``, ``"bool"``, ``"str"``, ``"matrix"``, ``"weight"``, ``"real list"``, ``"groups"``).
    default : Any
        The value the method uses when the option is not given (JSON-able).
    doc : str
        One line: what the option does.
    check : callable
        ``check(value) -> normalised value``; raises ``ValueError`` with the reason
        (``"must be in [0, 1)"``) when the value is not admissible.
    constraint : str
        The admissible values in words, e.g. ``"[0, 1)"``, ``">= 1"``, ``"one of daqp, highs"``.
    call_cap : float, optional
        For an option that sets how many iterations one call may run: the largest value a
        shared host (the service, where a call runs on its event loop) accepts.  The library
        itself accepts every admissible value.
    """

    type: str
    default: Any
    doc: str
    check: Callable[[Any], Any] = field(repr=False, compare=False)
    constraint: str = ""
    call_cap: float | None = None

    def describe(self) -> str:
        """One line for ``alloc methods`` and ``GET /v1/methods``: meaning, constraint, default."""
        parts = [self.doc]
        if self.constraint:
            parts.append(f"[{self.constraint}]")
        if self.default is not None:
            parts.append(f"(default {self.default!r})")
        return " ".join(parts)

    def to_dict(self) -> dict[str, Any]:
        """JSON-able spec: type, default, constraint, doc."""
        return {"type": self.type, "default": self.default, "constraint": self.constraint, "doc": self.doc}


def _is_real(value: Any) -> bool:
    return isinstance(value, Real) and not isinstance(value, bool)


def real(default: float | None, doc: str, *, low: float = -math.inf, high: float = math.inf,
         low_open: bool = False, high_open: bool = False) -> Option:
    """A finite real number in an interval (``low_open``/``high_open`` exclude the ends)."""
    lo_b, hi_b = "(" if low_open or low == -math.inf else "[", ")" if high_open or high == math.inf else "]"
    bounded = low > -math.inf or high < math.inf
    constraint = f"{lo_b}{low:g}, {high:g}{hi_b}" if bounded else "finite"

    def check(value: Any) -> float:
        if not _is_real(value):
            raise ValueError("must be a finite number")
        try:
            x = float(value)
        except OverflowError:  # a big Python integer
            x = math.inf if value > 0 else -math.inf
        if not math.isfinite(x):
            raise ValueError("must be a finite number" + ("" if isinstance(value, float) else
                                                          f" with |x| <= {MAX_MAGNITUDE:g}"))
        if abs(x) > MAX_MAGNITUDE:
            raise ValueError(f"must be a finite number with |x| <= {MAX_MAGNITUDE:g}")
        if x < low or x > high or (low_open and x == low) or (high_open and x == high):
            raise ValueError(f"must be in {constraint}")
        return x

    return Option("float", default, doc, check, constraint)


def integer(default: int | None, doc: str, *, low: int | None = None, high: int | None = None,
            call_cap: int | None = None) -> Option:
    """An integer (not a bool, not a float) in ``[low, high]``; ``call_cap``: :attr:`Option.call_cap`."""
    constraint = " and ".join(c for c in (f">= {low}" if low is not None else "",
                                          f"<= {high}" if high is not None else "") if c)

    def check(value: Any) -> int:
        if not isinstance(value, Integral) or isinstance(value, bool):
            raise ValueError("must be an integer")
        n = int(value)
        if (low is not None and n < low) or (high is not None and n > high):
            raise ValueError(f"must be {constraint}")
        return n

    return Option("int", default, doc, check, constraint, call_cap)


def flag(default: bool, doc: str) -> Option:
    """``True`` or ``False``."""

    def check(value: Any) -> bool:
        if not isinstance(value, (bool, np.bool_)):
            raise ValueError("must be true or false")
        return bool(value)

    return Option("bool", default, doc, check, "true or false")


def choice(default: str, doc: str, choices: Sequence[str] | Callable[[], Sequence[str]]) -> Option:
    """One of a set of names; ``choices`` may be a function (e.g. the solvers installed here)."""

    def allowed() -> list[str]:
        return list(choices() if callable(choices) else choices)

    def check(value: Any) -> str:
        names = allowed()
        if not isinstance(value, str) or value not in names:
            raise ValueError(f"must be one of {', '.join(names)}")
        return value

    constraint = "one of " + ", ".join(choices) if not callable(choices) else "a solver installed here"
    return Option("str", default, doc, check, constraint)


def _numeric(value: Any) -> np.ndarray:
    """``value`` as a float array within the valid domain, or ``ValueError`` with the reason
    (complex, boolean or text elements, big integers, non-finite or huge values)."""
    try:
        arr = as_float_array("value", value, ValueError)
    except ValueError as exc:
        raise ValueError(str(exc).removeprefix("value: ")) from None
    if not (np.abs(arr) <= MAX_MAGNITUDE).all():
        raise ValueError(f"must have finite entries with |x| <= {MAX_MAGNITUDE:g}")
    return arr


def matrix(doc: str) -> Option:
    """A finite numeric 2-D array in the valid domain (default ``None``); its shape is the
    method's to check."""

    def check(value: Any) -> Any:
        if value is None:
            return None
        arr = _numeric(value)
        if arr.ndim != 2:
            raise ValueError(f"must be a matrix (2-D), got {arr.ndim}-D")
        return value

    return Option("matrix", None, doc, check, f"finite 2-D array, |x| <= {MAX_MAGNITUDE:g}")


def weight(doc: str) -> Option:
    """A finite weight given as a scalar, a vector (a diagonal) or a matrix (default ``None``);
    its size and range are the method's to check."""

    def check(value: Any) -> Any:
        if value is None:
            return None
        arr = _numeric(value)
        if arr.ndim > 2:
            raise ValueError(f"must be a scalar, vector or matrix, got {arr.ndim}-D")
        return value

    return Option("weight", None, doc, check, "finite scalar, vector or matrix")


def _is_list(value: Any) -> bool:
    """A list, tuple or array (a string is not a list of anything here)."""
    return not isinstance(value, (str, bytes)) and isinstance(value, (Sequence, np.ndarray))


def _is_whole(value: Any) -> bool:
    return _is_real(value) and math.isfinite(float(value)) and float(value) == round(float(value))


def _is_level(value: Any) -> bool:
    """A real number used only by comparison: any size of Python int, a finite float."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, Real):
        return False
    return isinstance(value, Integral) or math.isfinite(float(value))


def levels(doc: str) -> Option:
    """A list of real numbers (default ``None``), e.g. one priority level per axis.

    Levels are compared exactly (ranks), never cast: ``[1e20, 1]`` and ``[2**63, 1]`` keep
    their order."""

    def check(value: Any) -> Any:
        if value is not None and not (_is_list(value) and all(_is_level(x) for x in value)):
            raise ValueError("must be a list of finite real numbers")
        return value

    return Option("real list", None, doc, check, "list of finite real numbers")


def groups(doc: str) -> Option:
    """A list of lists of effector indices or names (default ``None``)."""

    def is_effector(e: Any) -> bool:  # a whole float (2.0) is index 2; 1.7 is refused
        return isinstance(e, (str, Integral)) and not isinstance(e, bool) or (
            isinstance(e, (float, np.floating)) and _is_whole(e))

    def check(value: Any) -> Any:
        if value is not None and not (_is_list(value) and all(_is_list(g) and all(is_effector(e) for e in g)
                                                               for g in value)):
            raise ValueError("must be a list of lists of effector indices or names")
        return value

    return Option("groups", None, doc, check, "list of lists of effector indices or names")


def validate(method: str, spec: dict[str, Option], given: dict[str, Any]) -> dict[str, Any]:
    """``given`` checked against ``spec``: unknown names and bad values raise OptionError.

    Returns the normalised values (``float`` for reals, ``bool`` for flags, ...) of the given
    options only; absent options keep the method's defaults.
    """
    unknown = sorted(set(given) - set(spec))
    if unknown:
        allowed = ", ".join(sorted(spec)) or "none"
        raise OptionError(f"{method}: unknown option(s) {unknown}; accepted: {allowed}", field=unknown[0])
    out = {}
    for name, value in given.items():
        try:
            out[name] = spec[name].check(value)
        except ValueError as exc:
            raise OptionError(f"{name}: {exc}, got {short_repr(value)}", field=name) from None
    return out
