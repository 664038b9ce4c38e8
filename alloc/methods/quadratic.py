"""Quadratic-programming allocation (seed section 1.3.4.4, Eqs 1.20-1.21).

``qp``
    Two-stage sequential least squares.  Stage 1 (Eq 1.20): minimise
    ``(B u - v)' Wv (B u - v)`` over the limits; the achieved moment ``B u1`` is unique.
    Stage 2 (Eq 1.21): minimise ``(u - up)' Wu (u - up)`` subject to the limits and
    ``B u = B u1`` (``= v`` when ``v`` was attainable), so the answer is unique.  With
    ``priorities`` stage 1 runs once per level, most important first, each level keeping
    the moments of the levels before it.
``wls``
    Single-stage weighted least squares
    ``min (B u - v)' Wv (B u - v) + gamma^2 (u - up)' Wu (u - up)`` over the limits.  It
    approaches ``qp`` as ``gamma -> 0``; for attainable demands ``B u`` differs from ``v``
    by O(gamma^2), so tiny gammas are needed for an ``exact`` status.

Both run by default on the compiled lexicographic least-squares active set of
:mod:`alloc._engine._active_set` (``backend="active_set"``: Härkegård's sequential least squares,
KKT-exact, one compiled call per allocation, a compiled loop for ``allocate_batch``).
``backend="daqp"`` (DAQP models built once; stage 1 on ``B'WvB`` plus a ridge, stage 2 in
a band) or any qpsolvers name keep the previous formulation as cross-checks.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from .._engine._active_set import _HEAD, _MAXIT, lexico_batch_finished, lexico_call, lexico_solve, pack
from .._engine._linalg import check_real_option
from ..exceptions import OptionError, SolverError
from ..export_data import ActiveSetData
from ..options import choice, flag, levels, real
from ..problem import MAX_MAGNITUDE, Problem
from ..method import FloatArray, Method, register
from ..result import EXACT_RTOL, exact_tolerance
from ..solvers import backends, make_backend
from ._common import KEEP_RTOL, check_backend, row_basis
from .cascade import check_priorities
from .pseudo_inverse import distribution_matrix

STAGE1_RIDGE = 1e-10

_BACKEND = choice("daqp", "solver backend: 'daqp' or a qpsolvers name such as 'osqp', 'clarabel'", backends)


class _SolverTwoStageQP(Method):
    equation = "Eqs 1.20-1.21"
    summary = "stage 1 min moment error (Wv), stage 2 min (u-up)'Wu(u-up) at that moment"
    options = {"backend": _BACKEND, "priorities": levels("priority level per axis; larger levels are met first")}

    def __init__(self, problem: Problem, *, backend: str = "daqp", priorities: Sequence[int] | None = None) -> None:
        super().__init__(problem)
        name = check_backend(backend, backends(), "qp")
        p = self.problem
        m = p.m
        self.groups = check_priorities(priorities, p.k) or [np.arange(p.k)]
        lo, hi = p.umin, p.umax
        # Stage 1, one model per priority level: keep the moments of the levels before it.
        self._stage1 = []
        done: list[int] = []
        for rows in self.groups:
            Wl = p.Wv[np.ix_(rows, rows)]
            Bl = p.B[rows]
            H = Bl.T @ Wl @ Bl
            # B'WvB is singular (rank k < m); a 1e-10 relative ridge makes it definite and
            # measured more accurate than DAQP's proximal iterations (1e-8 vs 3e-6 relative
            # moment error on ICE).  Only the stage-1 moment is used, so the ridge's pull
            # on u1 does not reach the answer.
            H = H + STAGE1_RIDGE * max(float(np.trace(H)) / m, 1e-300) * np.eye(m)
            Q = row_basis(p.B[done]) @ np.eye(p.k)[done] if done else np.zeros((0, p.k))
            Aeq = Q @ p.B if done else np.zeros((0, m))
            z = Aeq @ p.up  # feasible at set-up
            model = make_backend(name, H, np.zeros(m), Aeq, z, z, lo, hi)
            self._stage1.append((rows, Bl.T @ Wl, Q, model))
            done.extend(rows.tolist())
        # Stage 2: min (u-up)'Wu(u-up) s.t. Q'B u = Q'B u1 (row-reduced), limits.
        self._Q = row_basis(p.B)
        self._BQ = self._Q @ p.B
        z = self._BQ @ p.up  # feasible at set-up; a band, not an equality (KEEP_RTOL)
        self._f2 = -p.Wu @ p.up
        self._stage2 = make_backend(name, p.Wu, self._f2, self._BQ, z - 1.0, z + 1.0, lo, hi)
        # Attainable demands: B u = v as an exact equality (interior feasible sets are not
        # degenerate; when DAQP calls it infeasible the two-stage path takes over).
        self._stage2_eq = make_backend(name, p.Wu, self._f2, self._BQ, z, z, lo, hi)

    def _in_range(self, v) -> bool:
        r = v - self._Q.T @ (self._Q @ v)
        return float(np.abs(r).max()) <= exact_tolerance(v)

    def stage1(self, v, lo, hi) -> tuple[FloatArray, int]:
        """Eq 1.20 (lexicographically per priority level): a minimiser ``u1``."""
        iters = 0
        u1 = None
        for rows, BWl, Q, model in self._stage1:
            rhs = Q @ (self.problem.B @ u1) if Q.shape[0] else None
            u1, it = model.solve(f=-BWl @ v[rows], lb=lo, ub=hi, bl=rhs, bu=rhs)
            iters += it
        return np.minimum(np.maximum(u1, lo), hi), iters

    def solve(self, v, lo, hi, u_prev):
        # Attainable demands (the common case in flight) need only stage 2 with B u = v;
        # when that is infeasible, stage 1 finds the closest attainable moment first.
        if self._in_range(v):
            rhs = self._Q @ v
            try:
                return self._stage2_eq.solve(lb=lo, ub=hi, bl=rhs, bu=rhs)
            except SolverError:
                pass
        u1, it1 = self.stage1(v, lo, hi)
        m1 = self.problem.B @ u1
        target = v if np.abs(m1 - v).max() <= exact_tolerance(v) else m1
        rhs = self._Q @ target
        band = KEEP_RTOL * max(1.0, float(np.abs(target).max()))
        u, it2 = self._stage2.solve(lb=lo, ub=hi, bl=rhs - band, bu=rhs + band)
        return u, it1 + it2


class _SolverWLS(Method):
    equation = "Eqs 1.20-1.21 (single-stage weighted form)"
    summary = "min (Bu-v)'Wv(Bu-v) + gamma^2 (u-up)'Wu(u-up) over the limits"
    options = {"backend": _BACKEND, "gamma": real(1e-4, "weight of the preference term", low=0.0, low_open=True)}

    def __init__(self, problem: Problem, *, backend: str = "daqp", gamma: float = 1e-4) -> None:
        super().__init__(problem)
        name = check_backend(backend, backends(), "wls")
        g = check_real_option(gamma, "wls", "gamma", 0.0, 1e6, open_lo=True)  # OptionError naming gamma
        p = self.problem
        self.gamma = g
        H = p.B.T @ p.Wv @ p.B + g * g * p.Wu
        self._BWv = p.B.T @ p.Wv
        self._f0 = -g * g * (p.Wu @ p.up)
        empty = np.zeros((0, p.m))
        self._model = make_backend(name, H, self._f0, empty, np.zeros(0), np.zeros(0), p.umin, p.umax)

    def solve(self, v, lo, hi, u_prev):
        return self._model.solve(f=self._f0 - self._BWv @ v, lb=lo, ub=hi)


# --------------------------------------------------------------------------------------
# The compiled sequential least-squares path (default backend "active_set").

ACTIVE_SET = "active_set"


def _is_diagonal(W: FloatArray) -> bool:
    return not np.count_nonzero(W - np.diag(np.diagonal(W)))


def _upper_sqrt(W: FloatArray) -> FloatArray:
    """``S`` with ``S' S = W`` (``S = L'`` for the Cholesky factor ``W = L L'``)."""
    if _is_diagonal(W):
        return np.diag(np.sqrt(np.diagonal(W)))
    return np.linalg.cholesky(W).T


