"""Direct allocation by facet search (seed sections 1.3.4.2.1-1.3.4.2.3, Eqs 1.15-1.17).

Same convention as the core's LP-based ``da``: base point ``u0 = clip(up, lo, hi)``,
``d = v - B u0``; the ray ``B u0 + a d`` leaves the AMS at ``a*`` through a facet with
boundary control ``u*``; ``a* >= 1`` gives ``u = u0 + (u* - u0) / a*`` (Eq 1.15, so
``B u = v``), otherwise ``u = u*`` (status ``unattainable``).

``da_facet``
    Sequential facet search (1.3.4.2.1): for every tile (a facet's parallelogram, Eq 1.16)
    the inverse of ``[corner - B u0, edge_1, ..., edge_(k-1)]`` is stored at build time;
    a call is one stacked matrix-vector product and the Eq 1.17 test
    ``a > 0, 0 <= b_i <= 1`` over all tiles at once (the tile satisfying it best wins, so
    rays through an edge are handled).  Any k.
``da_bisect``
    Durham's edge-bisecting search (1.3.4.2.2), k = 3: ``d`` is turned into the x-axis;
    for a rotation angle about it the AMS is projected onto the (x, y) plane and the
    silhouette edge crossing the positive x-axis is found by a weighted median over the
    generators (O(m log m), no facet list); the sign of that edge's z-coordinate brackets
    the ray and the angle interval is cut (``angles`` per round) until the two bracketing
    edges span a facet that passes Eq 1.17.  Work grows about linearly with m.
``da_table``
    Spherical look-up table (1.3.4.2.3, Peterson and Bodson's option 2), k = 3: azimuth and
    elevation of ``d`` quantised (option ``resolution``); each cell stores the tiles hit by
    its centre and corners; a call tests those few (Eq 1.17) and falls back to the
    sequential search when none passes, so it stays exact.  ``build_time`` is the
    (re)build cost after an effector failure.

Rate limits: the facet *structure* depends only on the columns' directions, so with
``u_prev``/``dt`` the search is the support-function form over the same facets with gaps
recomputed from the call's bounds (:meth:`AttainableSet.ray_exit`): exact, no LP.  Other
``k`` than 3 make ``da_bisect``/``da_table`` use the sequential search.  A flat AMS
(rank B < k) is searched the same way in an orthonormal basis of its hull (a demand off its
hull has ``a* = 0``; :meth:`AttainableSet.ray_exit` is the reference).  Every per-call
product is a compiled loop in a fixed order, never numpy's ``@``: BLAS and numpy's own loops
round differently by the operands' layout, and a copy of an allocator must answer bit for bit.

``da_facet`` and the family's cost model live here; ``da_bisect`` in
:mod:`alloc.methods.edge_bisect`, ``da_table`` in :mod:`alloc.methods.spherical_table`.
The geometry is :mod:`alloc.ams`'s public API only (:class:`~alloc.ams.AttainableSet`, its
:attr:`~alloc.ams.AttainableSet.tiling` and ``ray_exit``); the per-call searches are compiled
in :mod:`alloc.methods._facet_kernels`.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from ..ams.geometry import AttainableSet
from ..exceptions import OptionError, SolverError
from ..facet_cost import (_CALL_BASE_S, _CALL_SUBSET_K2_S, _CALL_SUBSET_M_S, FACET_BYTES, FACET_LIMIT,
                           FACET_SECONDS, NEAR_FLAT_RTOL, TILES_PER_SUBSET, facet_build_bytes, facet_build_seconds,
                           lp_build_bytes, near_flat_ratio)
from ..problem import Problem
from ..method import BUILD_LIMIT_BYTES, BUILD_LIMIT_SECONDS, FloatArray, Method, register
from . import _facet_kernels as _kernels
from ._direct_lp import RayLP

__all__ = ["FacetSearch", "FACET_LIMIT", "FACET_SECONDS", "FACET_BYTES",
           "facet_build_seconds", "facet_build_bytes"]

_EQ = "Eqs 1.15-1.17"
_TOL = 1e-10  # Eq 1.17 slack, relative (rays through an edge satisfy two tiles up to round-off)


def _kernel_array(a: Any, dtype: Any = None) -> np.ndarray:
    """``a`` as a C-contiguous, writable array (copied only when it is not one).

    numba compiles one version of a kernel per argument type, and writeability is part of
    the type: the tiling's read-only views would be one type in the original and another in
    a pickled copy (unpickled arrays are writable), so the copy's first call would compile."""
    a = np.asarray(a, dtype=dtype)
    if a.flags.c_contiguous and a.flags.writeable:
        return a
    return np.array(a, order="C")


