"""``da_table``: a spherical look-up table of facets (seed section 1.3.4.2.3, Eqs 1.16-1.17).

Peterson and Bodson's option 2, k = 3: azimuth and elevation of ``d`` quantised (option
``resolution``); each cell stores the tiles hit by its centre and corners; a call tests those
few (Eq 1.17) and falls back to the sequential search of
:class:`~alloc.methods.facet_search.FacetSearch` when none passes, so it stays exact.  Other
k, rate-limited calls and flat sets use that search throughout.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..exceptions import OptionError
from ..method import BUILD_LIMIT_SECONDS, FloatArray, register
from ..options import integer
from ..problem import Problem
from . import _facet_kernels as _kernels
from ..facet_cost import table_build_bytes, table_build_seconds
from .facet_search import _TOL, FacetSearch, _int_option

__all__ = ["SphericalTable"]


@register("da_table", needs_ams=True, supports_batch=True, family="da")
class SphericalTable(FacetSearch):
    """Direct allocation with a spherical (azimuth, elevation) look-up table of facets (k = 3)."""

    summary = "direct allocation: quantised azimuth/elevation table of facets, sequential check as backup"
    options = {"resolution": integer(64, "elevation cells (azimuth gets twice as many)", low=2)}
    _CANDIDATES = 5

    @classmethod
    def table_seconds(cls, problem: Problem, resolution: int) -> float:
        """Declared build time (s) of the k = 3 (resolution x 2 resolution) direction table:
        ``20 ms + resolution^2 x (20 + 1.2 S) us`` (0 where no table is built; :mod:`alloc.facet_cost`)."""
        if problem.k != 3:
            return 0.0
        return table_build_seconds(cls.facet_subsets(problem, {}), resolution)

    @classmethod
    def build_cost(cls, problem: Problem, **options: Any) -> float:
        """The facet enumeration plus, at k = 3, the (resolution x 2 resolution) direction table."""
        seconds = super().build_cost(problem, **options)
        res = options.get("resolution", cls.options["resolution"].default)
        if isinstance(res, (int, np.integer)) and not isinstance(res, (bool, np.bool_)) and res > 0:
            seconds += cls.table_seconds(problem, int(res))
        return seconds

    @classmethod
    def build_memory(cls, problem: Problem, **options: Any) -> int:
        """The facet tables plus the direction table's 10 resolution^2 candidate indices and
        the ray casts' temporaries (chunks of at most 2 million tile tests; :mod:`alloc.facet_cost`)."""
        res = options.get("resolution", cls.options["resolution"].default)
        extra = 0
        if (problem.k == 3 and isinstance(res, (int, np.integer)) and not isinstance(res, (bool, np.bool_))
                and res > 0 and not cls.redirected(problem, options)):
            extra = table_build_bytes(cls.facet_subsets(problem, options), int(res))
        return super().build_memory(problem, **options) + extra

    def __init__(self, problem: Problem, *, resolution: int = 64) -> None:
        resolution = _int_option(resolution, "resolution", 2, 256, "da_table")
        self.resolution = resolution
        if not self.redirected(problem):
            self._check_table_bound(problem, resolution)
        super().__init__(problem)
        self.hits = 0

    @classmethod
    def _check_table_bound(cls, problem: Problem, resolution: int) -> None:
        """OptionError naming ``resolution`` when the build's declared time exceeds the bound."""
        facets = cls.enumeration_cost(problem)[0]
        seconds = facets + cls.table_seconds(problem, resolution)
        if seconds <= BUILD_LIMIT_SECONDS:
            return
        base = cls.table_seconds(problem, 0)  # the table's fixed part
        per_cell = cls.table_seconds(problem, 1) - base
        fits = int(math.isqrt(int(max(BUILD_LIMIT_SECONDS - facets - base, 0.0) / per_cell)))
        hint = f"resolution <= {fits} fits" if fits >= 2 else "no table fits; use 'da_facet'"
        raise OptionError(f"resolution: da_table's declared build time {seconds:.3g} s at resolution {resolution} "
                          f"exceeds the build bound of {BUILD_LIMIT_SECONDS:g} s ({hint})", field="resolution")

    def _prepare(self) -> None:
        super()._prepare()
        self._table = None
        if self._flat or self.problem.k != 3 or len(self._tiles) == 0:
            return
        ne = self.resolution
        na = 2 * ne
        # quantise directions of W d, W = 1 / extent of the set per axis: a round set gives
        # facets comparable solid angles (ICE's pitch/roll/yaw extents differ 10x)
        ext = np.abs(self.ams.tiling.generators).sum(axis=1)
        self._W = 1.0 / ext
        az = np.linspace(-np.pi, np.pi, na + 1)
        el = np.linspace(-np.pi / 2, np.pi / 2, ne + 1)
        azc, elc = (az[:-1] + az[1:]) / 2, (el[:-1] + el[1:]) / 2

        def directions(A, E):
            A, E = np.meshgrid(A, E, indexing="ij")
            return np.stack([np.cos(E) * np.cos(A), np.cos(E) * np.sin(A), np.sin(E)], axis=-1).reshape(-1, 3)

        centre = self._tiles_hit(directions(azc, elc) * ext).reshape(na, ne)
        corner = self._tiles_hit(directions(az, el) * ext).reshape(na + 1, ne + 1)
        cand = np.stack([centre, corner[:-1, :-1], corner[1:, :-1], corner[:-1, 1:], corner[1:, 1:]], axis=-1)
        cand = np.where(cand < 0, centre[..., None], cand)
        self._table = np.ascontiguousarray(cand.reshape(na * ne, self._CANDIDATES))
        self._na, self._ne = na, ne

    def _solve_nominal(self, v):
        if self._table is None:
            return super()._solve_nominal(v)
        u, iterations, hit = _kernels.table_solve(v, self._kp0, self._ku0, self._kNz, self._kMinv, self._kU,
                                                  self._kS, self._W, self._table, self._na, self._ne)
        if iterations:
            self.hits += hit
            self.fallbacks += not hit
        return u, iterations

    def _tiles_hit(self, D: FloatArray) -> np.ndarray:
        T, k = len(self._tiles), 3
        out = np.empty(len(D), dtype=np.intp)
        chunk = max(1, 2_000_000 // (T * k))
        for s in range(0, len(D), chunk):
            X = (D[s:s + chunk] @ self._Minv2.T).reshape(-1, T, k)
            x0, P = X[:, :, 0], X[:, :, 1:]
            with np.errstate(divide="ignore", invalid="ignore"):
                score = np.minimum(P, x0[:, :, None] - P).min(axis=2) / x0
            score[~(x0 > 0)] = -np.inf
            t = np.argmax(score, axis=1)
            t[~np.isfinite(score[np.arange(len(t)), t])] = -1
            out[s:s + chunk] = t
        return out

    def _boundary(self, d):
        if self._table is None:
            return super()._boundary(d)
        w = self._W
        x, y, z = d[0] * w[0], d[1] * w[1], d[2] * w[2]
        az = math.atan2(y, x)
        el = math.atan2(z, math.hypot(x, y))
        i = min(int((az + math.pi) / (2 * math.pi) * self._na), self._na - 1)
        j = min(int((el + math.pi / 2) / math.pi * self._ne), self._ne - 1)
        cand = self._table[i * self._ne + j]
        X = self._Minv[cand] @ d
        t, score = self._tile_test(X)
        if score >= -_TOL:
            self.hits += 1
            return self._from_tile(int(cand[t]), X[t])
        self.fallbacks += 1
        return super()._boundary(d)
