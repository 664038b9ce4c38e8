"""A small internal interface to well-kept QP/LP solvers, built once and updated per call.

Every backend solves

    minimise 0.5 x' H x + f' x   subject to  lb <= x <= ub,  bl <= A x <= bu

where ``H`` may be ``None`` (a linear program) and rows with ``bl == bu`` are
equalities.  A backend is set up once and each call passes only the data that change
(cost vector, bounds, sometimes ``A``).  Every backend solves the problem's
:class:`Equilibration` (variables scaled to their bound widths around their centre, rows
of ``A`` and the cost to unit largest entry) and the answer is mapped back, so
magnitudes from 1e-30 to 1e48 in the allocation data reach the solver as O(1) numbers.
Every backend's answer is a function of the call's data alone (no warm state carried
from call to call), and every backend is bounded by iteration counts, never by wall-clock
time, so an answer does not depend on the machine's load (:data:`ITERATION_LIMITS`).  A
backend object is not re-entrant: the allocator that owns it serialises its calls
(:class:`alloc.api.Allocator`).  Measured costs are in ``benchmarks/bench_alloc.py`` and the README.

Backends
--------
``daqp``
    DAQP's dual active-set solver, a ``daqp.Model`` set up per solve (LPs and singular
    Hessians use its proximal-point iterations); LPs chain to HiGHS on DAQP's failure.
``highs``
    HiGHS (highspy), a new model per solve (the constraint matrix converted once); LPs only.
any name in ``qpsolvers.available_solvers`` (``osqp``, ``clarabel``, ``proxqp``, ...)
    Through qpsolvers, which rebuilds the solver each call: slow, for cross-checks.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from .exceptions import OptionError, SolverError

__all__ = ["Backend", "make_backend", "backends"]

FloatArray = NDArray[np.float64]


class Backend(Protocol):
    def solve(
        self,
        f: FloatArray | None = None,
        lb: FloatArray | None = None,
        ub: FloatArray | None = None,
        bl: FloatArray | None = None,
        bu: FloatArray | None = None,
        A: FloatArray | None = None,
    ) -> tuple[FloatArray, int]:
        """Solve with updated data; return ``(x, iterations)`` or raise SolverError."""
        ...


def backends(lp: bool = False) -> list[str]:
    """Names of the backends usable here (for LPs when ``lp``)."""
    names = ["daqp", "highs"] if lp else ["daqp"]
    if not lp:
        try:
            import qpsolvers

            names += [s for s in qpsolvers.available_solvers if s not in names]
        except ImportError:  # pragma: no cover - qpsolvers is a dependency
            pass
    return names


def make_backend(
    name: str,
    H: FloatArray | None,
    f: FloatArray,
    A: FloatArray,
    bl: FloatArray,
    bu: FloatArray,
    lb: FloatArray,
    ub: FloatArray,
    *,
    singular: bool = False,
) -> Backend:
    """Build backend ``name`` for the given problem structure, on equilibrated data.

    ``singular`` says the Hessian is only positive semidefinite (DAQP then uses its
    proximal-point iterations).  Every backend sees the problem through :class:`Equilibration`
    (variables scaled to their bound widths, rows of ``A`` to unit largest entry, the cost to
    unit largest entry), so magnitudes from 1e-30 to 1e48 in ``B`` and the limits reach the
    solver as O(1) numbers; answers are mapped back.
    """
    lp = H is None
    if name == "highs" and not lp:
        raise OptionError("backend: 'highs' is used for linear programs only (it returns wrong QP answers, see SOLVER-NOTES)")
    if name not in ("daqp", "highs") and lp:
        raise OptionError(f"backend: {name!r} is not an LP backend; use one of {backends(lp=True)}")
    eq = Equilibration(H, f, A, bl, bu, lb, ub)
    return _ScaledBackend(_make_raw(name, eq.H, eq.f, eq.A, eq.bl, eq.bu, eq.lb, eq.ub, singular), eq,
                          np.asarray(bl, dtype=float), np.asarray(bu, dtype=float))


def _highs_from(d: dict) -> _Highs:
    """The HiGHS LP of ``_Chain``'s data (a module-level function: a backend pickles)."""
    return _Highs(d["f"], d["A"], d["bl"], d["bu"], d["lb"], d["ub"])


