"""Direct allocation (seed section 1.3.4.2, Eqs 1.15-1.17) as a linear program.

The attainable moment set (AMS) is the image of the effector box under ``B``.  Direct
allocation finds the largest ``a`` with ``a d`` attainable, ``d = v - B u0`` the demand
measured from the base point ``u0`` (the preferred position clipped into the call's
bounds; ``u0 = 0`` in the seed):

    maximise a   subject to   B (u - u0) = a d,   lo <= u <= hi,   a >= 0.

The solution ``u*`` lies on the AMS boundary.  When ``a* >= 1`` the demand is attainable
and the boundary solution is scaled back along the ray (Eq 1.15):
``u = u0 + (u* - u0) / a*``, so ``B u = v``.  Otherwise ``u = u*``, the boundary point in
the demanded direction (status ``unattainable``).

Backends: the exact facet search of :mod:`alloc.methods.facet_search` (``da_facet``:
precomputed facet inverses, compiled) and the LP of :mod:`alloc.methods._direct_lp`: the compiled ray
simplex (``backend="simplex"``, :mod:`alloc._engine._ray_simplex`; a persistent DAQP model behind it) or a persistent
DAQP (or HiGHS) model alone, polished on the facet it finds.  ``backend="auto"`` picks the backend a measured cost model says is
cheaper per call (:func:`facet_is_cheaper`; never the facet search beyond ``FACET_LIMIT``).  With a rank-deficient ``B`` the ray
follows the part of ``d`` in the range of ``B``; the rest is reported as unallocated.  When the ray leaves the AMS through an
edge or a degenerate facet, ``u*`` is not unique (the moment is).  The facet-search
versions (``da_facet``, ``da_bisect``, ``da_table``) live in :mod:`alloc.methods.facet_search`.
"""

from __future__ import annotations

from typing import Any

import math

from ..method import Method, register
from ..options import choice
from ..problem import Problem
from ..solvers import backends
from ._direct_lp import RayLP
from .facet_search import FACET_LIMIT, FacetSearch


def facet_call_us(m: int, k: int) -> float:
    """Modelled median us per call of the compiled facet search (``benchmarks/bench_da_cost.py``)."""
    return 5.5 + (0.025 + 0.0045 * k) * math.comb(m, max(k - 1, 0))


def lp_call_us(m: int, k: int) -> float:
    """Modelled median us per call of the LP backend ``auto`` uses, the compiled ray simplex
    (``benchmarks/bench_da_cost.py``)."""
    return 7.5 + (0.015 * k + 0.008 * k * k) * m


def facet_is_cheaper(m: int, k: int) -> bool:
    """The measured per-call cost model of ``backend="auto"``.

    Fits to ``benchmarks/bench_da_cost.py`` (median us per call, k = 1..6, m = 4..64, load
    7-9, 2026-12-06): facet search ``5.5 + (0.025 + 0.0045 k) C(m, k-1)`` (0.038-0.053 us per
    subset), the compiled ray LP ``7.5 + (0.015 k + 0.008 k^2) m`` (7-36 us).  Never the facet search beyond
    :data:`FACET_LIMIT` subsets.  With the DAQP model as the LP (``47.4 + 2.94 m``, before the
    ray simplex) the facet search was chosen up to 3 x 64 at 2.2x the LP's cost.
    """
    return math.comb(m, max(k - 1, 0)) <= FACET_LIMIT and facet_call_us(m, k) <= lp_call_us(m, k)


@register("da", supports_batch=True, family="da")
class DirectAllocation(RayLP):
    """Direct allocation by the LP of :class:`~alloc.methods._direct_lp.RayLP` or the facet search."""

    equation = "Eqs 1.15-1.17"
    summary = "largest admissible moment along v (AMS boundary), scaled back when attainable"
    options = {"backend": choice("auto", "'auto': the cheaper of facet search and the compiled ray simplex by "
                                         "a measured cost model; 'facet'; 'simplex'; or an LP solver",
                                 lambda: ["auto", "facet", "simplex", *backends(lp=True)])}

    @classmethod
    def facet_subsets(cls, problem: Problem, options: dict[str, Any]) -> int:
        """Subsets the build enumerates: only with ``backend="facet"`` or ``"auto"`` under the limit."""
        backend = options.get("backend", "auto")
        n = math.comb(int((problem.umax > problem.umin).sum()), max(problem.k - 1, 0))
        if backend == "facet" or (backend == "auto" and facet_is_cheaper(problem.m, problem.k)):
            return n
        return 0

    @classmethod
    def build_cost(cls, problem: Problem, **options: Any) -> float:
        """The facet search's (:class:`FacetSearch`) when the facet backend is used, else the
        ray LP's set-up (milliseconds, :func:`alloc.facet_cost.lp_build_seconds`)."""
        if cls.facet_subsets(problem, options):
            return FacetSearch.build_cost(problem)
        return super().build_cost(problem, **options)

    @classmethod
    def build_memory(cls, problem: Problem, **options: Any) -> int:
        """The facet search's tables when the facet backend is used, else the ray LP's."""
        if cls.facet_subsets(problem, options):
            return FacetSearch.build_memory(problem)
        return super().build_memory(problem, **options)

    def __init__(self, problem: Problem, *, backend: str = "auto") -> None:
        self._facet = None
        if backend in ("auto", "facet"):
            if backend == "facet" or facet_is_cheaper(problem.m, problem.k):
                Method.__init__(self, problem)
                self._facet = FacetSearch(problem)
                return
            backend = "simplex"
        if backend == "simplex":
            # the compiled ray simplex, DAQP's model behind it (alloc._engine._ray_simplex)
            super().__init__(problem, backend="daqp", simplex=True)
            return
        super().__init__(problem, backend=backend)

    def solve_batch(self, V, lo, hi):
        return None if self._facet is None else self._facet.solve_batch(V, lo, hi)

    def solve(self, v, lo, hi, u_prev):
        if self._facet is not None:
            return self._facet.solve(v, lo, hi, u_prev)
        return super().solve(v, lo, hi, u_prev)
