"""A small internal interface to well-kept QP/LP solvers, built once and updated per call.

Every backend solves

    minimise 0.5 x' H x + f' x   subject to  lb <= x <= ub,  bl <= A x <= bu

where ``H`` may be ``None`` (a linear program) and rows with ``bl == bu`` are
equalities.  A backend is set up once (the solver model is kept) and each call
only updates the data that change (cost vector, bounds, sometimes ``A``), so
the hot path never rebuilds a model.  Measured costs are in
``benchmarks/bench_alloc.py`` and the README.

Backends
--------
``daqp``
    DAQP's dual active-set solver through a persistent ``daqp.Model`` (default for QPs
    and LPs: a few microseconds on allocation-sized problems; LPs and singular
    Hessians use its proximal-point iterations).
``highs``
    HiGHS (highspy), the model passed afresh per call (history-independent); LPs only.
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
    """Build backend ``name`` for the given problem structure.

    ``singular`` says the Hessian is only positive semidefinite (DAQP then uses its
    proximal-point iterations).
    """
    lp = H is None
    if name == "daqp":
        primary = _Daqp(H, f, A, bl, bu, lb, ub, singular=singular or lp)
        if lp:
            # DAQP's proximal-point LP reports false infeasibility or cycling on a few
            # degenerate allocation LPs (~0.3 % of the random suites); HiGHS' simplex
            # re-solves exactly those calls.
            return _Chain(primary, lambda d: _Highs(d["f"], d["A"], d["bl"], d["bu"], d["lb"], d["ub"]),
                          dict(f=f, A=A, bl=bl, bu=bu, lb=lb, ub=ub))
        return primary
    if name == "highs":
        if not lp:
            raise OptionError("backend: 'highs' is used for linear programs only (it returns wrong QP answers, see SOLVER-NOTES)")
        return _Highs(f, A, bl, bu, lb, ub)
    if lp:
        raise OptionError(f"backend: {name!r} is not an LP backend; use one of {backends(lp=True)}")
    return _Qpsolvers(name, H, f, A, bl, bu, lb, ub)


class _Daqp:
    """Persistent DAQP workspace (``daqp.Model``)."""

    _EQ = 5  # DAQP sense flag of an equality constraint

    def __init__(self, H, f, A, bl, bu, lb, ub, *, singular: bool) -> None:
        import daqp

        self._n = int(f.size)
        # daqp.Model needs a matrix: an LP is a QP with H = 0 solved by proximal-point iterations.
        self._H = np.zeros((f.size, f.size)) if H is None else np.array(H, dtype=float, order="C")
        self._A = np.array(A, dtype=float, order="C")
        self._bupper = np.concatenate([_widen(lb, ub), bu]).astype(float)
        self._blower = np.concatenate([lb, bl]).astype(float)
        self._sense = np.zeros(self._bupper.size, dtype=np.int32)
        self._sense[self._n:][bl == bu] = self._EQ
        self._f = np.array(f, dtype=float)
        self._model = daqp.Model()
        flag, _ = self._model.setup(self._H, self._f, self._A, self._bupper, self._blower, self._sense)
        if flag < 0:
            raise SolverError(f"daqp setup failed with exit flag {flag}")
        settings = {"iter_limit": 2000}
        if singular:
            settings["eps_prox"] = 1e-6
        self._model.settings = settings
        self._settings = settings
        self._daqp = daqp
        self._cold = H is None
        self._base_sense = self._sense.copy()
        self._last_lb = self._last_ub = None
        self._bupper_src = np.array(ub, dtype=float)

    def solve(self, f=None, lb=None, ub=None, bl=None, bu=None, A=None):
        n = self._n
        upd: dict = {}
        if f is not None:
            upd["f"] = f
        # Simple bounds are re-sent unless the caller passes the same read-only array as
        # last time (the problem's position limits, on every call without rate limits);
        # a writeable array may have been changed in place, so it is always sent.
        if lb is not None and not (lb is self._last_lb and not lb.flags.writeable):
            self._blower[:n] = lb
            self._last_lb = lb
            upd["blower"] = self._blower
            ub = self._bupper_src if ub is None else ub
            self._last_ub = None
        if ub is not None and not (ub is self._last_ub and not ub.flags.writeable):
            self._bupper[:n] = _widen(self._blower[:n], ub)
            self._bupper_src = ub
            self._last_ub = ub
            upd["bupper"] = self._bupper
        if bl is not None:
            self._blower[n:] = bl
            upd["blower"] = self._blower
        if bu is not None:
            self._bupper[n:] = bu
            upd["bupper"] = self._bupper
        if A is not None:
            upd["A"] = A if A.flags.c_contiguous and A.flags.writeable else np.array(A, dtype=float, order="C")
        if self._cold:
            # LPs (proximal-point iterations): DAQP keeps iterate state across solves, so a
            # degenerate LP's vertex would depend on the call history; a new workspace per
            # call makes the answer a function of the data alone.
            if "f" in upd:
                self._f = np.array(upd["f"], dtype=float)
            if A is not None:
                self._A = np.array(A, dtype=float, order="C")
            self._model = self._daqp.Model()
            flag, _ = self._model.setup(self._H, self._f, self._A, self._bupper, self._blower, self._base_sense)
            if flag < 0:
                raise SolverError(f"daqp setup failed with exit flag {flag}")
            self._model.settings = self._settings
        elif upd:
            upd["sense"] = self._base_sense  # cold start: no stale active set across updates
            flag = self._model.update(**upd)
            if flag < 0:
                raise SolverError(f"daqp update failed with exit flag {flag}")
        x, _fval, flag, info = self._model.solve()
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
    """HiGHS LP, passed afresh on every solve.

    A kept model (even with ``clearSolver``) remembers the sparsity pattern and bounds of
    earlier calls, and where the LP optimum is not unique (a ray through an AMS edge) the
    simplex then lands on another vertex: answers would depend on call history.  Passing
    the model anew makes every answer a function of this call's data alone.
    """

    def __init__(self, f, A, bl, bu, lb, ub) -> None:
        import highspy

        self._hs = highspy
        self._f = np.array(f, dtype=float)
        self._A = np.array(A, dtype=float)
        self._bl, self._bu = np.array(bl, dtype=float), np.array(bu, dtype=float)
        self._lb, self._ub = np.array(lb, dtype=float), np.array(ub, dtype=float)

    def _model(self):
        hs = self._hs
        h = hs.Highs()
        h.setOptionValue("output_flag", False)
        lp = hs.HighsLp()
        n, mA = int(self._f.size), int(self._A.shape[0])
        lp.num_col_, lp.num_row_ = n, mA
        lp.col_cost_, lp.col_lower_, lp.col_upper_ = self._f, self._lb, self._ub
        lp.row_lower_, lp.row_upper_ = self._bl, self._bu
        lp.a_matrix_.format_ = hs.MatrixFormat.kColwise
        lp.a_matrix_.start_, lp.a_matrix_.index_, lp.a_matrix_.value_ = _to_csc(self._A)
        lp.a_matrix_.num_col_, lp.a_matrix_.num_row_ = n, mA
        h.passModel(lp)
        return h

    def solve(self, f=None, lb=None, ub=None, bl=None, bu=None, A=None):
        for name, value in (("_f", f), ("_lb", lb), ("_ub", ub), ("_bl", bl), ("_bu", bu), ("_A", A)):
            if value is not None:
                setattr(self, name, np.array(value, dtype=float))
        h = self._model()
        h.run()
        status = h.getModelStatus()
        if status != self._hs.HighsModelStatus.kOptimal:
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
            G_parts.append(A[up_rows]); h_parts.append(bu[up_rows])
        if lo_rows.any():
            G_parts.append(-A[lo_rows]); h_parts.append(-bl[lo_rows])
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


#: Wall-clock bound (s) per solve handed to the iterative qpsolvers backends (a qp call with
#: priorities solves up to k + 1 stages, so at most 0.7 s a call): on badly scaled problems
#: (B ~ 1e47) OSQP and SCS otherwise iterate for seconds to minutes (adversarial suite); a
#: time-out is a SolverError, so the allocator answers with its fallback.
QP_TIME_LIMIT_S = 0.1

# Stock tolerances of first-order/interior-point solvers do not resolve the small
# regularisation terms of allocation QPs (SOLVER-NOTES); tighten them, and bound their time.
_TIGHT = {
    "osqp": {"eps_abs": 1e-9, "eps_rel": 1e-9, "polish": True, "max_iter": 200000, "time_limit": QP_TIME_LIMIT_S},
    "clarabel": {"tol_gap_abs": 1e-10, "tol_gap_rel": 1e-10, "tol_feas": 1e-10, "time_limit": QP_TIME_LIMIT_S},
    "scs": {"time_limit_secs": QP_TIME_LIMIT_S},
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
