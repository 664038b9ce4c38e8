"""Results of an allocation: the command, what it achieves, and how it was found."""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum
from operator import itemgetter
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["Status", "Result", "BatchResult", "EXACT_RTOL"]

#: Relative tolerance of the ``exact`` status: the residual in exact arithmetic is certified
#: within it, ``max_i (|fl(B u - v)_i| + gamma_{m+1} (|B| |u| + |v|)_i) <= EXACT_RTOL * max(1, max|v|)``
#: (the computed residual plus its rounding bound, :func:`alloc._engine._kernels.rounding_gamma`).
EXACT_RTOL = 1e-6


class Status(str, Enum):
    """Outcome of one allocation (a closed set).

    ``exact``
        ``B u = v`` within ``EXACT_RTOL``, certified: the computed residual plus its
        rounding bound is within the tolerance (:data:`EXACT_RTOL`).
    ``unattainable``
        ``v`` lies outside what the method reaches with admissible ``u``; ``u`` is the
        method's best admissible answer and ``v - B u`` is reported as ``unallocated``.
    ``fallback``
        The numerical backend failed or hit its iteration cap; ``u`` is the documented
        safe answer (the weighted pseudo-inverse clipped to the limits, see
        :func:`alloc.methods.pseudo_inverse.safe_command`), always finite and admissible.
    """

    EXACT = "exact"
    UNATTAINABLE = "unattainable"
    FALLBACK = "fallback"

    def __str__(self) -> str:
        return self.value


def exact_tolerance(v: NDArray[np.float64]) -> float:
    """Absolute moment tolerance used for the ``exact`` status of demand ``v``."""
    return EXACT_RTOL * max(1.0, float(np.abs(v).max()) if v.size else 1.0)


def _field(i: int, doc: str) -> property:
    return property(itemgetter(i), doc=doc)


class Result(tuple):
    """One allocation: an immutable record (a tuple of its fields, ``__slots__ = ()``).

    Built once per call on the hot path, so it is a tuple (built in one C call) rather than
    a frozen dataclass (one ``object.__setattr__`` per field, about a microsecond); its
    arrays are read-only and its own (never views of the caller's arrays).

    Attributes
    ----------
    u : ndarray (m,)
        Effector command, finite and within the (rate-limited) bounds.
    v : ndarray (k,)
        The demand.
    v_achieved : ndarray (k,)
        ``B u``.
    status : Status
    method : str
    iterations : int
        Solver iterations or cascade steps (0 for closed-form methods).
    solve_time : float
        Seconds spent in the method (excluding validation).
    message : str
        Why a fallback happened, or empty.
    unallocated : ndarray (k,)
        The part of the demand left unallocated, ``v - B u`` (for hedging/anti-windup);
        computed from ``v`` and ``v_achieved`` when not given.
    """

    __slots__ = ()
    _fields = ("u", "v", "v_achieved", "status", "method", "iterations", "solve_time", "message", "unallocated")

    def __new__(cls, u: NDArray[np.float64], v: NDArray[np.float64], v_achieved: NDArray[np.float64],
                status: Status, method: str, iterations: int = 0, solve_time: float = 0.0, message: str = "",
                unallocated: NDArray[np.float64] | None = None) -> Result:
        if unallocated is None:
            unallocated = np.subtract(v, v_achieved)
            unallocated.setflags(write=False)
        return tuple.__new__(cls, (u, v, v_achieved, status, method, iterations, solve_time, message, unallocated))

    def __reduce__(self) -> tuple[Any, tuple[Any, ...]]:
        """Pickle, ``copy`` and ``deepcopy``: the same fields, the arrays read-only again."""
        return _result_from_fields, tuple(self)

    def __repr__(self) -> str:
        return "Result(" + ", ".join(f"{f}={x!r}" for f, x in zip(self._fields, self)) + ")"

    u = _field(0, "Effector command (m,), finite and within the (rate-limited) bounds.")
    v = _field(1, "The demand (k,).")
    v_achieved = _field(2, "``B u`` (k,).")
    status = _field(3, "The outcome, a :class:`Status`.")
    method = _field(4, "The registry name of the method.")
    iterations = _field(5, "Solver iterations or cascade steps (0 for closed-form methods).")
    solve_time = _field(6, "Seconds spent in the method (excluding validation).")
    message = _field(7, "Why a fallback happened, or empty.")
    unallocated = _field(8, "``v - B u`` (k,): the part of the demand left unallocated.")

    @property
    def moment_error(self) -> float:
        """Euclidean norm of ``v - B u``."""
        return float(np.linalg.norm(self.unallocated))

    @property
    def fallback(self) -> bool:
        return self.status is Status.FALLBACK

    def limit_violation(self, lo: NDArray[np.float64], hi: NDArray[np.float64]) -> float:
        """Largest amount by which ``u`` leaves ``[lo, hi]`` (0 when admissible)."""
        return float(max(0.0, (lo - self.u).max(), (self.u - hi).max()))

    def to_dict(self) -> dict[str, Any]:
        return {**_arrays_dict(self, with_v=True), "status": self.status.value, "method": self.method,
                "iterations": int(self.iterations), "solve_time": float(self.solve_time), "message": self.message}


