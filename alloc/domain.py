"""The valid input domain and the checks of single values every entry point applies.

The size caps, the magnitude bound and the conversions that refuse what is not a real
number (complex, boolean, text, Python integers beyond float range) live here once:
:class:`alloc.Problem`, the options, the health records and the call arguments all read them.
A module of its own, below :mod:`alloc.problem`, so that modules the problem uses (the
health records) can check values without importing the problem.
"""

from __future__ import annotations

import math
import reprlib
from numbers import Real
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .exceptions import ProblemError

__all__ = ["MAX_MAGNITUDE", "MIN_WEIGHT", "MAX_AXES", "MAX_EFFECTORS", "as_float_array", "as_real", "short_repr", "singular_within_round_off",
           "check_magnitude"]

FloatArray = NDArray[np.float64]


#: The valid input domain (README "Valid input domain").  Every number a problem or a call
#: carries -- B, the limits, ``up``, finite rate limits, the entries of ``Wu``/``Wv``, the
#: demand ``v``, ``u_prev`` and ``dt`` -- is finite with ``|x| <= MAX_MAGNITUDE``; subnormal
#: and zero values are allowed everywhere except as a weight's eigenvalue, which must be at
#: least ``MIN_WEIGHT``.  With these caps the products the methods form (``B u``, ``B Wu^-1
#: B'``, squared norms of moments, the facet inverses) stay below 1e300, so no stage can
#: overflow to ``inf``/``NaN``; physical allocation problems are many orders inside them.
MAX_MAGNITUDE = 1e50
#: Smallest eigenvalue of a weight matrix (``Wu``, ``Wv``); ``1 / MAX_MAGNITUDE``.
MIN_WEIGHT = 1e-50
#: Size caps: virtual-control axes ``k`` and effectors ``m``.
MAX_AXES = 32
MAX_EFFECTORS = 512


#: Array kinds refused as numbers, by numpy dtype kind: a complex value would lose its
#: imaginary part, a boolean or a text would be read as a number it is not.
_NOT_REAL = {"c": "complex", "b": "boolean", "U": "text", "S": "text", "M": "datetime", "m": "timedelta",
             "V": "structured"}


_PLAIN = {float, int}


def _not_real(value: Any) -> str | None:
    """What the first kind of element of ``value`` that is not a real number is, or ``None``.

    Judged by type, once per distinct element type (the elements are gathered by numpy into
    an object array, in C); nested sequences that numpy cannot make regular are left to the
    conversion to report.  Python ``bool`` is refused although it is an ``int``: ``True`` as
    an effectiveness or a limit is a caller's mistake, never a number.
    """
    if isinstance(value, np.ndarray) and value.dtype.kind != "O":
        return _NOT_REAL.get(value.dtype.kind)
    if type(value) in (list, tuple) and set(map(type, value)) <= _PLAIN:
        return None  # a flat list of floats (a demand): no object array
    try:
        cells = np.array(value, dtype=object).ravel()
    except (TypeError, ValueError):
        return None  # not an array at all: the conversion reports it
    for t in set(map(type, cells)):
        if issubclass(t, (bool, np.bool_)):
            return "boolean"
        if issubclass(t, Real) or issubclass(t, (list, tuple, np.ndarray)):
            continue
        if issubclass(t, (complex, np.complexfloating)):
            return "complex"
        if issubclass(t, (str, bytes)):
            return "text"
        return "null" if t is type(None) else t.__name__
    return None


def as_float_array(name: str, value: Any, error: type[Exception] = ProblemError, *,
                   none_as: float | None = None) -> FloatArray:
    """``value`` as a new float array, or ``error`` naming ``name``.

    Refused, each with its reason: ragged or deeply nested sequences; elements that are not
    real numbers (complex -- whose imaginary part a cast would drop --, boolean, text,
    ``None``); Python integers too large for a float.  With ``none_as`` a ``None`` element
    (JSON ``null``) stands for that value.
    """
    if none_as is not None and not isinstance(value, np.ndarray) and value is not None:
        try:
            value = [none_as if x is None else x for x in value]
        except TypeError:
            pass  # not iterable: the checks below report it
    if isinstance(value, np.ndarray) and value.dtype.kind in "fiu":
        kind = None  # the common case: one dtype test, no walk
    else:
        kind = _not_real(value)
    if kind is not None:
        raise error(f"{name}: {kind} values are not accepted (real numbers required)")
    try:
        arr = np.array(value, dtype=float)
    except OverflowError as exc:
        raise error(f"{name}: a number is too large for a float (|x| <= {MAX_MAGNITUDE:g} required)") from exc
    except (TypeError, ValueError) as exc:
        raise error(f"{name}: not a numeric array of consistent shape ({exc})") from exc
    return arr


