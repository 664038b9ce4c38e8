"""Public entry points: allocate, make_allocator, allocate_batch."""

from __future__ import annotations

import time
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from ._kernels import all_finite, finish, fused_affine
from .exceptions import DemandError, SolverError
from .problem import Problem
from .registry import FloatArray, build
from .result import EXACT_RTOL, BatchResult, Result, Status

__all__ = ["Allocator", "make_allocator", "allocate", "allocate_batch"]

_EXACT, _UNATT, _FALLBACK = Status.EXACT, Status.UNATTAINABLE, Status.FALLBACK


class Allocator:
    """A method built once for a problem; call it with demands.

    ``allocator(v, u_prev=None, dt=None) -> Result``.  With ``u_prev`` and ``dt`` the
    command also respects the rate limits over that step (Eq 1.28).  The output is always
    finite and within the bounds: when the method's backend fails, the safe answer of
    :class:`~alloc.methods.pseudo_inverse.SafeCommand` is returned with status ``fallback``.
    """

    __slots__ = ("problem", "method", "impl", "_safe", "_B", "_lo", "_hi", "_kshape", "_W", "_m", "_mk")

    def __init__(self, problem: Problem, method: str, **options: Any) -> None:
        self.problem = problem
        self.method = method
        self.impl = build(problem, method, options)
        from .methods.pseudo_inverse import SafeCommand  # loaded with the registry's methods, not with alloc
        self._safe = SafeCommand(problem)
        self._B = problem.B
        self._lo, self._hi = problem.umin, problem.umax
        self._kshape = (problem.k,)
        self._m, self._mk = problem.m, problem.m + problem.k
        self._W = None
        if self.impl.fused is not None:  # closed-form u = clip(c + P v): one packed compiled call
            c, P = self.impl.fused
            self._W = np.ascontiguousarray(
                np.column_stack([c, P, problem.B.T, problem.umin, problem.umax]), dtype=float)

    def __repr__(self) -> str:
        return f"Allocator(method={self.method!r}, {self.problem!r})"

    def __call__(self, v: ArrayLike, *, u_prev: ArrayLike | None = None, dt: float | None = None) -> Result:
        if self._W is not None and u_prev is None and dt is None:
            t0 = time.perf_counter()
            if type(v) is np.ndarray and v.shape == self._kshape and v.dtype == np.float64:
                out = fused_affine(self._W, v, EXACT_RTOL)
                code = out[self._mk]
                if code < 2.0:
                    return Result(out[:self._m], v, out[self._m:self._mk], _EXACT if code == 0.0 else _UNATT,
                                  self.method, 0, time.perf_counter() - t0, "")
        problem = self.problem
        try:
            v = np.asarray(v, dtype=float)
        except (TypeError, ValueError):
            v = problem.check_demand(v)  # raises DemandError naming v
        if v.shape != self._kshape or not all_finite(v):
            v = problem.check_demand(v)
        if u_prev is None and dt is None:
            lo, hi, up = self._lo, self._hi, None
        else:
            lo, hi = problem.effective_bounds(u_prev, dt)
            up = np.asarray(u_prev, dtype=float)
        t0 = time.perf_counter()
        message = ""
        try:
            u, iterations = self.impl.solve(v, lo, hi, up)
            u = np.array(u, dtype=float)  # own copy: clipped in place below
            v_ach = np.empty(problem.k)
            code = finish(self._B, u, lo, hi, v, v_ach, EXACT_RTOL)
            if code == 2:
                raise SolverError(f"{self.method} produced non-finite commands")
            status = _EXACT if code == 0 else _UNATT
        except SolverError as exc:
            u, iterations, status, message = self._safe(v, lo, hi), 0, _FALLBACK, str(exc)
            if not all_finite(u):  # last resort: the preferred position, clipped
                u = np.array(problem.up)
            u = np.minimum(np.maximum(u, lo), hi)
            v_ach = self._B @ u
        return Result(u, v, v_ach, status, self.method, iterations, time.perf_counter() - t0, message)

    def batch(self, V: ArrayLike) -> BatchResult:
        """Allocate each row of ``V`` (N, k) without rate limits; vectorised where the method allows."""
        problem = self.problem
        try:
            Varr = np.asarray(V, dtype=float)
        except (TypeError, ValueError) as exc:
            raise DemandError(f"V: not a numeric array ({exc})") from exc
        if Varr.ndim != 2 or Varr.shape[1] != problem.k:
            raise DemandError(f"V: expected shape (N, {problem.k}), got {Varr.shape}")
        if not np.isfinite(Varr).all():
            bad = np.argwhere(~np.isfinite(Varr))[0]
            raise DemandError(f"V: non-finite value at row {bad[0]}, column {bad[1]}")
        t0 = time.perf_counter()
        U = self.impl.solve_batch(Varr, self._lo, self._hi)
        if U is not None and np.isfinite(U).all():
            U = np.minimum(np.maximum(U, self._lo), self._hi)
            Vach = U @ self._B.T
            err = np.abs(Vach - Varr).max(axis=1) if len(Varr) else np.zeros(0)
            tol = EXACT_RTOL * np.maximum(1.0, np.abs(Varr).max(axis=1)) if len(Varr) else np.zeros(0)
            status = np.where(err <= tol, _EXACT.value, _UNATT.value)
            return BatchResult(U, Varr, Vach, status, self.method, time.perf_counter() - t0)
        results = [self(v) for v in Varr]
        m = problem.m
        U = np.array([r.u for r in results]).reshape(len(results), m)
        Vach = np.array([r.v_achieved for r in results]).reshape(len(results), problem.k)
        status = np.array([r.status.value for r in results], dtype="<U12")
        return BatchResult(U, Varr, Vach, status, self.method, time.perf_counter() - t0)


def make_allocator(problem: Problem, method: str = "pinv", **options: Any) -> Allocator:
    """Build ``method`` for ``problem`` once; the returned callable allocates fast.

    Parameters
    ----------
    problem : Problem
    method : str
        A name from :func:`alloc.methods`.
    **options
        Method options (see ``alloc methods``); unknown options raise ``OptionError`` (a TypeError).

    Examples
    --------
    >>> import alloc
    >>> p = alloc.Problem([[1.0, 1.0, 0.5]], [-1, -1, -1], [1, 1, 1])
    >>> allocate = alloc.make_allocator(p, "qp")
    >>> r = allocate([1.5])
    >>> r.status.value, round(float(r.v_achieved[0]), 6)
    ('exact', 1.5)
    """
    return Allocator(problem, method, **options)


def allocate(
    problem: Problem,
    v: ArrayLike,
    method: str = "pinv",
    *,
    u_prev: ArrayLike | None = None,
    dt: float | None = None,
    **options: Any,
) -> Result:
    """Allocate one demand ``v`` (builds the method each call: use :func:`make_allocator` in loops)."""
    return Allocator(problem, method, **options)(v, u_prev=u_prev, dt=dt)


def allocate_batch(problem: Problem, V: ArrayLike, method: str = "pinv", **options: Any) -> BatchResult:
    """Allocate the rows of ``V`` (N, k); vectorised for the pseudo-inverse family and ganging."""
    return Allocator(problem, method, **options).batch(V)
