"""The attainable moment set (AMS) as a zonotope (seed section 1.3.4.2).

The AMS is the image of the effector box under ``B``:

    AMS = {B u : lo <= u <= hi} = c + sum_j [-1, 1] g_j,   c = B (lo + hi) / 2,
    g_j = b_j (hi_j - lo_j) / 2,

a zonotope in ``k`` dimensions.  Its boundary facets (seed: "m(m-1) parallelograms" for
``k = 3`` in general position) are found from the *directions* of the columns only, so
the facet structure survives any change of the box (rate limits, reduced limits) and
only the positions move.

Degenerate suites are handled exactly:

* zero columns and jammed effectors (``lo == hi``) generate nothing;
* collinear columns (ICE: pitch flap and pitch thrust vectoring act only on pitch;
  duplicated effectors) are merged into one *generator class* that moves all its members
  together;
* coplanar classes (ICE: left + right elevon is a pure pitch moment) span one hyperplane;
  its facet is a polygon (a (k-1)-zonotope) with more than four corners.  For the ray
  search such a facet is tiled into parallelepipeds by lifting its generators with
  generic heights and projecting the upper faces back (a regular zonotopal tiling), so
  every tile is an Eq 1.16 parallelogram.

Glossary: the seed's facet vectors ``m_i*, m_(i-j)*, m_(i-k)*`` of Eq 1.16 are a tile's
corner and its edges; ``u_d*`` is the boundary control of :meth:`AttainableSet.max_in_direction`;
``a`` is the scale of Eq 1.15 (the largest ``a`` with ``a d`` attainable from the base point).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..exceptions import DemandError, ProblemError
from ..problem import Problem
from .zonotope import (DIRECTION_TOL, FloatArray, _active, _check_closed, _hyperplanes, _plane_basis, _unit_columns,
                       _upper_tiles, _vertex_signs, generator_classes, zonotope_volume)

__all__ = ["AttainableSet", "Facet", "FacetTiling", "zonotope_volume", "generator_classes", "DIRECTION_TOL"]


# --------------------------------------------------------------------------- the set
@dataclass(frozen=True)
class Facet:
    """One boundary facet of the AMS: ``normal . v <= offset`` with equality on the facet.

    ``free`` are the effectors that move within the facet (two for a parallelogram in
    general position, more for a merged polygon); every other effector sits at ``fixed[j]``
    (its limit by the sign of ``normal . b_j``, or its base position when it generates
    nothing).  ``vertices`` are the facet's corners (ordered around the polygon for k = 3).
    """

    index: int
    normal: FloatArray
    offset: float
    free: tuple[int, ...]
    fixed: FloatArray
    vertices: FloatArray

    @property
    def n_corners(self) -> int:
        return int(len(self.vertices))


def _read_only(a: np.ndarray) -> np.ndarray:
    view = a.view()
    view.flags.writeable = False
    return view


@dataclass(frozen=True)
class FacetTiling:
    """The set's boundary as arrays, in its own coordinates (rank ``r``; ``r = k`` unless flat).

    Every facet is tiled into parallelepipeds (one per simple facet, a zonotopal tiling of a
    merged polygon): tile ``t`` is ``corner[t] + sum_i b_i generators[:, span[t, i]]``,
    ``0 <= b_i <= 1`` (the seed's Eq 1.16 parallelogram for k = 3), reached by the control
    ``tile_u[t] + sum_i b_i class_steps[span[t, i]]``.  This is what a facet search needs
    (Eqs 1.16-1.17); read-only views of the set's own arrays, for the nominal box.

    Attributes
    ----------
    B : (r, m)
        ``Q' B``: the columns in the set's coordinates (``Q`` an orthonormal basis of its hull).
    normals : (F, r)
        Unit outward facet normals.
    normal_columns : (F, m)
        ``normals @ B``: each facet normal against each column.
    gaps : (F,)
        Distance from the base point ``B u0`` to each facet along its normal (>= 0).
    free_classes : (F, C) bool
        Generator classes lying in each facet.
    generators : (r, C)
        Class generators (full length: the class moved from its low to its high end).
    class_members : (C, m)
        1 where effector ``j`` belongs to class ``c``.
    class_steps : (C, m)
        Change of ``u`` moving each class from its low to its high end.
    tile_facet : (T,)
        Facet of each tile (sorted).
    tile_span : (T, r-1)
        Classes spanning each tile.
    tile_hi : (T, m) bool
        Effectors at their upper limit at the tile's corner.
    tile_u : (T, m)
        Control at each tile's corner.
    tile_corner : (T, r)
        Each tile's corner point.
    """

    B: FloatArray
    normals: FloatArray
    normal_columns: FloatArray
    gaps: FloatArray
    free_classes: NDArray[np.bool_]
    generators: FloatArray
    class_members: FloatArray
    class_steps: FloatArray
    tile_facet: NDArray[np.intp]
    tile_span: NDArray[np.intp]
    tile_hi: NDArray[np.bool_]
    tile_u: FloatArray
    tile_corner: FloatArray


class AttainableSet:
    """The attainable moment set of a problem (seed section 1.3.4.2), for k = 1..6.

    Parameters
    ----------
    problem : Problem
    lo, hi : array_like (m,), optional
        The box (default: the position limits).  Effective bounds of a rate-limited step
        (Eq 1.28) give the set reachable in that step.

    Attributes
    ----------
    base_u : ndarray (m,)
        Base point ``u0 = clip(up, lo, hi)``: rays of Eq 1.15 start at ``B u0`` (the core's
        ``da`` convention; ``u0 = 0`` in the seed).
    rank : int
        Dimension of the set; ``rank < k`` means a flat set (volume 0), whose facets are
        then relative to its affine hull.

    Examples
    --------
    >>> from alloc.ams import AttainableSet
    >>> from alloc.vehicles import harv_latdir
    >>> ams = AttainableSet(harv_latdir())
    >>> len(ams.facets), len(ams.vertices)        # m(m-1) and m(m-1)+2 for m = 5
    (20, 22)
    """

    def __init__(self, problem: Problem, lo: ArrayLike | None = None, hi: ArrayLike | None = None, *,
                 tile_limit: int | None = None) -> None:
        # tile_limit: refuse (ProblemError) a tiling of more tiles, counted before any is built
        # (the facet searches' build is priced for at most that many; see alloc.facet_cost)
        self._tile_limit = tile_limit
        if not isinstance(problem, Problem):
            raise TypeError(f"problem: expected alloc.Problem, got {type(problem).__name__}")
        self.problem = problem
        B = problem.B
        self.k, self.m = problem.k, problem.m
        self.lo = problem.umin if lo is None else np.asarray(lo, dtype=float)
        self.hi = problem.umax if hi is None else np.asarray(hi, dtype=float)
        if self.lo.shape != (self.m,) or self.hi.shape != (self.m,) or (self.lo > self.hi).any():
            raise ProblemError(f"lo/hi: expected ordered bounds of shape ({self.m},)")
        self.base_u = np.minimum(np.maximum(problem.up, self.lo), self.hi)
        self.base_v = B @ self.base_u
        # Structure (depends on the column directions and on which effectors move only).
        self.active = _active(B, problem.umin, problem.umax) & (self.hi > self.lo)
        self.cls, self.sign, R = generator_classes(B, self.active)
        self.n_classes = R.shape[1]
        # Work in the span of the directions (rank r); Q (k, r) orthonormal.
        if self.n_classes:
            Uq, s, _ = np.linalg.svd(R, full_matrices=False)
            self.rank = int((s > 1e-10 * s[0]).sum())
            # full rank: keep the user's axes (no rotation round-off)
            self._Q = np.eye(self.k) if self.rank == self.k else Uq[:, : self.rank]
        else:
            self.rank, self._Q = 0, np.zeros((self.k, 0))
        r = self.rank
        self._full = r == self.k
        Rr = _unit_columns(self._Q.T @ R) if r else np.zeros((0, self.n_classes))
        self._Br = self._Q.T @ B  # (r, m)
        member = np.zeros((self.n_classes, self.m))
        member[self.cls[self.active], np.flatnonzero(self.active)] = 1.0
        self._member = member
        if r == 0:
            self._Nr = np.zeros((0, 0))
            self._free_cls = np.zeros((0, 0), dtype=bool)
            self._tile_facet = np.zeros(0, dtype=np.intp)
            self._tile_span = np.zeros((0, 0), dtype=np.intp)
            self._tile_hi = np.zeros((0, self.m), dtype=bool)
        else:
            self._build_structure(Rr)
        self._place(self.lo, self.hi)

    # ------------------------------------------------------------ structure
    def _build_structure(self, Rr: FloatArray) -> None:
        r, C = Rr.shape
        normals, free = _hyperplanes(Rr)
        _check_closed(normals, r)
        # each hyperplane bounds the set on both sides
        N = np.concatenate([normals, -normals])
        free_cls = np.concatenate([free, free])
        self._Nr, self._free_cls = N, free_cls
        sgn_cls = np.sign(N @ Rr)  # (F, C), 0 on free classes
        free_eff = free_cls[:, self.cls] & self.active
        # fixed effector j sits at hi when its column points along the normal
        fixed_hi = (sgn_cls[:, self.cls] * self.sign > 0) & ~free_eff & self.active
        self._free_eff = free_eff
        # tiles: one per simple facet, a zonotopal tiling of each merged polygon
        low_hi = (self.sign < 0) & self.active  # a class's low end: members at lo if sign>0
        simple = free_cls.sum(axis=1) == r - 1
        if self._tile_limit is not None:
            # a merged facet of F directions holds C(F, r-1) tiles; tolerance merging that is not
            # transitive (directions within DIRECTION_TOL of some hyperplanes, not of others) can
            # put one subset into many facets: 15,962 tiles for 325 subsets at 3 x 26
            count = int(simple.sum()) + sum(math.comb(int(n), r - 1) for n in free_cls[~simple].sum(axis=1))
            if count > self._tile_limit:
                raise ProblemError(f"AMS: {count:,} facet tiles exceed the limit of {self._tile_limit:,} "
                                   "(directions coplanar within DIRECTION_TOL for some hyperplanes only)")
        tf = [np.flatnonzero(simple)]
        ts = [np.nonzero(free_cls[simple])[1].reshape(int(simple.sum()), r - 1)]
        th = [fixed_hi[simple] | (free_eff[simple] & low_hi)]
        for f in np.flatnonzero(~simple):
            F = np.flatnonzero(free_cls[f])
            sub_span, ends = _upper_tiles(_unit_columns(_plane_basis(N[f]).T @ Rr[:, F]))
            # class end 1 = members at the class's high end
            end_eff = np.zeros((len(ends), self.m), dtype=np.int8)
            end_eff[:, :] = -2
            mem = free_eff[f]
            end_eff[:, mem] = ends[:, np.searchsorted(F, self.cls[mem])]
            at_hi = np.repeat(fixed_hi[f][None], len(ends), axis=0)
            at_hi[:, mem] = np.where(end_eff[:, mem] == 1, ~low_hi[mem], low_hi[mem])
            tf.append(np.full(len(ends), f))
            ts.append(F[sub_span])
            th.append(at_hi)
        tf_all = np.concatenate(tf)
        order = np.argsort(tf_all, kind="stable")
        self._tile_facet = tf_all[order].astype(np.intp)
        self._tile_span = np.concatenate(ts)[order].astype(np.intp).reshape(len(order), r - 1)
        self._tile_hi = np.concatenate(th)[order]
        starts = np.searchsorted(self._tile_facet, np.arange(len(N) + 1))
        self._facet_tiles = [np.arange(starts[f], starts[f + 1]) for f in range(len(N))]
        self._Rr, self._sgn_cls = Rr, sgn_cls.astype(np.int8)
        self._fixed_hi = fixed_hi
        self._NB = N @ self._Br  # (F, m): facet normal . column, in the set's own coordinates

    # ------------------------------------------------------------ positions
    def _config(self, at_hi: NDArray[np.bool_], lo: FloatArray, hi: FloatArray, u0: FloatArray) -> FloatArray:
        """Effector positions of boolean configurations; inactive effectors at the base point."""
        U = np.where(at_hi, hi, lo)
        U[..., ~self.active] = u0[~self.active]
        return U

    def _class_steps(self, lo: FloatArray, hi: FloatArray) -> FloatArray:
        """(C, m): the change of u moving each class from its low to its high end."""
        return self._member * (self.sign * (hi - lo))

    def _place(self, lo: FloatArray, hi: FloatArray) -> None:
        """Positions for this box: offsets, tile corners and edges, vertices."""
        u0 = self.base_u
        Br = self._Br
        if self.rank == 0:
            self._offsets = np.zeros(0)
            self._gap = np.zeros(0)
            return
        self._steps = self._class_steps(lo, hi)
        self._Er = Br @ self._steps.T  # (r, C) class generators (full length)
        self._gap = self._gaps(lo, hi, u0)
        self._offsets = self._gap + self._Nr @ (Br @ u0)
        self._tile_u = self._config(self._tile_hi, lo, hi, u0)
        self._tile_corner = self._tile_u @ Br.T  # (T, r)

    def _gaps(self, lo: FloatArray, hi: FloatArray, u0: FloatArray) -> FloatArray:
        """Distance (along each unit normal) from the base point to each facet; >= 0 exactly."""
        NB = self._NB
        return np.maximum(NB * (lo - u0), NB * (hi - u0)).sum(axis=1)

    # ------------------------------------------------------------ vertices (on demand)
    # The vertex enumeration visits every facet's 2^(r-1) corners: at high rank it costs far more
    # than the facets and tiles the facet searches need (k = 14, m = 17: 39 million sign rows for
    # 131 thousand vertices, 3 GB and 14 s), so it runs only when a caller asks for vertices.
    @cached_property
    def _vertex_sig(self) -> NDArray[np.int8]:
        """(V, C) sign vectors over the generator classes of the vertices."""
        if self.rank == 0:
            return np.zeros((1, self.n_classes), dtype=np.int8)
        return _vertex_signs(self._Rr)

    @cached_property
    def vertex_u(self) -> FloatArray:
        """(V, m) effector positions of the vertices (a class's effectors at ``hi`` when
        ``sigma_c sign_j > 0``; effectors that generate nothing at the base point)."""
        if self.rank == 0:
            at_hi = np.zeros((1, self.m), dtype=bool)
        else:
            at_hi = (self._vertex_sig[:, self.cls] * self.sign > 0) & self.active
        return self._config(at_hi, self.lo, self.hi, self.base_u)

    @cached_property
    def vertices(self) -> FloatArray:
        """(V, k) the corners of the set."""
        return self.vertex_u @ self.problem.B.T

    @cached_property
    def _extent(self) -> float:
        """``max |v_i|`` over the set and the axes (the largest vertex coordinate), from the
        support along each axis: no vertex enumeration."""
        B = self.problem.B
        u0 = self.base_u
        Ba = np.where(self.active, B, 0.0)
        rest = B[:, ~self.active] @ u0[~self.active]
        top = np.maximum(Ba * self.lo, Ba * self.hi).sum(axis=1) + rest
        bottom = np.minimum(Ba * self.lo, Ba * self.hi).sum(axis=1) + rest
        return float(np.abs(np.concatenate([top, bottom])).max()) if len(top) else 0.0

    # ------------------------------------------------------------ public geometry
    @property
    def n_facets(self) -> int:
        return int(len(self._Nr))

    @property
    def n_tiles(self) -> int:
        """Parallelogram tiles used by the ray search (= facets in general position)."""
        return int(len(self._tile_facet))

    @property
    def normals(self) -> FloatArray:
        """Unit outward facet normals (F, k) (in the set's affine hull when it is flat)."""
        return self._Nr @ self._Q.T

    @property
    def offsets(self) -> FloatArray:
        """Facet offsets ``h``: ``normals @ v <= offsets`` for every ``v`` in the set."""
        return self._offsets.copy()

    @cached_property
    def tiling(self) -> FacetTiling:
        """The facet tiling as arrays (:class:`FacetTiling`), for facet searches."""
        r, m, C = self.rank, self.m, self.n_classes
        if r == 0:
            zf, zi = np.zeros((0, m)), np.zeros(0, dtype=np.intp)
            return FacetTiling(*(_read_only(a) for a in (
                np.zeros((0, m)), np.zeros((0, 0)), zf, np.zeros(0), np.zeros((0, C), dtype=bool), np.zeros((0, C)),
                self._member, np.zeros((C, m)), zi, np.zeros((0, 0), dtype=np.intp), np.zeros((0, m), dtype=bool),
                zf, np.zeros((0, 0)))))
        return FacetTiling(*(_read_only(a) for a in (
            self._Br, self._Nr, self._NB, self._gap, self._free_cls, self._Er, self._member, self._steps,
            self._tile_facet, self._tile_span, self._tile_hi, self._tile_u, self._tile_corner)))

    @cached_property
    def volume(self) -> float:
        """Exact k-dimensional volume (divergence theorem over the facet tiles); 0 when flat.

        ``vol = (1/k) sum_tiles (n . (corner - c)) area``, with ``area`` the (k-1)-volume of
        the tile's parallelepiped.  Checked against :func:`zonotope_volume` in the tests.
        """
        return self.volume_in_hull if self._full else 0.0

    @cached_property
    def volume_in_hull(self) -> float:
        """Volume within the set's own affine hull (``rank``-dimensional)."""
        r = self.rank
        if r == 0:
            return 0.0
        if r == 1:
            return float(np.abs(self._Er).sum())
        E = np.moveaxis(self._Er[:, self._tile_span], 1, 0)  # (T, r, r-1)
        area = np.sqrt(np.abs(np.linalg.det(np.swapaxes(E, 1, 2) @ E)))
        center = self._Br @ ((self.lo + self.hi) / 2)
        height = np.einsum("tr,tr->t", self._Nr[self._tile_facet], self._tile_corner - center)
        return float((height * area).sum() / r)

    def support(self, n: ArrayLike) -> float:
        """``max n . v`` over the set: each effector at the limit given by ``sign(n . b_j)``."""
        nb = np.asarray(n, dtype=float) @ self.problem.B
        return float(np.maximum(nb * self.lo, nb * self.hi).sum())

    def contains(self, v: ArrayLike, tol: float = 1e-9) -> bool | NDArray[np.bool_]:
        """Whether ``v`` (k,) or each row of ``V`` (N, k) is attainable: ``n . v <= h(n)`` for all facets.

        ``tol`` is relative to the size of the set.
        """
        V = np.asarray(v, dtype=float)
        one = V.ndim == 1
        V = np.atleast_2d(V)
        if V.shape[1] != self.k:
            raise DemandError(f"v: expected {self.k} components, got {V.shape[1]}")
        scale = tol * max(1.0, self._extent)
        D = V - self.base_v
        Y = D @ self._Q
        ok = np.linalg.norm(D - Y @ self._Q.T, axis=1) <= scale
        if self.rank:
            ok &= (Y @ self._Nr.T - self._gap <= scale).all(axis=1)
        else:
            ok &= np.linalg.norm(D, axis=1) <= scale
        return bool(ok[0]) if one else ok

    def max_in_direction(self, d: ArrayLike, *, lo: ArrayLike | None = None, hi: ArrayLike | None = None,
                         u0: ArrayLike | None = None) -> tuple[float, FloatArray]:
        """Eq 1.15's ``a*`` and ``u_d*``: the largest ``a`` with ``B u0 + a d`` attainable.

        Support-function form of the sequential facet search: ``a* = min over facets with
        n . d > 0 of gap(n) / (n . d)``, the gap from the base point to the facet being
        ``sum_j max(n.b_j (lo_j - u0_j), n.b_j (hi_j - u0_j))``.  Valid for any box inside
        the position limits (the facet directions do not change), so a rate-limited step
        only recomputes the gaps.  ``u_d*`` is found on the hit facet's tiles (Eq 1.16).

        Returns ``(a*, u_d*)``; ``a* = inf`` for ``d = 0``.
        """
        a, u, _ = self.ray_exit(d, lo=lo, hi=hi, u0=u0)
        return a, u

    def facet_hit(self, d: ArrayLike) -> int:
        """Index (into :attr:`facets`) of the facet the ray ``B u0 + a d`` leaves through (-1 if none)."""
        return self.ray_exit(d)[2]

    def ray_exit(self, d: ArrayLike, *, lo: ArrayLike | None = None, hi: ArrayLike | None = None,
                 u0: ArrayLike | None = None) -> tuple[float, FloatArray, int]:
        """``(a*, u_d*, facet index)`` of the ray from ``B u0`` along ``d``; see :meth:`max_in_direction`."""
        d = np.asarray(d, dtype=float)
        if d.shape != (self.k,):
            raise DemandError(f"d: expected shape ({self.k},), got {d.shape}")
        nominal = lo is None and hi is None and u0 is None
        lo = self.lo if lo is None else np.asarray(lo, dtype=float)
        hi = self.hi if hi is None else np.asarray(hi, dtype=float)
        u0 = np.minimum(np.maximum(self.problem.up, lo), hi) if u0 is None else np.asarray(u0, dtype=float)
        dn = float(np.linalg.norm(d))
        if dn == 0.0:
            return np.inf, u0.copy(), -1
        y = self._Q.T @ d
        if self.rank == 0 or np.linalg.norm(d - self._Q @ y) > 1e-12 * dn:
            return 0.0, u0.copy(), -1  # leaves the (flat) set's hull at once
        gap = self._gap if nominal else self._gaps(lo, hi, u0)
        nd = self._Nr @ y
        ok = nd > 1e-12 * dn
        ratio = np.full(len(nd), np.inf)
        ratio[ok] = gap[ok] / nd[ok]
        f = int(np.argmin(ratio))
        a = max(0.0, float(ratio[f]))
        if a == np.inf:  # unreachable on a closed structure (_check_closed); never return a point at infinity
            raise ProblemError("AMS: no facet ahead of the ray (degenerate facet structure)")
        if a == 0.0:
            return 0.0, u0.copy(), f
        return a, self.point_on_facet(f, self._Br @ u0 + a * y, lo, hi, u0, nominal=nominal), f

    def point_on_facet(self, f: int, q: FloatArray, lo: FloatArray, hi: FloatArray, u0: FloatArray,
                       *, nominal: bool = False) -> FloatArray:
        """A control ``u`` in the box with ``B u = q`` for ``q`` (in the set's coordinates) on facet ``f``.

        Solves Eq 1.16 on each tile of the facet and keeps the one whose parameters satisfy
        Eq 1.17 best (they all do up to round-off on a shared edge).
        """
        tiles = self._facet_tiles[f]
        steps = self._steps if nominal else self._class_steps(lo, hi)
        U = self._tile_u[tiles] if nominal else self._config(self._tile_hi[tiles], lo, hi, u0)
        best, best_u = -np.inf, None
        for i, t in enumerate(tiles):
            S = steps[self._tile_span[t]]  # (r-1, m)
            E = self._Br @ S.T
            p = np.linalg.lstsq(E, q - self._Br @ U[i], rcond=None)[0]
            margin = float(np.minimum(p, 1.0 - p).min()) if p.size else 0.0
            if margin > best:
                best, best_u = margin, U[i] + np.clip(p, 0.0, 1.0) @ S
            if margin >= -1e-12:
                break
        if best_u is None:  # no tile gave a finite margin: q is not a finite point of the facet
            raise ProblemError(f"AMS: point {q} is not on facet {f}")
        return best_u

    @cached_property
    def facets(self) -> list[Facet]:
        """Boundary facets with their effector assignments (merged polygons for coplanar columns)."""
        out = []
        V = self.vertices
        N = self.normals
        for f in range(self.n_facets):
            # a vertex is a corner of the facet when it agrees with the facet's fixed signs
            fixed_cls = ~self._free_cls[f]
            on = (self._vertex_sig[:, fixed_cls] == self._sgn_cls[f, fixed_cls]).all(axis=1)
            corners = V[on]
            if self.rank == 3 and len(corners) > 2:
                P = _plane_basis(self._Nr[f])
                xy = (corners - corners.mean(axis=0)) @ self._Q @ P
                corners = corners[np.argsort(np.arctan2(xy[:, 1], xy[:, 0]))]
            fixed = self._config(self._fixed_hi[f], self.lo, self.hi, self.base_u).astype(float)
            fixed[self._free_eff[f]] = np.nan
            free = tuple(int(j) for j in np.flatnonzero(self._free_eff[f]))
            out.append(Facet(f, N[f], float(self._offsets[f]), free, fixed, corners))
        return out

    def summary(self) -> dict[str, object]:
        """Counts and volume (for the CLI's ``alloc ams summary``)."""
        merged = [[self.problem.names[j] for j in np.flatnonzero(self.cls == c)] for c in range(self.n_classes)]
        return {
            "k": self.k, "m": self.m, "rank": self.rank, "volume": self.volume,
            "facets": self.n_facets, "tiles": self.n_tiles, "vertices": int(len(self.vertices)),
            "generator_classes": self.n_classes,
            "merged_collinear": [g for g in merged if len(g) > 1],
            "inactive": [self.problem.names[j] for j in np.flatnonzero(~self.active)],
            "polygon_facets": int((self._free_cls.sum(axis=1) > max(self.rank - 1, 0)).sum()) if self.rank else 0,
        }

    def __repr__(self) -> str:
        return (f"AttainableSet(k={self.k}, m={self.m}, rank={self.rank}, facets={self.n_facets}, "
                f"vertices={len(self.vertices)}, volume={self.volume:.6g})")