def _int_option(value: object, field: str, lo: int, hi: int, method: str = "da_bisect") -> int:
    """An integer option in ``[lo, hi]`` (bounded: it sizes build-time tables); OptionError otherwise."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)) or not lo <= value <= hi:
        raise OptionError(f"{method}: {field} must be an integer in [{lo}, {hi}], got {value!r}")
    return int(value)


@register("da_facet", needs_ams=True, supports_batch=True, family="da")
class FacetSearch(Method):
    """Direct allocation by sequential facet search over precomputed facet inverses."""

    equation = _EQ
    summary = "direct allocation: sequential facet search over stored facet inverses (Eq 1.16-1.17)"
    options = {}

    @classmethod
    def enumeration_cost(cls, problem: Problem, options: dict[str, Any] | None = None) -> tuple[float, int]:
        """Declared ``(seconds, bytes)`` of the facet enumeration and its search tables
        (:func:`facet_build_seconds`, :func:`facet_build_bytes`; subclasses add their own tables)."""
        subsets, k, m = cls.facet_subsets(problem, options or {}), problem.k, problem.m
        return facet_build_seconds(subsets, k, m), facet_build_bytes(subsets, k, m)

    @classmethod
    def build_cost(cls, problem: Problem, **options: Any) -> float:
        """The facet enumeration (:meth:`enumeration_cost`).  Above the build bounds the
        method builds the LP instead (milliseconds); the declared cost stays the
        enumeration's, so that a budget refuses what the method's name promises."""
        return cls.enumeration_cost(problem, options)[0]

    @classmethod
    def build_memory(cls, problem: Problem, **options: Any) -> int:
        """The facet tables (:meth:`enumeration_cost`); the LP's where the build is routed there
        (:func:`alloc.facet_cost.lp_build_bytes`)."""
        if cls.redirected(problem, options):
            return lp_build_bytes(problem.k, problem.m)
        return cls.enumeration_cost(problem, options)[1]

    @classmethod
    def redirected(cls, problem: Problem, options: dict[str, Any] | None = None) -> str:
        """Why the build uses the LP formulation instead of enumerating ("" if it does not):
        a nearly rank-deficient ``B`` (:func:`near_flat_ratio`), or the enumeration's declared
        time or memory beyond the build bounds."""
        ratio = near_flat_ratio(problem)
        if ratio:
            return (f"B is nearly rank-deficient (singular value ratio {ratio:.1e} of its unit columns, below "
                    f"{NEAR_FLAT_RTOL:g}): its facet tiling is not priced")
        seconds, nbytes = cls.enumeration_cost(problem, options)
        if seconds > BUILD_LIMIT_SECONDS:
            return (f"the facet enumeration's declared build time {seconds:.3g} s exceeds the build bound of "
                    f"{BUILD_LIMIT_SECONDS:g} s")
        if nbytes > BUILD_LIMIT_BYTES:
            return (f"the facet tables' declared memory {nbytes / 2**20:,.0f} MiB exceeds the build bound of "
                    f"{BUILD_LIMIT_BYTES / 2**20:,.0f} MiB")
        return ""

    @classmethod
    def call_cost(cls, problem: Problem, **options: Any) -> float:
        """A nominal call scans every tile (``O(S k^2)``), a rate-limited call recomputes every
        facet's gap (``O(S m)``): ``1 ms + S (0.05 k^2 + 0.02 m) us``; the LP's cost
        (:meth:`Method.call_cost`) when the build is redirected."""
        if cls.redirected(problem, options):
            return super().call_cost(problem, **options)
        subsets = cls.facet_subsets(problem, options)
        return _CALL_BASE_S + subsets * (_CALL_SUBSET_K2_S * problem.k ** 2 + _CALL_SUBSET_M_S * problem.m)

    def __init__(self, problem: Problem) -> None:
        super().__init__(problem)
        t0 = time.perf_counter()
        self.fallbacks = 0
        #: the LP formulation of Eqs 1.15-1.17 (``da``'s LP backend) when the facet search
        #: cannot be built: a set too large to enumerate within the build bounds, or
        #: degenerate geometry (nearly rank-deficient or coplanar beyond tolerance) that the
        #: exact search cannot tile
        self._lp: Method | None = None
        self.lp_reason = ""
        too_large = self.redirected(problem)
        if too_large:
            self._use_lp(too_large)
        else:
            try:
                # more tiles than the model prices (a tiling in general position has 2 per
                # subset) only come from uneven tolerance merging: the LP instead
                limit = TILES_PER_SUBSET * max(self.facet_subsets(problem, {}), 1)
                self.ams = AttainableSet(problem, tile_limit=limit)
                self._prepare()
            except Exception as exc:  # noqa: BLE001 - degenerate geometry: handled, not refused
                self._use_lp(f"{type(exc).__name__}: {exc}")
        self.build_time = time.perf_counter() - t0

    @property
    def uses_lp(self) -> bool:
        """The build took the LP formulation (:attr:`lp_reason` says why) instead of the facets."""
        return self._lp is not None

    @property
    def tile_count(self) -> int:
        """Tiles of the attainable set's boundary the search looks through (0 on the LP or on a
        flat set, which is searched otherwise)."""
        if self._lp is not None or getattr(self, "_flat", True):
            return 0
        return len(self._tiles)

    def _use_lp(self, reason: str) -> None:
        # the LP formulation of the same problem (the compiled ray simplex, DAQP behind it)
        self._lp = RayLP(self.problem, backend="daqp", simplex=True)
        self.lp_reason = reason

    # ------------------------------------------------------------ tables
    def _prepare(self) -> None:
        ams, p = self.ams, self.problem
        self._u0 = ams.base_u
        self._p0 = ams.base_v
        self._umin, self._umax = p.umin, p.umax
        self._flat = ams.rank < p.k or ams.rank == 0
        if self._flat:
            # as the core's ``da``: the ray follows the part of d in the range of B
            U, sv, _ = np.linalg.svd(p.B, full_matrices=False)
            Qb = U[:, sv > 1e-10 * sv[0]] if sv.size and sv[0] > 0 else np.zeros((p.k, 0))
            self._range_proj = Qb @ Qb.T
            self._prepare_flat_kernel()
            return
        k = p.k
        scale = np.abs(ams.tiling.normal_columns).sum(axis=1) * np.abs(p.umax - p.umin).max() + 1e-300
        base = ams.tiling.gaps <= 1e-12 * scale  # facets through the base point: Eq 1.16 is singular there
        self._Nz = ams.tiling.normals[base]
        keep = ~base[ams.tiling.tile_facet]
        tiles = np.flatnonzero(keep)
        self._tiles = tiles
        span = ams.tiling.tile_span[tiles]  # (T, k-1)
        M = np.empty((len(tiles), k, k))
        M[:, :, 0] = ams.tiling.tile_corner[tiles] - self._p0
        M[:, :, 1:] = np.moveaxis(ams.tiling.generators[:, span], 0, 1)
        self._Minv = np.linalg.inv(M)
        self._Minv2 = self._Minv.reshape(-1, k)  # X = (Minv2 @ d).reshape(T, k): one BLAS call
        self._U = ams.tiling.tile_u[tiles]  # (T, m) corner controls
        self._S = ams.tiling.class_steps[span]  # (T, k-1, m) edge steps in u
        self._facet_of_tile = ams.tiling.tile_facet[tiles]
        self._prepare_kernels()

    def _prepare_kernels(self) -> None:
        """Contiguous copies of the tables the compiled kernels read (full-rank sets only)."""
        ams = self.ams
        f64 = _kernel_array
        self._kMinv, self._kU, self._kS = f64(self._Minv), f64(self._U), f64(self._S)
        self._kNz, self._kp0, self._ku0 = f64(self._Nz), f64(self._p0), f64(self._u0)
        # rate-limited box: the facet structure with gaps and tiles placed per call
        t = ams.tiling
        self._kray = (f64(self.problem.B), f64(t.B), f64(t.normals), f64(t.normal_columns), f64(t.class_members),
                      f64(ams.sign, dtype=float), f64(ams.active), f64(t.tile_hi), f64(t.tile_span),
                      np.searchsorted(t.tile_facet, np.arange(ams.n_facets + 1)).astype(np.intp))

    def _prepare_flat_kernel(self) -> None:
        """The flat set's tables in an orthonormal basis ``Q`` of its hull (the row space of
        its facet normals), for the compiled search: every call is then loops in a fixed
        order, whatever the memory layout of the arrays (numpy's BLAS paths are not)."""
        ams, p = self.ams, self.problem
        k, m, r = p.k, p.m, ams.rank
        f64 = _kernel_array
        if r == 0:
            Q, Br, Nr = np.zeros((k, 0)), np.zeros((0, m)), np.zeros((0, 0))
            NB, tile_hi, tile_span = np.zeros((0, m)), np.zeros((0, m), dtype=bool), np.zeros((0, 0), dtype=np.intp)
            ptr = np.zeros(1, dtype=np.intp)
        else:
            t = ams.tiling
            Q = np.linalg.svd(ams.normals, full_matrices=False)[2][:r].T  # (k, r)
            Br, Nr, NB, tile_hi, tile_span = Q.T @ p.B, ams.normals @ Q, t.normal_columns, t.tile_hi, t.tile_span
            ptr = np.searchsorted(t.tile_facet, np.arange(ams.n_facets + 1)).astype(np.intp)
        self._kflat = (f64(p.B), f64(self._range_proj), f64(Q), f64(Br), f64(Nr), f64(NB),
                       f64(ams.tiling.class_members), f64(ams.sign, dtype=float), f64(ams.active), f64(tile_hi),
                       f64(tile_span, dtype=np.intp), f64(ptr))

    def _nominal(self, lo: FloatArray, hi: FloatArray) -> bool:
        return (lo is self._umin or np.array_equal(lo, self._umin)) and (
            hi is self._umax or np.array_equal(hi, self._umax))

    # ------------------------------------------------------------ search
    def _tile_test(self, X: FloatArray) -> tuple[int, float]:
        """Eq 1.17 on rows ``X = [1/a, b/a, c/a, ...]``: the best tile and its margin."""
        x0 = X[:, 0]
        P = X[:, 1:]
        with np.errstate(divide="ignore", invalid="ignore"):
            score = np.minimum(P, x0[:, None] - P).min(axis=1, initial=np.inf) / x0
        score[~(x0 > 0)] = -np.inf
        t = int(np.argmax(score))
        return t, float(score[t])

    def _boundary(self, d: FloatArray) -> tuple[float, FloatArray]:
        """``(a*, u*)`` for the nominal box (subclasses replace the tile search)."""
        t, _ = self._tile_test((self._Minv2 @ d).reshape(-1, self.problem.k))
        return self._from_tile(t, (self._Minv[t] @ d))

    def _from_tile(self, t: int, x: FloatArray) -> tuple[float, FloatArray]:
        a = 1.0 / x[0]
        b = np.minimum(np.maximum(x[1:] * a, 0.0), 1.0)
        return a, self._U[t] + b @ self._S[t]

    def solve(self, v, lo, hi, u_prev):
        """Compiled search (:mod:`alloc.methods._facet_kernels`); answers as :meth:`_solve_reference`."""
        if self._lp is not None:
            return self._lp.solve(v, lo, hi, u_prev)
        if self._flat:
            u, iterations = _kernels.flat_ray_exit_solve(v, self.problem.up, lo, hi, *self._kflat)
        elif not self._nominal(lo, hi):
            u, iterations = _kernels.ray_exit_solve(v, self.problem.up, lo, hi, *self._kray)
        else:
            return self._solve_nominal(v)
        if iterations < 0:
            raise SolverError("AMS: no facet ahead of the ray (degenerate facet structure)")
        return u, iterations

    def _solve_nominal(self, v: FloatArray) -> tuple[FloatArray, int]:
        return _kernels.facet_solve(v, self._kp0, self._ku0, self._kNz, self._kMinv, self._kU, self._kS)

    def _solve_reference(self, v, lo, hi, u_prev):
        """The numpy implementation the kernels reproduce (kept for tests and flat sets)."""
        p = self.problem
        if self._lp is not None:
            return self._lp.solve(v, lo, hi, u_prev)
        if self._flat or not self._nominal(lo, hi):
            u0 = np.minimum(np.maximum(p.up, lo), hi)
            d = v - p.B @ u0
            if self._flat:
                d = self._range_proj @ d
            if not np.abs(d).max() > 1e-14 * max(1.0, float(np.abs(v).max())):
                return u0, 0
            a, ustar, _ = self.ams.ray_exit(d, lo=lo, hi=hi, u0=u0)
        else:
            u0 = self._u0
            d = v - self._p0
            if not np.abs(d).max() > 1e-14 * max(1.0, float(np.abs(v).max())):
                return u0.copy(), 0
            if self._Nz.size and (self._Nz @ d > 1e-12 * np.linalg.norm(d)).any():
                return u0.copy(), 0  # the ray leaves at once through a facet holding the base point
            a, ustar = self._boundary(d)
        if a >= 1.0:
            return u0 + (ustar - u0) / a, 1  # Eq 1.15
        return ustar, 1

    def solve_batch(self, V, lo, hi):
        """The compiled single-call search over the rows of ``V`` (one call, no Python loop):
        a batch row is bitwise the single call ``solve(V[i])``.  Subclasses with their own
        nominal search (``da_bisect``, ``da_table``) return ``None``: the allocator then
        runs their single calls row by row, so batch equals single for them too."""
        if (self._lp is not None or self._flat or type(self)._solve_nominal is not FacetSearch._solve_nominal
                or not self._nominal(lo, hi)):
            return None
        return _kernels.facet_solve_batch(np.ascontiguousarray(V), self._kp0, self._ku0, self._kNz,
                                          self._kMinv, self._kU, self._kS)

    def _solve_batch_support(self, V, lo, hi):
        """Vectorised over demands in numpy (kept as a reference; :meth:`solve_batch` is
        the compiled per-row search).  The facet is picked in support-function form (one
        (N, F) product: ``a* = min gap / (n . d)``), then Eq 1.16 runs on that facet's tiles
        only; testing every tile for every demand would touch (N, T, k) arrays."""
        if self._lp is not None or self._flat or not self._nominal(lo, hi):
            return None
        if not hasattr(self, "_facet_pad"):
            self._pad_tiles()
        N = len(V)
        ams = self.ams
        D = V - self._p0
        U = np.empty((N, self.problem.m))
        chunk = max(1, 1_000_000 // max(1, ams.n_facets))
        for s in range(0, N, chunk):
            Dc = D[s:s + chunk]
            n = len(Dc)
            rows = np.arange(n)
            ND = Dc @ ams.tiling.normals.T
            with np.errstate(divide="ignore", invalid="ignore"):
                R = np.where(ND > 1e-12 * np.linalg.norm(Dc, axis=1, keepdims=True), ams.tiling.gaps / ND, np.inf)
            f = np.argmin(R, axis=1)
            a = np.maximum(R[rows, f], 0.0)
            tl = self._facet_pad[f]  # (n, P) tile positions, -1 padded
            X = np.einsum("npij,nj->npi", self._Minv[np.maximum(tl, 0)], Dc)
            x0, P = X[:, :, 0], X[:, :, 1:]
            with np.errstate(divide="ignore", invalid="ignore"):
                score = np.minimum(P, x0[:, :, None] - P).min(axis=2, initial=np.inf) / x0
            score[~(x0 > 0) | (tl < 0)] = -np.inf
            j = np.argmax(score, axis=1)
            t = np.maximum(tl[rows, j], 0)
            xt = X[rows, j]
            with np.errstate(divide="ignore", invalid="ignore"):
                b = np.clip(xt[:, 1:] / xt[:, :1], 0.0, 1.0)
            ustar = self._U[t] + np.einsum("ni,nim->nm", b, self._S[t])
            att = a >= 1.0
            u = ustar
            u[att] = self._u0 + (ustar[att] - self._u0) / a[att, None]
            still = ~(np.abs(Dc).max(axis=1) > 1e-14 * np.maximum(1.0, np.abs(V[s:s + chunk]).max(axis=1)))
            still |= (a == 0.0) | (tl[rows, j] < 0)
            u[still] = self._u0
            U[s:s + chunk] = u
        return U

    def _pad_tiles(self) -> None:
        """(F, P) positions in the inverse table of each facet's tiles, -1 padded."""
        F = self.ams.n_facets
        per = [np.flatnonzero(self._facet_of_tile == f) for f in range(F)]
        width = max(1, max(len(x) for x in per))
        pad = np.full((F, width), -1, dtype=np.intp)
        for f, x in enumerate(per):
            pad[f, : len(x)] = x
        self._facet_pad = pad