def _make_raw(name, H, f, A, bl, bu, lb, ub, singular):
    lp = H is None
    if name == "daqp":
        primary = _Daqp(H, f, A, bl, bu, lb, ub, singular=singular or lp)
        if lp:
            # DAQP's proximal-point LP reports false infeasibility or cycling on a few
            # degenerate allocation LPs (~0.3 % of the random suites); HiGHS' simplex
            # re-solves exactly those calls.
            return _Chain(primary, _highs_from, dict(f=f, A=A, bl=bl, bu=bu, lb=lb, ub=ub))
        return primary
    if name == "highs":
        return _Highs(f, A, bl, bu, lb, ub)
    return _Qpsolvers(name, H, f, A, bl, bu, lb, ub)


class Equilibration:
    """``x = c + s * y``, rows of ``A`` divided by ``r``, the cost by ``sigma``.

    ``c`` is the centre of each variable's bounds (its finite bound when one-sided, 0 when
    free) and ``s`` its half-width, so bounded variables live in ``[-1, 1]``; a variable
    with an infinite bound gets the scale that gives its column of the row-scaled ``A`` a
    largest entry of 1.  ``r`` makes every row of ``A diag(s)`` have largest entry 1, and
    ``sigma`` the largest entry of the scaled ``H`` (a QP; fixed at set-up since the backend
    keeps ``H``) or of the scaled cost vector of each call (an LP).  The scaled problem has
    the same minimisers (mapped by ``x = c + s y``).  ``A`` may change per call (direct
    allocation's ray): its row scales are then recomputed with ``s`` and ``c`` kept.
    """

    def __init__(self, H, f, A, bl, bu, lb, ub) -> None:
        lb, ub = np.asarray(lb, dtype=float), np.asarray(ub, dtype=float)
        A = np.asarray(A, dtype=float)
        lo_f, hi_f = np.isfinite(lb), np.isfinite(ub)
        both = lo_f & hi_f
        with np.errstate(over="ignore", invalid="ignore"):
            width = (ub - lb) / 2.0
            self.c = np.where(both, lb + width, np.where(lo_f, lb, np.where(hi_f, ub, 0.0)))
            s = np.where(both & (width > 0) & np.isfinite(width), width, 1.0)
        s = np.where(s > 0, s, 1.0)
        free = ~both
        if free.any() and A.size:
            r = _row_scales(A[:, ~free] * s[~free]) if (~free).any() else np.ones(A.shape[0])
            col = np.abs(A[:, free] / r[:, None]).max(axis=0)
            s[free] = np.where((col > 0) & np.isfinite(col), 1.0 / np.where(col > 0, col, 1.0), 1.0)
        self.s = s
        self._Ac = A @ self.c if A.size else np.zeros(A.shape[0])
        self.r = _row_scales(A * s)
        self.A = np.ascontiguousarray(A * s / self.r[:, None])
        self.qp = H is not None
        if self.qp:
            Hs = np.asarray(H, dtype=float) * s[:, None] * s[None, :]
            top = float(np.abs(Hs).max()) if Hs.size else 0.0
            self.sigma = top if top > 0 and np.isfinite(top) else 1.0
            self.H = Hs / self.sigma
            self._Hc = np.asarray(H, dtype=float) @ self.c
        else:
            self.sigma = 1.0
            self.H, self._Hc = None, None
        self.f = self.cost(f)
        self.lb, self.ub = self.lower(lb), self.upper(ub)
        self.bl, self.bu = self.rows(bl), self.rows(bu)

    def cost(self, f: FloatArray) -> FloatArray:
        fy = self.s * (np.asarray(f, dtype=float) if self._Hc is None else f + self._Hc)
        if self.qp:
            return fy / self.sigma
        top = float(np.abs(fy).max()) if fy.size else 0.0
        return fy / top if top > 0 and np.isfinite(top) else fy

    def lower(self, lb: FloatArray) -> FloatArray:
        return (lb - self.c) / self.s

    upper = lower

    def rows(self, b: FloatArray) -> FloatArray:
        return (b - self._Ac) / self.r

    def matrix(self, A: FloatArray) -> FloatArray:
        """A new constraint matrix (row scales and ``A c`` recomputed)."""
        As = A * self.s
        self.r = _row_scales(As)
        self._Ac = A @ self.c
        return np.ascontiguousarray(As / self.r[:, None])


def _row_scales(M: FloatArray) -> FloatArray:
    """Largest absolute entry of each row (1 for zero or non-finite rows)."""
    if M.shape[1] == 0:
        return np.ones(M.shape[0])
    r = np.abs(M).max(axis=1)
    return np.where((r > 0) & np.isfinite(r), r, 1.0)