def as_real(name: str, value: Any, error: type[Exception] = ProblemError) -> float:
    """``value`` as a finite float within the valid domain, or ``error`` naming ``name``.

    A real number (``int``, ``float``, a numpy real scalar, a ``Fraction``); not a bool, a
    complex, a text or ``None``; ``|x| <= MAX_MAGNITUDE`` (a big Python integer is refused
    by its size, not by an overflow).
    """
    if isinstance(value, np.ndarray) and value.ndim == 0 and value.dtype.kind in "fiu":
        value = value.item()  # a 0-d array from numpy arithmetic is its number
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, Real):
        kind = _not_real(value) if not isinstance(value, (bool, np.bool_)) else "boolean"
        raise error(f"{name}: expected a real number, got {kind or type(value).__name__} {short_repr(value)}")
    try:
        x = float(value)
    except OverflowError as exc:
        raise error(f"{name}: {short_repr(value)} is too large (|x| <= {MAX_MAGNITUDE:g} required)") from exc
    if not abs(x) <= MAX_MAGNITUDE:
        what = "must be finite" if not math.isfinite(x) else f"|x| must be <= {MAX_MAGNITUDE:g}"
        raise error(f"{name}: {what}, got {short_repr(value)}")
    return x


_REPR = reprlib.Repr()
_REPR.maxlevel, _REPR.maxlist, _REPR.maxtuple, _REPR.maxdict = 3, 6, 6, 4
_REPR.maxlong, _REPR.maxstring, _REPR.maxother = 24, 40, 40


def short_repr(value: Any, limit: int = 60) -> str:
    """``repr(value)`` for a message: nesting, long sequences and long integers elided (a
    400-digit integer is noise; a list nested 100,000 deep would exhaust the recursion limit)."""
    try:
        text = _REPR.repr(value)
    except Exception:  # noqa: BLE001 - an object whose __repr__ fails still gets a message
        text = f"<{type(value).__name__}>"
    return text if len(text) <= limit else text[: limit - 3] + "..."


def check_magnitude(name: str, arr: FloatArray, error: type[Exception] = ProblemError, *,
                    allow_inf: bool = False) -> None:
    """Raise ``error`` naming ``name`` unless every value is finite (``inf`` if allowed) and
    within ``MAX_MAGNITUDE``."""
    if allow_inf:
        bad = np.isnan(arr) | (np.isfinite(arr) & (np.abs(arr) > MAX_MAGNITUDE))
    else:
        bad = ~(np.abs(arr) <= MAX_MAGNITUDE)
    if bad.any():
        idx = tuple(int(i) for i in np.argwhere(bad)[0])
        x = arr[idx]
        what = "NaN" if np.isnan(x) else ("non-finite" if not np.isfinite(x) else f"|{x:g}| > {MAX_MAGNITUDE:g}")
        where = idx if len(idx) > 1 else (idx[0] if idx else "")
        raise error(f"{name}: {what} value at index {where} (valid domain: finite, |x| <= {MAX_MAGNITUDE:g})")


def singular_within_round_off(matrix: FloatArray, smallest: float, largest: float) -> bool:
    """Whether a square ``matrix`` whose computed smallest and largest singular values (or
    eigenvalues) are ``smallest`` and ``largest`` cannot be shown nonsingular: a full matrix
    whose ``smallest`` is within ``n eps largest`` of zero (the size of the round-off of a
    backward-stable SVD or eigensolver: a rank-deficient ``W`` came out at 3e-17 instead of 0
    with one LAPACK build).  A diagonal matrix has exact values: never."""
    n = matrix.shape[0]
    if np.count_nonzero(matrix - np.diag(np.diag(matrix))) == 0:
        return False
    return bool(smallest <= n * np.finfo(float).eps * largest)
