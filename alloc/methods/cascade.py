"""Cascaded generalized inverse and daisy chaining (seed sections 1.3.4.6-1.3.4.7)."""

from __future__ import annotations

import math
import numbers
from collections.abc import Sequence
from typing import Any

import numpy as np

from .._engine._inverse_kernels import cascade, daisy_chain, free_set_insert
from .._engine._kernels import _FREE_BITS, free_set_pinv, matvec
from .._engine._linalg import ABS_FLOOR, RCOND, check_rcond, max_scale, priority_groups, sqrt_factor, weighted_pinv
from ..exceptions import OptionError, ProblemError
from ..export_data import CascadeData
from ..options import groups as groups_option
from ..options import levels, real
from ..problem import Problem
from ..method import CALL_LIMIT_SECONDS, FloatArray, Method, register

#: Bytes the compiled cascade's cache of free-set pseudo-inverses may hold (64 MiB: all 4,096
#: slots up to k m = 2,048, 512 slots at the size caps, 32 x 512)
CGI_CACHE_BYTES = 64 << 20
# Declared per-call cost (``Method.call_cost``), CPU seconds, measured under load on the
# project's machine (``benchmarks/bench_cost_bounds.py``).  One level: a compiled cascade step
# is O(k m), a free set met for the first time adds a compiled k x m SVD; worst call 1 ms +
# 1.5e-7 k m^2 (declared 1.26 s at 32 x 512, where 0.57 s was the worst measured; 4.7 ms at
# 6 x 64, 0.44 ms measured).  By level: each step removes an effector or ends its level (at most
# m_free + L steps) and is one Python prioritised pseudo-inverse over n free effectors,
# 1.5 ms + 3.2e-8 (k + 8) n^2 s (measured 0.3 ms at 32 x 64, 325 ms at 32 x 512 with two BLAS
# threads under load); summed over n = m_free .. 1 plus one full step per level.
_CGI_BASE_S, _CGI_KMM_S = 1e-3, 1.5e-7
_LEVEL_STEP_S, _LEVEL_STEP_N2_S = 1.5e-3, 3.2e-8
# Daisy chaining and the closed forms: a fixed number of O(k m) passes
_DAISY_BASE_S, _DAISY_KM_S = 4e-4, 1e-7


def priority_ranks(priorities: Any, k: int) -> list[int] | None:
    """The ``priorities`` option as ranks ``0 .. L-1`` (larger = more important).

    Levels may be any finite real numbers (Python big integers included); only their order
    matters, and it is compared exactly (``1e20`` and ``2**63`` are never cast to a machine
    integer, which would wrap).  Raises ProblemError naming the field otherwise.
    """
    if priorities is None:
        return None
    if isinstance(priorities, (str, bytes, dict)):
        raise ProblemError(f"priorities: expected a sequence of {k} real numbers, got {type(priorities).__name__}")
    try:
        vals = list(priorities.tolist() if isinstance(priorities, np.ndarray) else priorities)
    except TypeError as exc:
        raise ProblemError(f"priorities: expected a sequence of {k} real numbers ({exc})") from exc
    if len(vals) != k:
        raise ProblemError(f"priorities: expected {k} levels (one per axis), got {len(vals)}")
    for i, x in enumerate(vals):
        x = x.item() if isinstance(x, np.generic) else x
        if isinstance(x, bool) or not isinstance(x, numbers.Real) or (isinstance(x, float) and not math.isfinite(x)):
            raise ProblemError(f"priorities: priorities[{i}] = {x!r} is not a finite real number")
        vals[i] = x
    rank = {lv: r for r, lv in enumerate(sorted(set(vals)))}
    return [rank[x] for x in vals]


def check_priorities(priorities: Any, k: int) -> list[np.ndarray] | None:
    """Validate the ``priorities`` option; the axis groups, most important first (or None)."""
    ranks = priority_ranks(priorities, k)
    return None if ranks is None else priority_groups(ranks, k)