#: the ``warm_start`` option of ``qp``, ``wls`` and ``dynamic`` (compiled active set only)
WARM_START_DOC = ("keep the last call's working set and start the next call from it (answers agree with a cold "
                  "call to round-off, not bit for bit; refused on ill-conditioned problems)")


def check_warm_start(A: FloatArray, Wu: FloatArray) -> None:
    """Refuse ``warm_start`` (OptionError naming it) where the optimum is determined only to
    round-off times a condition number above :data:`alloc._engine._warm.WARM_COND_MAX`: a warm start
    would end elsewhere.  The same rule as the C export's."""
    from .._engine._warm import WARM_COND_MAX, warm_conditioning

    found = warm_conditioning(A, [Wu])
    if found is not None:
        worst, what = found
        raise OptionError(f"warm_start: the problem's {what} has condition number {worst:.2g}, above "
                          f"{WARM_COND_MAX:g}: its optimum is determined only to round-off times that, so a "
                          "warm start would end elsewhere; allocate cold (warm_start=False)", field="warm_start")


def check_warm_backend(warm_start: bool, backend: str, method: str) -> bool:
    """``warm_start`` as a bool; True only with the compiled active set (OptionError naming it)."""
    if not isinstance(warm_start, (bool, np.bool_)):
        raise OptionError(f"{method}: warm_start must be True or False, got {warm_start!r}", field="warm_start")
    if warm_start and backend != ACTIVE_SET:
        raise OptionError(f"warm_start: only the compiled active set keeps a working set ({method} backend "
                          f"{backend!r} does not); use backend='active_set'", field="warm_start")
    return bool(warm_start)