class _ScaledBackend:
    """A backend solving the :class:`Equilibration` of the caller's problem."""

    def __init__(self, inner, eq: Equilibration, bl: FloatArray, bu: FloatArray) -> None:
        self._inner, self._eq = inner, eq
        self._bl, self._bu = bl, bu  # the caller's row bounds (unscaled), last sent
        # read-only bound arrays passed again unchanged (the problem's limits) are mapped once
        self._memo: dict[str, tuple[object, FloatArray]] = {}

    def _bound(self, key: str, value, fn):
        if value is None:
            return None
        hit = self._memo.get(key)
        if hit is not None and hit[0] is value and not value.flags.writeable:
            return hit[1]
        out = fn(value)
        if isinstance(value, np.ndarray) and not value.flags.writeable:
            out.setflags(write=False)
            self._memo[key] = (value, out)
        return out

    def solve(self, f=None, lb=None, ub=None, bl=None, bu=None, A=None):
        eq = self._eq
        As = None
        if A is not None:
            As = eq.matrix(np.asarray(A, dtype=float))
            # the row bounds are scaled with the rows: re-send them on a new matrix
            bl = self._bl if bl is None else bl
            bu = self._bu if bu is None else bu
        self._bl = self._bl if bl is None else bl
        self._bu = self._bu if bu is None else bu
        y, it = self._inner.solve(
            f=None if f is None else eq.cost(f),
            lb=self._bound("lb", lb, eq.lower), ub=self._bound("ub", ub, eq.upper),
            bl=None if bl is None else eq.rows(bl), bu=None if bu is None else eq.rows(bu), A=As)
        x = eq.c + eq.s * y
        if not np.all(np.isfinite(x)):
            raise SolverError("backend answer is not finite after unscaling")
        return x, it


class _Daqp:
    """DAQP (``daqp.Model``), a new workspace per solve.

    DAQP keeps iterate state across solves (the proximal iterations of an LP; the working
    set of a QP, even with the sense flags reset on update), and where the optimum is weakly
    determined (an LP's optimal face, stage 1's ridge-regularised minimiser) the answer
    would then depend on the call history.  Setting up afresh makes every answer a function
    of this call's data alone (measured cost in ``benchmarks/bench_alloc.py``).
    """

    _EQ = 5  # DAQP sense flag of an equality constraint

    def __init__(self, H, f, A, bl, bu, lb, ub, *, singular: bool) -> None:
        import daqp  # noqa: F401 - fails here, at build, when DAQP is absent

        self._n = int(f.size)
        # daqp.Model needs a matrix: an LP is a QP with H = 0 solved by proximal-point iterations.
        self._H = np.zeros((f.size, f.size)) if H is None else np.array(H, dtype=float, order="C")
        self._A = np.array(A, dtype=float, order="C")
        self._bupper = np.concatenate([_widen(lb, ub), bu]).astype(float)
        self._blower = np.concatenate([lb, bl]).astype(float)
        self._sense = np.zeros(self._bupper.size, dtype=np.int32)
        self._sense[self._n:][bl == bu] = self._EQ
        self._f = np.array(f, dtype=float)
        self._ub = np.array(ub, dtype=float)
        self._settings = {"iter_limit": ITERATION_LIMITS["daqp"]}
        if singular:
            self._settings["eps_prox"] = 1e-6
        self._setup()

    def _setup(self):
        import daqp  # a module is not kept on the object: a backend pickles (alloc.Allocator)

        model = daqp.Model()
        flag, _ = model.setup(self._H, self._f, self._A, self._bupper, self._blower, self._sense.copy())
        if flag < 0:
            raise SolverError(f"daqp setup failed with exit flag {flag}")
        model.settings = self._settings
        return model

    def solve(self, f=None, lb=None, ub=None, bl=None, bu=None, A=None):
        n = self._n
        if f is not None:
            self._f = np.array(f, dtype=float)
        if lb is not None:
            self._blower[:n] = lb
        if ub is not None:
            self._ub = np.array(ub, dtype=float)
        self._bupper[:n] = _widen(self._blower[:n], self._ub)
        if bl is not None:
            self._blower[n:] = bl
        if bu is not None:
            self._bupper[n:] = bu
        if A is not None:
            self._A = np.array(A, dtype=float, order="C")
        x, _fval, flag, info = self._setup().solve()
        if flag < 1 or not np.all(np.isfinite(x)):
            raise SolverError(f"daqp returned exit flag {flag}")
        return x, info["iterations"]