def _read_only(a: Any) -> Any:
    """``a`` itself with its write flag cleared (an array unpickled or deep-copied is writeable)."""
    if isinstance(a, np.ndarray) and a.flags.writeable:
        a.setflags(write=False)
    return a


def _result_from_fields(u: Any, v: Any, v_achieved: Any, status: Any, method: str, iterations: int,
                        solve_time: float, message: str, unallocated: Any) -> Result:
    """:meth:`Result.__reduce__`'s rebuild (module level, so pickle can name it)."""
    return tuple.__new__(Result, (_read_only(u), _read_only(v), _read_only(v_achieved), Status(status), method,
                                  iterations, solve_time, message, _read_only(unallocated)))


def _arrays_dict(r: Result | BatchResult, with_v: bool) -> dict[str, Any]:
    """The arrays of a single or a batch result in their JSON form."""
    v = {"v": r.v.tolist()} if with_v else {}
    return {"u": r.u.tolist(), **v, "v_achieved": r.v_achieved.tolist(), "unallocated": r.unallocated.tolist()}


@dataclass(frozen=True, slots=True)
class BatchResult:
    """Allocations of ``N`` demands: arrays stacked along the first axis."""

    u: NDArray[np.float64]
    v: NDArray[np.float64]
    v_achieved: NDArray[np.float64]
    status: NDArray[np.str_]
    method: str
    solve_time: float = 0.0

    @property
    def unallocated(self) -> NDArray[np.float64]:
        return _read_only(self.v - self.v_achieved)

    def __len__(self) -> int:
        return int(self.u.shape[0])

    def __reduce__(self) -> tuple[Any, tuple[Any, ...]]:
        """Pickle, ``copy`` and ``deepcopy``: the same fields, the arrays read-only again."""
        return _batch_from_fields, (self.u, self.v, self.v_achieved, self.status, self.method, self.solve_time)

    def counts(self) -> dict[str, int]:
        """How many results have each status."""
        return {s.value: int((self.status == s.value).sum()) for s in Status}

    def to_dict(self) -> dict[str, Any]:
        return {**_arrays_dict(self, with_v=False), "status": self.status.tolist(), "method": self.method,
                "counts": self.counts(), "solve_time": float(self.solve_time)}


def _batch_from_fields(u: Any, v: Any, v_achieved: Any, status: Any, method: str, solve_time: float) -> BatchResult:
    """:meth:`BatchResult.__reduce__`'s rebuild (module level, so pickle can name it)."""
    return BatchResult(_read_only(u), _read_only(v), _read_only(v_achieved), _read_only(status), method, solve_time)