class LexicoLS:
    """Data and state of the compiled lexicographic least-squares solver (:mod:`alloc._engine._active_set`).

    Level ``l`` is ``min ||S_l (B_l u - v_l)||^2 + gammas[l]^2 (u - up)' Wu (u - up)`` with
    ``S_l' S_l = Wv[rows_l, rows_l]``, the earlier levels' moments held; ``final`` adds
    ``min (u - up)' Wu (u - up)`` with every moment held (stage 2, Eq 1.21).  With
    ``target = (d, Kv, Ku)`` the preference point of a call is ``d + Kv v`` (``+ Ku u_prev``
    with rate limits) instead of the problem's ``up`` (``dynamic``).  The packed arrays
    carry the factorisation cache from call to call and, with ``warm_start``, the last single
    call's answer and working set (:data:`WARM_START_DOC`).
    """

    def __init__(self, problem: Problem, groups: Sequence[np.ndarray], gammas: Sequence[float],
                 final: bool, Wu: FloatArray | None = None,
                 target: tuple[FloatArray, FloatArray, FloatArray] | None = None, warm_start: bool = False) -> None:
        p = problem
        perm = np.concatenate([np.asarray(g, dtype=np.int64) for g in groups])
        T = np.zeros((p.k, p.k))
        starts = [0]
        for rows in groups:
            a = starts[-1]
            n = len(rows)
            T[a:a + n, a:a + n] = _upper_sqrt(p.Wv[np.ix_(rows, rows)])
            starts.append(a + n)
        A = T @ p.B[perm]  # rows S_l B_l, level by level
        Wu = np.asarray(p.Wu if Wu is None else Wu, dtype=float)
        # start of a cold call: the Eq 1.23 weighted pseudo-inverse in the same Wu metric
        P0 = distribution_matrix(p if Wu is p.Wu else p.replace(Wu=Wu))
        up, Kv, Ku = (p.up, None, None) if target is None else target
        if warm_start:
            check_warm_start(A, Wu)
        self._state = pack(A, T, perm, starts, np.asarray(gammas, dtype=float), final, Wu, _is_diagonal(Wu),
                           up, p.B, P0, p.umin, p.umax, p.rate_min, p.rate_max, 50 + 10 * (p.m + p.k),
                           MAX_MAGNITUDE, EXACT_RTOL, Kv, Ku, warm=bool(warm_start))
        #: ``(kernel, state)``: the allocator's one-call fast path, ``kernel(*state, v, u_prev, dt)``
        self.packed = (lexico_call, self._state)

    @property
    def state(self) -> tuple[np.ndarray, ...]:
        """The packed solver state (:func:`alloc._engine._active_set.pack`: matrices, vectors, integers,
        then the working arrays), which the C generator prints; read it, do not write it."""
        return self._state

    @property
    def maxit(self) -> int:
        """Iteration cap per level."""
        return int(self._state[2][_HEAD, _MAXIT])

    @maxit.setter
    def maxit(self, value: int) -> None:
        self._state[2][_HEAD, _MAXIT] = int(value)

    def solve(self, v: FloatArray, lo: FloatArray, hi: FloatArray,
              u_prev: FloatArray | None = None) -> tuple[FloatArray, int]:
        rate = u_prev is not None
        u, it, ok = lexico_solve(*self._state, v, lo, hi, u_prev if rate else v, rate)
        if not ok:
            if it < 0:
                raise SolverError("active set: non-finite preference point (u_prev or the static distribution)")
            raise SolverError(f"active set: iteration cap ({self.maxit} per level) reached")
        return u, it

    def solve_batch(self, V: FloatArray, lo: FloatArray, hi: FloatArray) -> FloatArray:
        """Rows of ``V`` within the position limits (``lo``, ``hi`` are those), clipped: the
        compiled pass of :meth:`batch_finished`; NaN rows where it could not finish (the
        allocator redoes those one by one)."""
        U, _, codes = lexico_batch_finished(self._state, V)
        U[codes > 1] = np.nan
        return U

    def batch_finished(self, V: FloatArray) -> tuple[FloatArray, FloatArray, np.ndarray]:
        """Solve and classify in one compiled pass (:func:`alloc._engine._active_set.lexico_batch_finished`)."""
        return lexico_batch_finished(self._state, V)