class _Chain:
    """A fast primary backend with a robust secondary built on the primary's first failure."""

    def __init__(self, primary, make_secondary, data: dict) -> None:
        self._primary = primary
        self._make_secondary = make_secondary
        self._secondary = None
        self._data = {key: np.array(val, dtype=float) for key, val in data.items()}

    def solve(self, f=None, lb=None, ub=None, bl=None, bu=None, A=None):
        upd = dict(f=f, lb=lb, ub=ub, bl=bl, bu=bu, A=A)
        for key, val in upd.items():
            if val is not None:
                self._data[key] = np.array(val, dtype=float)
        try:
            return self._primary.solve(**upd)
        except SolverError as first:
            try:
                if self._secondary is None:
                    self._secondary = self._make_secondary(self._data)
                    return self._secondary.solve()
                return self._secondary.solve(**self._data)
            except SolverError as second:
                raise SolverError(f"{first}; then {second}") from second


class _Highs:
    """HiGHS LP, a new model per solve, so each answer is a function of this call's costs,
    bounds and matrix alone.

    A kept model, even with its solver state cleared (``clearSolver``) before each solve,
    answered differently after earlier calls where the LP optimum is not unique (B near
    1e-100, a zero row, duplicated columns: u differing by up to 0.95 between the same
    demand's fresh and history-laden calls, both ``exact``); changing coefficients one by one
    also keeps the earlier sparsity pattern.  A fresh model costs a model hand-over per solve
    (``benchmarks/bench_alloc.py``); the matrix is converted to CSC only when it changes.
    """

    def __init__(self, f, A, bl, bu, lb, ub) -> None:
        import highspy  # noqa: F401 - fails here, at build, when HiGHS is absent

        self._f = np.array(f, dtype=float)
        self._A = np.array(A, dtype=float)
        self._csc = _to_csc(self._A)
        self._bl, self._bu = np.array(bl, dtype=float), np.array(bu, dtype=float)
        self._lb, self._ub = np.array(lb, dtype=float), np.array(ub, dtype=float)

    def _model(self):
        import highspy as hs  # a module is not kept on the object: a backend pickles (alloc.Allocator)

        h = hs.Highs()
        h.setOptionValue("output_flag", False)
        h.setOptionValue("simplex_iteration_limit", ITERATION_LIMITS["highs"])
        h.setOptionValue("ipm_iteration_limit", ITERATION_LIMITS["highs"])
        lp = hs.HighsLp()
        n, mA = int(self._f.size), int(self._A.shape[0])
        lp.num_col_, lp.num_row_ = n, mA
        lp.col_cost_, lp.col_lower_, lp.col_upper_ = self._f, self._lb, self._ub
        lp.row_lower_, lp.row_upper_ = self._bl, self._bu
        lp.a_matrix_.format_ = hs.MatrixFormat.kColwise
        lp.a_matrix_.start_, lp.a_matrix_.index_, lp.a_matrix_.value_ = self._csc
        lp.a_matrix_.num_col_, lp.a_matrix_.num_row_ = n, mA
        h.passModel(lp)
        return h

    def solve(self, f=None, lb=None, ub=None, bl=None, bu=None, A=None):
        for name, value in (("_f", f), ("_lb", lb), ("_ub", ub), ("_bl", bl), ("_bu", bu), ("_A", A)):
            if value is not None:
                setattr(self, name, np.array(value, dtype=float))
        if A is not None:
            self._csc = _to_csc(self._A)
        import highspy

        h = self._model()
        h.run()
        status = h.getModelStatus()
        if status != highspy.HighsModelStatus.kOptimal:
            raise SolverError(f"highs returned model status {h.modelStatusToString(status)}")
        x = np.array(h.getSolution().col_value, dtype=float)
        if not np.all(np.isfinite(x)):
            raise SolverError("highs returned non-finite values")
        return x, int(h.getInfo().simplex_iteration_count)