@register("cgi", supports_priorities=True, export="cascade")
class CascadedGeneralizedInverse(Method):
    """Cascaded generalized inverse (section 1.3.4.6, after Eq 1.23).

    Solve Eq 1.23 over the free effectors; effectors whose command violates a limit are
    set to that limit, their effect is subtracted from the demand and they are removed;
    repeat until (1) no new effector saturates, (2) all have saturated, or (3) fewer free
    effectors remain than axes, when the least-squares left pseudo-inverse (Eq 1.24) is
    used and the result clipped.  Inverses are cached per free set, so repeated saturation
    patterns cost one matrix-vector product each.

    With ``priorities`` of more than one level the cascade runs level by level, most
    important first: each level's remaining demand is distributed in the null space of
    the levels before it (so their moments do not change), the increment is scaled until
    the first free effector reaches a limit, that effector is removed, and the rest of the
    level's demand is re-solved over the remaining free effectors.
    """

    equation = "Eqs 1.23-1.24"
    summary = "cascade: saturate violators, remove, re-solve Eq 1.23 (Eq 1.24 when few remain)"
    options = {
        "rcond": real(RCOND, "relative singular-value cut-off", low=0.0, high=1.0, high_open=True),
        "priorities": levels("priority level per axis; larger levels are met first"),
    }
    _CACHE_LIMIT = 4096

    @classmethod
    def call_cost(cls, problem: Problem, **options: Any) -> float:
        """Declared worst-case CPU seconds of one call (model and measurements above).

        With ``priorities`` of L > 1 levels: ``1 ms + sum`` over the at most ``m_free + L``
        steps of ``1.5 ms + 3.2e-8 (k + 8) n^2`` (n the free effectors of the step); else
        ``1 ms + 1.5e-7 k m^2``.  An unreadable ``priorities`` counts as one level.
        """
        k, m = problem.k, problem.m
        try:
            ranks = priority_ranks(options.get("priorities"), k)
        except ProblemError:
            ranks = None
        levels = len(set(ranks)) if ranks else 1
        if levels <= 1:
            return _CGI_BASE_S + _CGI_KMM_S * k * m * m
        n = int((problem.umax > problem.umin).sum())
        squares = levels * n * n + n * (n + 1) * (2 * n + 1) / 6  # one full step per level, then n .. 1
        return _CGI_BASE_S + _LEVEL_STEP_S * (n + levels) + _LEVEL_STEP_N2_S * (k + 8) * squares

    def __init__(self, problem: Problem, *, rcond: float = RCOND, priorities: Sequence[int] | None = None) -> None:
        super().__init__(problem)
        self.rcond = check_rcond(rcond, "cgi")
        self.groups = check_priorities(priorities, problem.k)
        if self.groups is not None and len(self.groups) > 1:
            seconds = self.call_cost(problem, priorities=priorities)
            if seconds > CALL_LIMIT_SECONDS:
                raise OptionError(
                    f"priorities: cgi by {len(self.groups)} levels over {problem.k} x {problem.m} declares "
                    f"{seconds:.3g} s per call, beyond the call bound of {CALL_LIMIT_SECONDS:g} s (fewer levels, "
                    f"fewer effectors, or 'qp' with priorities)", field="priorities")
        self._cache: dict[bytes, FloatArray] = {}
        self._level_cache: dict[tuple[int, bytes], FloatArray] = {}
        self._level_bytes = 0
        # the compiled cascade's cache: free set -> slot of ``_bank`` (see _inverse_kernels.cascade),
        # bounded in bytes; when full it is emptied and refilled (answers never depend on it)
        m, k = problem.m, problem.k
        self._cache_slots = int(min(self._CACHE_LIMIT, max(16, CGI_CACHE_BYTES // (8 * max(m * k, 1)))))
        self._keys = np.zeros((2 * self._CACHE_LIMIT, -(-max(m, 1) // _FREE_BITS)), dtype=np.int64)
        self._slots = np.full(2 * self._CACHE_LIMIT, -1, dtype=np.int64)
        self._bank = np.zeros((16, m, k))
        self._banked = 0
        # a diagonal Wu lets a new free set's inverse be computed compiled, from S B and Wu^-1/2
        Wu = problem.Wu
        self._diagonal_Wu = np.count_nonzero(Wu - np.diag(np.diagonal(Wu))) == 0
        S = sqrt_factor(problem.Wv) if problem.Wv is not None else np.eye(k)
        # contiguous writable copies: one compiled signature whatever the layout of the factors
        f64 = np.ascontiguousarray
        self._S, self._SB, self._rdiag = f64(S), f64(S @ problem.B), f64(1.0 / np.sqrt(np.diagonal(Wu)))

    def _pinv(self, free: np.ndarray) -> FloatArray:
        key = free.tobytes()
        P = self._cache.get(key)
        if P is None:
            p = self.problem
            P = weighted_pinv(p.B[:, free], p.Wu[np.ix_(free, free)], p.Wv, groups=self.groups, rcond=self.rcond)
            if len(self._cache) < self._cache_slots:
                self._cache[key] = P
        return P

    def _bank_pinv(self, free: np.ndarray) -> None:
        """Add the pseudo-inverse of ``free`` to the compiled cascade's cache; a full cache
        is emptied first (its entries are a function of the free set alone, so a call answers
        the same whatever the cache held before)."""
        if self._banked >= self._cache_slots:
            self._slots.fill(-1)
            self._banked = 0
        if self._banked == self._bank.shape[0]:
            self._bank = np.concatenate([self._bank, np.zeros_like(self._bank)])
        P = self.free_set_pinv(free)
        self._bank[self._banked, :P.shape[0]] = P
        free_set_insert(self._keys, self._slots, free, self._banked)
        self._banked += 1

    def free_set_pinv(self, free: np.ndarray) -> FloatArray:
        """The weighted pseudo-inverse over the free effectors (boolean mask ``free``; rows of
        the free effectors) that the compiled cascade uses: compiled from ``S B`` and
        ``Wu^-1/2`` for a diagonal ``Wu``, else :func:`alloc._engine._linalg.weighted_pinv` (cached)."""
        if self._diagonal_Wu:
            return free_set_pinv(self._SB, self._rdiag, self._S, free, self.rcond, ABS_FLOOR)
        return self._pinv(free)

    def level_pinv(self, level: int, free: np.ndarray) -> FloatArray:
        """Priority level ``level``'s pseudo-inverse over the free effectors ``free`` in the null
        space of the levels before it: the columns of the level's own axes, as the cascade by
        level uses them."""
        if self.groups is None:
            raise ValueError("level_pinv: cgi without priorities has one level (use free_set_pinv)")
        done = np.concatenate([np.zeros(0, dtype=np.intp), *self.groups[:level]])
        rows = np.concatenate([done, self.groups[level]])
        sub = [np.arange(done.size), np.arange(done.size, rows.size)]
        Wv = self.problem.Wv[np.ix_(rows, rows)]
        return self._level_pinv(level, free, rows, np.flatnonzero(free), Wv, sub)[:, done.size:]

    def export_data(self) -> CascadeData:
        groups = None if self.groups is None else tuple(self.groups)
        return CascadeData(groups=groups, free_set_pinv=self.free_set_pinv, level_pinv=self.level_pinv)

    def solve(self, v, lo, hi, u_prev):
        if self.groups is not None and len(self.groups) > 1:
            return self._solve_by_level(v, lo, hi)
        p = self.problem
        u = np.empty(p.m)
        free = np.empty(p.m, dtype=np.bool_)
        it = 1
        while True:
            it, missing = cascade(p.B, p.up, v, lo, hi, self._keys, self._slots, self._bank, u, free, it)
            if not missing:
                return u, it
            self._bank_pinv(free)

    def _solve_reference(self, v, lo, hi, u_prev):
        """The cascade in numpy (what :func:`alloc._engine._inverse_kernels.cascade` computes, compiled)."""
        if self.groups is not None and len(self.groups) > 1:
            return self._solve_by_level(v, lo, hi)
        p = self.problem
        base = np.minimum(np.maximum(p.up, lo), hi)
        u = base.copy()
        free = lo < hi
        k = p.k
        for it in range(1, p.m + 2):
            F = np.flatnonzero(free)
            if F.size == 0:
                return u, it - 1  # (2) all saturated
            u[F] = base[F]
            r = v - p.B @ u
            uF = base[F] + self._pinv(free) @ r
            if F.size < k:
                u[F] = np.minimum(np.maximum(uF, lo[F]), hi[F])  # (3) Eq 1.24, then clip
                return u, it
            over, under = uF > hi[F], uF < lo[F]
            if not (over.any() or under.any()):
                u[F] = uF  # (1) no new saturation
                return u, it
            u[F[over]] = hi[F[over]]
            u[F[under]] = lo[F[under]]
            free[F[over | under]] = False
        return u, p.m + 1

    def _level_pinv(self, li: int, free: np.ndarray, rows: np.ndarray, F: np.ndarray, Wv: FloatArray,
                    sub: list[np.ndarray]) -> FloatArray:
        """Level ``li``'s prioritised pseudo-inverse over the free set, cached (bounded in bytes
        by :data:`CGI_CACHE_BYTES`; a function of the level and the free set alone)."""
        key = (li, free.tobytes())
        P = self._level_cache.get(key)
        if P is None:
            p = self.problem
            P = weighted_pinv(p.B[np.ix_(rows, F)], p.Wu[np.ix_(F, F)], Wv, groups=sub, rcond=self.rcond)
            if self._level_bytes + P.nbytes > CGI_CACHE_BYTES:
                self._level_cache.clear()
                self._level_bytes = 0
            self._level_cache[key] = P
            self._level_bytes += P.nbytes
        return P

    def _solve_by_level(self, v, lo, hi):
        p = self.problem
        u = np.minimum(np.maximum(p.up, lo), hi)
        free = lo < hi
        done = np.zeros(0, dtype=np.intp)
        steps = 0
        for li, level in enumerate(self.groups):
            rows = np.concatenate([done, level])
            sub = [np.arange(done.size), np.arange(done.size, rows.size)]
            Wv = p.Wv[np.ix_(rows, rows)]
            for _ in range(p.m + 1):
                r = v[level] - matvec(p.B[level], u)  # fixed order (alloc._engine._kernels.matvec): any copy, same bits
                if not free.any() or np.abs(r).max() <= 1e-12 * max(1.0, float(np.abs(v).max())):
                    break
                F = np.flatnonzero(free)
                P = self._level_pinv(li, free, rows, F, Wv, sub)
                du = matvec(np.ascontiguousarray(P[:, done.size:]), r)
                s = max_scale(u[F], du, lo[F], hi[F])
                u[F] = np.minimum(np.maximum(u[F] + s * du, lo[F]), hi[F])
                steps += 1
                if s >= 1.0:
                    break
                with np.errstate(divide="ignore", invalid="ignore"):
                    reach = np.where(du > 0, (hi[F] - u[F]) / du, np.where(du < 0, (lo[F] - u[F]) / du, np.inf))
                hit = reach <= 1e-12
                if not hit.any():
                    break
                free[F[hit]] = False
            done = rows
        return u, steps


@register("daisy")
class DaisyChain(Method):
    """Daisy chaining (section 1.3.4.7, Eqs 1.25-1.27).

    Effector groups are used in priority order.  Group ``g`` is given the remaining demand
    through its own (pseudo-)inverse (Eq 1.26; the inverse when its B-block is square and
    invertible, the weighted pseudo-inverse otherwise); if that is inadmissible the group's
    increment is scaled until its first effector reaches a limit, the group is held there
    (``u_1(sat)``) and the next group gets the rest (Eq 1.27).  Effectors in no group stay at
    their preferred position.  Without ``groups`` all effectors form one group (then this is
    the direction-preserving pseudo-inverse).
    """

    equation = "Eqs 1.25-1.27"
    summary = "effector groups used one after another, each held where it saturates"
    options = {
        "groups": groups_option("list of lists of effector indices (or names), in priority order"),
        "rcond": real(RCOND, "relative singular-value cut-off", low=0.0, high=1.0, high_open=True),
    }

    @classmethod
    def call_cost(cls, problem: Problem, **options: Any) -> float:
        """One compiled O(k m) pass over the groups: ``0.4 ms + 0.1 us k m`` (worst measured
        0.3 ms at 3 x 8, 0.57 ms at 32 x 512, under load)."""
        return _DAISY_BASE_S + _DAISY_KM_S * problem.k * problem.m

    def __init__(self, problem: Problem, *, groups=None, rcond: float = RCOND) -> None:
        super().__init__(problem)
        rcond = check_rcond(rcond, "daisy")
        self.groups = self._check_groups(problem, groups)
        self.P = []
        for g in self.groups:
            gf = g[~problem.jammed[g]]
            Pg = weighted_pinv(problem.B[:, gf], problem.Wu[np.ix_(gf, gf)], problem.Wv, rcond=rcond)
            self.P.append((gf, Pg))
        # the same groups packed for the compiled chain: indices, offsets, stacked inverses
        self._idx = np.concatenate([gf for gf, _ in self.P]).astype(np.int64)
        self._start = np.cumsum([0] + [len(gf) for gf, _ in self.P]).astype(np.int64)
        self._Pcat = np.ascontiguousarray(np.concatenate([Pg for _, Pg in self.P]).reshape(-1, problem.k))

    @staticmethod
    def _check_groups(problem: Problem, groups) -> list[np.ndarray]:
        if groups is None:
            return [np.arange(problem.m)]
        if isinstance(groups, (str, bytes)) or not hasattr(groups, "__iter__"):
            raise ProblemError("groups: expected a list of lists of effector indices")
        out, seen = [], set()
        for gi, g in enumerate(groups):
            if isinstance(g, (str, bytes)) or not hasattr(g, "__iter__"):
                raise ProblemError(f"groups[{gi}]: expected a list of effector indices")
            try:
                idx = [problem.index(e) for e in g]
            except ProblemError as exc:
                raise ProblemError(f"groups[{gi}]: {exc}") from exc
            if not idx:
                raise ProblemError(f"groups[{gi}]: empty group")
            dup = seen.intersection(idx)
            if dup or len(set(idx)) != len(idx):
                raise ProblemError(f"groups[{gi}]: effector(s) {sorted(dup) or idx} listed twice")
            seen.update(idx)
            out.append(np.array(idx, dtype=np.intp))
        if not out:
            raise ProblemError("groups: no groups given")
        return out

    def solve(self, v, lo, hi, u_prev):
        p = self.problem
        return daisy_chain(p.B, p.up, v, lo, hi, self._idx, self._start, self._Pcat)

    def _solve_reference(self, v, lo, hi, u_prev):
        """The chain in numpy (what :func:`alloc._engine._inverse_kernels.daisy_chain` computes, compiled)."""
        p = self.problem
        u = np.minimum(np.maximum(p.up, lo), hi)
        r = v - p.B @ u
        tol = 1e-12 * max(1.0, float(np.abs(v).max()))
        used = 0
        for gf, Pg in self.P:
            if np.abs(r).max() <= tol:
                break
            used += 1
            du = Pg @ r
            s = max_scale(u[gf], du, lo[gf], hi[gf])
            u[gf] += s * du
            r = r - p.B[:, gf] @ (s * du)
        return u, used
