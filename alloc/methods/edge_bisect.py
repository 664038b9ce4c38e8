"""``da_bisect``: Durham's edge-bisecting facet search (seed section 1.3.4.2.2, Eqs 1.16-1.17).

k = 3: ``d`` is turned into the x-axis; for a rotation angle about it the AMS is projected
onto the (x, y) plane and the silhouette edge crossing the positive x-axis is found by a
weighted median over the generators (O(m log m), no facet list); the sign of that edge's
z-coordinate brackets the ray and the angle interval is cut (``angles`` per round) until
the two bracketing edges span a facet that passes Eq 1.17.  Other k, rate-limited calls and
flat sets use the sequential search of :class:`~alloc.methods.facet_search.FacetSearch`,
whose conventions, build-cost model and kernels (:mod:`alloc.methods._facet_kernels`) it shares.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..method import FloatArray, register
from ..options import integer
from ..problem import Problem
from . import _facet_kernels as _kernels
from ..facet_cost import _BISECT_SUBSET_SECONDS
from .facet_search import _TOL, FacetSearch, _int_option, _kernel_array

__all__ = ["EdgeBisect"]


@register("da_bisect", needs_ams=True, supports_batch=True, family="da")
class EdgeBisect(FacetSearch):
    """Direct allocation by Durham's edge-bisecting facet search (k = 3)."""

    summary = "direct allocation: Durham's edge-bisecting facet search, cost ~linear in m (Eq 1.16-1.17)"
    # both set the work of one call: a shared service holds them to their caps
    options = {"angles": integer(16, "rotation angles tried per round (1 = plain bisection)", low=1, high=1024,
                                 call_cap=1024),
               "max_rounds": integer(40, "rounds before falling back to the sequential search", low=1, high=1000,
                                     call_cap=1000)}

    @classmethod
    def enumeration_cost(cls, problem: Problem, options: dict[str, Any] | None = None) -> tuple[float, int]:
        """The facet enumeration plus, at k = 3, the edge table: 60 us per subset (measured,
        :mod:`alloc.facet_cost`) and the (C, C) class-pair tables (C <= m classes)."""
        seconds, nbytes = super().enumeration_cost(problem, options)
        if problem.k == 3:
            seconds += _BISECT_SUBSET_SECONDS * cls.facet_subsets(problem, options or {})
            nbytes += 48 * problem.m ** 2
        return seconds, nbytes

    def __init__(self, problem: Problem, *, angles: int = 16, max_rounds: int = 40) -> None:
        angles = _int_option(angles, "angles", 1, 1024)
        max_rounds = _int_option(max_rounds, "max_rounds", 1, 1000)
        self.angles, self.max_rounds = angles, max_rounds
        super().__init__(problem)
        self.rounds = 0

    def _prepare(self) -> None:
        super()._prepare()
        ams = self.ams
        self._bisect = not self._flat and self.problem.k == 3 and ams.n_classes >= 2
        if not self._bisect:
            return
        G = ams.tiling.generators / 2.0  # centred class generators
        self._R = G / np.linalg.norm(G, axis=0)
        # Search in axes scaled to the set's extent: facet identity is invariant under a
        # linear map, and the angular search is far better conditioned on a round set.
        self._W = 1.0 / np.abs(G).sum(axis=1)
        self._G = G * self._W[:, None]
        self._c = (ams.tiling.B @ ((ams.lo + ams.hi) / 2.0) - self._p0) * self._W  # centre seen from B u0
        C = G.shape[1]
        # facet of each (class i, class j, side): side 1 when n . (r_i x r_j) > 0
        lut = np.full((C, C, 2), -1, dtype=np.intp)
        tiles_of = {}
        for i, f in enumerate(self._facet_of_tile):
            tiles_of.setdefault(int(f), []).append(i)
        for f in tiles_of:
            F = np.flatnonzero(ams.tiling.free_classes[f])
            n = ams.tiling.normals[f]
            for a in range(len(F)):
                for b in range(a + 1, len(F)):
                    i, j = F[a], F[b]
                    side = int(n @ np.cross(self._R[:, i], self._R[:, j]) > 0)
                    lut[i, j, side] = lut[j, i, 1 - side] = f
        self._lut = lut
        self._tiles_of = {f: np.array(tl) for f, tl in tiles_of.items()}
        self._pair_cross = np.cross(self._R.T[:, None, :], self._R.T[None, :, :])  # (C, C, 3)
        self._fractions = np.arange(1, self.angles + 1) / (self.angles + 1)
        self._first_angles = np.concatenate([[0.0], math.pi * self._fractions])
        # tiles of each facet as positions into the inverse table (CSR) for the kernel
        order = np.argsort(self._facet_of_tile, kind="stable")
        self._ktile_pos = order.astype(np.intp)
        self._ktile_ptr = np.searchsorted(self._facet_of_tile[order], np.arange(ams.n_facets + 1)).astype(np.intp)
        self._kbisect = (_kernel_array(self._W), _kernel_array(self._G), _kernel_array(self._c),
                         _kernel_array(lut), _kernel_array(self._pair_cross), self._ktile_ptr,
                         self._ktile_pos, _kernel_array(self._fractions),
                         _kernel_array(self._first_angles), self.max_rounds)

    def _solve_nominal(self, v):
        if not self._bisect:
            return super()._solve_nominal(v)
        u, iterations, rounds, fell_back = _kernels.bisect_solve(
            v, self._kp0, self._ku0, self._kNz, self._kMinv, self._kU, self._kS, *self._kbisect)
        if rounds:
            self.rounds = rounds
        self.fallbacks += fell_back
        return u, iterations

    def _edge(self, th: FloatArray, gx, gy0, gz0, cx, cy0, cz0):
        """Silhouette edge over the positive x-axis for rotation angles ``th`` (K,).

        Returns the edge class (K,), the generator signs (K, C) and the edge point's z (K,).
        """
        K = len(th)
        rot = np.empty((2 * K, 2))
        rot[:K, 0] = rot[K:, 1] = np.cos(th)
        rot[:K, 1] = np.sin(th)
        rot[K:, 0] = -rot[:K, 1]
        H = rot @ np.array([np.append(gy0, cy0), np.append(gz0, cz0)])  # rows: y then z
        gy, cy = H[:K, :-1], H[:K, -1]
        gz, cz = H[K:, :-1], H[K:, -1]
        # max x on y = 0 of the projection: minimise cx + t cy + sum|gx + t gy| over t
        # (a weighted median of the breakpoints t_c = -gx_c / gy_c)
        tb = np.divide(-gx, gy, out=np.full(gy.shape, np.inf), where=gy != 0)
        order = np.argsort(tb, axis=1)
        agy = np.abs(gy)
        rows = np.arange(K)
        slope = np.cumsum(agy[rows[:, None], order], axis=1)
        slope *= 2.0
        slope += (cy - agy.sum(axis=1))[:, None]
        i = np.minimum((slope < 0).sum(axis=1), gy.shape[1] - 1)
        c = order[rows, i]
        sig = np.sign(gx + tb[rows, c][:, None] * gy)
        sig[rows, c] = 0.0
        gyc, gzc = gy[rows, c], gz[rows, c]
        s = -(cy + np.einsum("kc,kc->k", sig, gy)) / gyc
        z = cz + np.einsum("kc,kc->k", sig, gz) + s * gzc
        return c, sig, z

    def _boundary(self, d):
        if not self._bisect:
            return super()._boundary(d)
        G, c0 = self._G, self._c
        # orthonormal frame (x along the scaled demand), scalar arithmetic: np.cross costs ~10 us
        x0, x1, x2 = d[0] * self._W[0], d[1] * self._W[1], d[2] * self._W[2]
        nx = math.sqrt(x0 * x0 + x1 * x1 + x2 * x2)
        x0, x1, x2 = x0 / nx, x1 / nx, x2 / nx
        if abs(x0) <= abs(x1) and abs(x0) <= abs(x2):
            y0, y1, y2 = 0.0, x2, -x1  # x cross e0
        elif abs(x1) <= abs(x2):
            y0, y1, y2 = -x2, 0.0, x0  # x cross e1
        else:
            y0, y1, y2 = x1, -x0, 0.0  # x cross e2
        ny = math.sqrt(y0 * y0 + y1 * y1 + y2 * y2)
        y0, y1, y2 = y0 / ny, y1 / ny, y2 / ny
        frame = np.array([[x0, x1, x2], [y0, y1, y2],
                          [x1 * y2 - x2 * y1, x2 * y0 - x0 * y2, x0 * y1 - x1 * y0]])
        gx, gy0, gz0 = frame @ G
        cx, cy0, cz0 = frame @ c0
        K = self.angles
        lo_t, hi_t = 0.0, math.pi
        # round 1 also evaluates angle 0; the half-turn (pi) sees the same edge, z mirrored
        th = self._first_angles
        cc, ss, zz = self._edge(th, gx, gy0, gz0, cx, cy0, cz0)
        cl, sl, zl = cc[0], ss[0], zz[0]
        ch, sh, zh = cl, sl, -zl
        th, cc, ss, zz = th[1:], cc[1:], ss[1:], zz[1:]
        for r in range(1, self.max_rounds + 1):
            if r > 1:
                th = lo_t + (hi_t - lo_t) * self._fractions
                cc, ss, zz = self._edge(th, gx, gy0, gz0, cx, cy0, cz0)
            # bracket: first angle whose z has the sign of the upper end
            pos = zz > 0 if zh > 0 else zz <= 0
            j = int(np.argmax(pos)) if pos.any() else K
            if j > 0:
                lo_t, cl, sl = th[j - 1], cc[j - 1], ss[j - 1]
            if j < K:
                hi_t, ch, sh = th[j], cc[j], ss[j]
            found = self._try_facet(cl, sl, ch, sh, d)
            if found is not None:
                self.rounds = r
                return found
        self.fallbacks += 1
        return super()._boundary(d)

    def _try_facet(self, cl, sl, ch, sh, d):
        """Test the facet spanned by the two bracketing edges (Eq 1.17); ``None`` if it fails."""
        differ = sl != sh
        differ[cl] = differ[ch] = True
        cand = np.flatnonzero(differ)
        if len(cand) < 2:
            return None
        i, j = int(cand[0]), int(cand[1])
        side = int(d @ self._pair_cross[i, j] > 0)
        f = int(self._lut[i, j, side])
        tl = self._tiles_of.get(f)
        if tl is None:
            return None
        if len(tl) == 1:  # a parallelogram: Eq 1.17 on three floats
            t = int(tl[0])
            x = self._Minv[t] @ d
            x0, *rest = x.tolist()
            slack = _TOL * abs(x0)
            if x0 > 0 and all(-slack <= b <= x0 + slack for b in rest):
                return self._from_tile(t, x)
            return None
        X = self._Minv[tl] @ d
        t, score = self._tile_test(X)
        if score < -_TOL:
            return None
        return self._from_tile(int(tl[t]), X[t])