class _Qpsolvers:
    """Any qpsolvers backend; the problem is rebuilt on every call (slow, for cross-checks)."""

    def __init__(self, name, H, f, A, bl, bu, lb, ub) -> None:
        import qpsolvers

        if name not in qpsolvers.available_solvers:
            raise OptionError(f"backend: {name!r} is not available; available: {backends()}")
        self._name = name
        self._H = np.array(H, dtype=float)
        self._f, self._A = np.array(f, dtype=float), np.array(A, dtype=float)
        self._bl, self._bu = np.array(bl, dtype=float), np.array(bu, dtype=float)
        self._lb, self._ub = np.array(lb, dtype=float), np.array(ub, dtype=float)

    def solve(self, f=None, lb=None, ub=None, bl=None, bu=None, A=None):
        import qpsolvers

        f = self._f if f is None else f
        lb = self._lb if lb is None else lb
        ub = self._ub if ub is None else ub
        bl = self._bl if bl is None else bl
        bu = self._bu if bu is None else bu
        A = self._A if A is None else A
        eq = bl == bu
        G_parts, h_parts = [], []
        up_rows = ~eq & np.isfinite(bu)
        lo_rows = ~eq & np.isfinite(bl)
        if up_rows.any():
            G_parts.append(A[up_rows])
            h_parts.append(bu[up_rows])
        if lo_rows.any():
            G_parts.append(-A[lo_rows])
            h_parts.append(-bl[lo_rows])
        G = np.vstack(G_parts) if G_parts else None
        h = np.concatenate(h_parts) if h_parts else None
        Aeq = A[eq] if eq.any() else None
        beq = bu[eq] if eq.any() else None
        try:
            x = qpsolvers.solve_qp(self._H, f, G, h, Aeq, beq, lb, ub, solver=self._name,
                                   **_TIGHT.get(self._name, {}))
        except Exception as exc:  # backend errors are re-raised as SolverError
            raise SolverError(f"{self._name} failed: {exc}") from exc
        if x is None or not np.all(np.isfinite(x)):
            raise SolverError(f"{self._name} found no solution")
        return np.asarray(x, dtype=float), 0


#: Iteration bounds per solve, the only bound on a backend's work (no wall-clock limit: the
#: same call must give the same answer on an idle and on a busy machine).  Measured on 791
#: solves of ``qp`` and ``wls`` on ICE and seeded 3 x 8 and 6 x 16 problems of every kind in
#: :data:`alloc.testing.KINDS` (tests/alloc/test_backend_determinism.py checks the load independence):
#:
#: - ``daqp``: an active-set solver needs about one iteration per constraint that enters or
#:   leaves the working set (tens at m <= 64); 2,000 stops only a cycling solve.
#: - ``highs``: ``lp`` and ``da`` calls took at most 40 simplex iterations over 1,560 calls
#:   (ICE, 3 x 8 to 6 x 30 of every kind, 60 degenerate problems; median 3); 10,000 stops
#:   only a cycling or stalled solve.
#: - ``osqp``: ADMM at the tightened tolerances: median 75 iterations; 765 of 791 solves end
#:   within 20,000, 17 within 50,000, 4 within 100,000, 3 within 200,000 and 2 never.  At
#:   4.5 us an iteration, 100,000 bounds a solve to about half a second; the 5 solves beyond
#:   it (0.6 %) become the allocator's fallback.
#: - ``scs``: at most 875 iterations measured (median 50); 20,000 stops only a stalled solve.
#: - ``clarabel``: an interior-point method; none of the 791 solves reached its default 200.
#:
#: Reaching a bound is a SolverError, so the allocator answers with its fallback.
ITERATION_LIMITS = {"daqp": 2000, "highs": 10_000, "osqp": 100_000, "scs": 20_000, "clarabel": 200}

# Stock tolerances of first-order/interior-point solvers do not resolve the small
# regularisation terms of allocation QPs (SOLVER-NOTES); tighten them, and bound their
# iterations (never their time: the solvers' default time limits are off, see ITERATION_LIMITS).
_TIGHT = {
    "osqp": {"eps_abs": 1e-9, "eps_rel": 1e-9, "polish": True, "max_iter": ITERATION_LIMITS["osqp"]},
    "clarabel": {"tol_gap_abs": 1e-10, "tol_gap_rel": 1e-10, "tol_feas": 1e-10,
                 "max_iter": ITERATION_LIMITS["clarabel"]},
    "scs": {"max_iters": ITERATION_LIMITS["scs"]},
}


def _widen(lb: FloatArray, ub: FloatArray) -> FloatArray:
    """Upper bounds nudged above collapsed ones (a jammed effector, ``lb == ub``).

    DAQP treats ``lb == ub`` as an equality; with the allocation equalities this can
    make its initial active set overdetermined (exit flag -6).  A gap of 1e-12 relative
    avoids that; the allocator clips the result back onto the limits.
    """
    ub = np.asarray(ub, dtype=float)
    return np.maximum(ub, np.asarray(lb, dtype=float) + 1e-12 * (1.0 + np.abs(ub)))


def _to_csc(A: FloatArray) -> tuple[NDArray[np.int32], NDArray[np.int32], FloatArray]:
    """Dense matrix to CSC (start, index, value), keeping explicit structural entries."""
    from scipy.sparse import csc_matrix

    M = csc_matrix(np.asarray(A, dtype=float))
    return M.indptr.astype(np.int32), M.indices.astype(np.int32), M.data.astype(float)