def _backend_choice(backend: object, method: str) -> str:
    return ACTIVE_SET if backend == ACTIVE_SET else check_backend(backend, [ACTIVE_SET] + backends(), method)


_AS_BACKEND = choice(ACTIVE_SET, "solver: 'active_set' (default, compiled sequential least squares), 'daqp' or a "
                                 "qpsolvers name such as 'quadprog', 'osqp' (cross-checks)",
                     lambda: [ACTIVE_SET, *backends()])


class _ActiveSetOrBackend(Method):
    """Dispatch of the QP methods: the compiled active set (``self._impl`` a :class:`LexicoLS`,
    batch-capable) or a solver backend kept for cross-checks."""

    backend: str
    _impl: Any

    def solve(self, v, lo, hi, u_prev):
        if self.backend != ACTIVE_SET:
            return self._impl.solve(v, lo, hi, u_prev)
        return self._impl.solve(v, lo, hi)

    def solve_batch(self, V, lo, hi):
        return self._impl.solve_batch(V, lo, hi) if self.backend == ACTIVE_SET else None

    def batch_finished(self, V):
        return self._impl.batch_finished(V) if self.backend == ACTIVE_SET else None

    def export_data(self) -> ActiveSetData | None:
        """The compiled active set's state; ``None`` on a cross-check backend (not exported)."""
        return ActiveSetData(states=(self._impl.state,)) if self.backend == ACTIVE_SET else None


@register("wls", supports_batch=True, export="active_set")
class WeightedLeastSquares(_ActiveSetOrBackend):
    equation = "Eqs 1.20-1.21 (single-stage weighted form)"
    summary = "min (Bu-v)'Wv(Bu-v) + gamma^2 (u-up)'Wu(u-up) over the limits"
    options = {"backend": _AS_BACKEND,
               "gamma": real(1e-4, "weight of the preference term (at most 1e6 on the qpsolvers/DAQP backends)",
                             low=0.0, low_open=True, high=MAX_MAGNITUDE),
               "warm_start": flag(False, WARM_START_DOC)}

    def __init__(self, problem: Problem, *, backend: str = ACTIVE_SET, gamma: float = 1e-4,
                 warm_start: bool = False) -> None:
        super().__init__(problem)
        self.backend = _backend_choice(backend, "wls")
        warm = check_warm_backend(warm_start, self.backend, "wls")
        # the valid domain's bound on numbers: gamma = 1e300 squared is inf (every call a fallback)
        g = check_real_option(gamma, "wls", "gamma", 0.0, MAX_MAGNITUDE, open_lo=True)
        self.gamma = g
        if self.backend != ACTIVE_SET:
            self._impl = _SolverWLS(problem, backend=self.backend, gamma=g)
            return
        self._impl = LexicoLS(problem, [np.arange(problem.k)], [g], final=False, warm_start=warm)
        self.packed = self.packed_rate = self._impl.packed


@register("qp", supports_priorities=True, supports_batch=True, export="active_set")
class TwoStageQP(_ActiveSetOrBackend):
    equation = "Eqs 1.20-1.21"
    summary = "stage 1 min moment error (Wv), stage 2 min (u-up)'Wu(u-up) at that moment"
    options = {"backend": _AS_BACKEND, "priorities": levels("priority level per axis; larger levels are met first"),
               "warm_start": flag(False, WARM_START_DOC)}

    def __init__(self, problem: Problem, *, backend: str = ACTIVE_SET, priorities: Sequence[int] | None = None,
                 warm_start: bool = False) -> None:
        super().__init__(problem)
        self.backend = _backend_choice(backend, "qp")
        warm = check_warm_backend(warm_start, self.backend, "qp")
        self.groups = check_priorities(priorities, problem.k) or [np.arange(problem.k)]
        if self.backend != ACTIVE_SET:
            self._impl = _SolverTwoStageQP(problem, backend=self.backend, priorities=priorities)
            return
        self._impl = LexicoLS(problem, self.groups, [0.0] * len(self.groups), final=True, warm_start=warm)
        self.packed = self.packed_rate = self._impl.packed
