"""The iteration bound of an exported active-set kernel: the analytic bound and a sampled
certification over the demand set.

Two statements, of different strength, go into every active-set kernel's header:

* **Analytic** (a proof, in exact arithmetic and without ties in the ratio test): a level of the
  primal active set ends within ``(m + 1) 3^m`` iterations (:func:`analytic_bound`).  Every
  iteration is a blocking step (one free effector fixed: at most ``m`` in a row) or ends at
  the minimiser of the level on its working set, and there the level's objective (with the
  preference distance as tie-break, the step's own target) has strictly decreased since the last
  such minimiser, so no working set -- each effector free, at its lower or at its upper bound,
  ``3^m`` of them -- is met twice at a minimiser.  It is far above the library's per-level cap
  (5,103 against 150 for 6 effectors) and a worst-case time built on it is useless in flight;
  primal active sets have exponential worst cases, so no polynomial bound exists to prove.
* **Sampled** (not a proof): :func:`certify` runs the library's own active set (whose iteration
  counts the ``double`` kernel reproduces exactly) on a deterministic dense sample of the demand
  set (:func:`certification_demands`) and takes the largest count per call.  A kernel exported
  with ``iteration_bound="certify"`` enforces that count per call with the nominal limits and
  no rate window: a call that would need more stops there and returns the documented safe
  answer with status 2.  The sample certifies that no demand in it reaches the bound; a demand
  between its points can (the count is constant on regions of the demand space that a grid can
  miss), and the kernel then says so with status 2, never with a wrong answer.  An exact
  certification in DAQP's manner (enumerating the regions of the demand space on which the
  sequence of working sets is fixed) is not made here.

Calls with a rate window (``u_prev``) or reduced limits (``set_limits``) have bounds that are
not in the sample; they keep the library's cap, ``PFX_MAXIT`` a level.

The ``lp`` kernel (the library's simplex, :mod:`alloc._engine._simplex`) is certified by the same
sample and the same rule, counting the simplex's pivots (bound flips included) instead of
active-set iterations (:func:`certify` with ``count``; :func:`simplex_bound_text`), and with
one part more, :data:`SIMPLEX_RANDOM_DEMANDS` seeded random demands: the pivot count changes
on finer regions of the demand space than the grid resolves (on the 4 x 6 hexacopter the
other parts alone certified 11 pivots where 0.3 % of the export benchmark's demands need 12 or
13; with the random part, 13, and none of them beyond).  No
analytic bound is claimed for it: the simplex method's worst case is exponential (Klee and
Minty), and the library's cap ``50 (N + k)`` is what bounds a call's time.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..problem import Problem

#: demands of the grid part of the sample (rounded to a whole grid of odd side)
GRID_DEMANDS = 6000
#: the grid spans this multiple of the attainable set's extent per axis (the shared random
#: suite's factor for demands past the attainable set)
GRID_REACH = 2.5
#: radii, in units of the attainable extent, of the far demands along each grid direction
FAR_RADII = (10.0, 1e3, 1e6)
#: scales of the attainable set's vertices (its boundary, where ties in the ratio test are likely)
VERTEX_SCALES = (0.5, 1.0, 1.0 + 1e-9, 1.5)
#: at most this many vertices of the box are mapped (all of them up to 12 effectors)
MAX_VERTICES = 4096
#: ``lp``: seeded random demands added to the sample (alloc.testing.random_demands, half
#: attainable, half up to 2.5x past the attainable set), and their seed
SIMPLEX_RANDOM_DEMANDS = 20000
RANDOM_SEED = 0


@dataclass(frozen=True)
class Certificate:
    """The sampled certification of one exported active-set problem."""

    #: the largest iteration count per call over the sample (all levels)
    bound: int
    #: demands in the sample, and how many of each part (grid, far, vertices, axes)
    demands: int
    parts: dict[str, int]
    #: the demand that needs ``bound`` iterations (the first one met)
    worst_demand: np.ndarray
    #: the largest count per part of the sample
    part_max: dict[str, int]
    #: what is counted: active-set ``"iterations"`` or simplex ``"pivots"``
    unit: str = "iterations"


def analytic_bound(m: int) -> int:
    """Iterations of one level within which the primal active set ends, in exact arithmetic
    without ties: ``(m + 1) 3^m`` (see the module docstring)."""
    return (m + 1) * 3 ** m


def _extent(problem: Problem) -> np.ndarray:
    """Per axis, the largest magnitude of an attainable moment: ``sum_j |B_ij| max(|umin_j|, |umax_j|)``
    bounds it (the vertex that attains it per axis)."""
    reach = np.abs(problem.B) @ np.maximum(np.abs(problem.umin), np.abs(problem.umax))
    return np.where(reach > 0, reach, 1.0)


def certification_demands(problem: Problem, random: int = 0) -> dict[str, np.ndarray]:
    """The sample of the demand set, deterministic (no seed): the parts of :class:`Certificate`.

    ``grid``: an odd-sided grid over ``GRID_REACH`` times the attainable extent per axis (the
    origin and both signs of every axis on it); ``far``: every grid direction at the radii
    :data:`FAR_RADII` (demands whose answer saturates); ``vertices``: the moments ``B u`` of the
    box's vertices at :data:`VERTEX_SCALES` (inside, on and just past the attainable set's
    boundary); ``axes``: each axis alone, both signs, at 100 magnitudes from 1e-6 to 1e6 of the
    extent (symmetric vehicles tie there); ``random`` (when ``random > 0``): that many seeded
    demands of :func:`alloc.testing.random_demands` (seed :data:`RANDOM_SEED`)."""
    k, m = problem.k, problem.m
    ext = _extent(problem)
    side = max(3, int(round(GRID_DEMANDS ** (1.0 / k))))
    side += 1 - side % 2
    ticks = np.linspace(-1.0, 1.0, side)
    unit = np.array(list(itertools.product(ticks, repeat=k)))
    grid = unit * (GRID_REACH * ext)
    norms = np.abs(unit).max(axis=1)
    shell = unit[norms == 1.0]
    far = np.concatenate([shell * (r * ext) for r in FAR_RADII])
    bits = range(min(1 << m, MAX_VERTICES))
    corners = np.array([[problem.umax[j] if b >> j & 1 else problem.umin[j] for j in range(m)] for b in bits])
    moments = corners @ problem.B.T
    vertices = np.concatenate([moments * s for s in VERTEX_SCALES])
    mags = np.logspace(-6, 6, 100)
    axes = np.concatenate([np.outer(sign * mags, np.eye(k)[i] * ext[i]) for i in range(k) for sign in (1.0, -1.0)])
    parts = {"grid": grid, "far": far, "vertices": vertices, "axes": axes}
    if random > 0:
        from ..testing import random_demands

        parts["random"] = random_demands(np.random.default_rng(RANDOM_SEED), problem, random)
    return parts


def sample_size(k: int, m: int, random: int = 0) -> int:
    """Demands in :func:`certification_demands` of a ``k x m`` problem, without making them
    (what :mod:`alloc.export.cost` prices)."""
    side = max(3, int(round(GRID_DEMANDS ** (1.0 / k))))
    side += 1 - side % 2
    shell = side ** k - (side - 2) ** k
    return side ** k + len(FAR_RADII) * shell + len(VERTEX_SCALES) * min(1 << min(m, 62), MAX_VERTICES) \
        + 200 * k + max(random, 0)


def certify(allocator, problem: Problem, count: Callable[[np.ndarray], int] | None = None,
            unit: str = "iterations", random: int = 0) -> Certificate:
    """Run ``allocator`` (the library's active set) on :func:`certification_demands`; the
    largest count per call is the bound a kernel exported with ``iteration_bound="certify"``
    enforces.

    ``count(v)``, when given, is the count of one demand instead of ``allocator(v).iterations``
    (``lp``: the simplex's pivots, also on a call that stops at the library's cap, which the
    allocator reports as a fallback of 0 iterations); ``unit`` names it; ``random`` as for
    :func:`certification_demands`."""
    if count is None:
        def count(v: np.ndarray) -> int:
            return int(allocator(v).iterations)
    parts = certification_demands(problem, random)
    best, worst = -1, np.zeros(problem.k)
    part_max: dict[str, int] = {}
    for name, V in parts.items():
        top = 0
        for v in V:
            it = int(count(v))
            top = max(top, it)
            if it > best:
                best, worst = it, np.array(v, dtype=float)
        part_max[name] = top
    return Certificate(bound=max(best, 1), demands=sum(len(V) for V in parts.values()),
                       parts={name: len(V) for name, V in parts.items()}, worst_demand=worst, part_max=part_max,
                       unit=unit)


def _enforced_text(budget: int, cert: Certificate | None, default: str | None, what: str, counted: str) -> str:
    """The header's lines on ``PFX_ITERATION_BOUND``: uncertified (``default`` says why it is the
    number it is; None: given at export), or certified, ``counted`` saying by what and how much."""
    if cert is None:
        given = default or "given at export"
        return (f" * PFX_ITERATION_BOUND = {budget}: the per-call {what}, {given} (not certified:\n"
                " * export with iteration_bound=\"certify\" for a sampled certification).\n")
    if budget == cert.bound:
        parts = ", ".join(f"{n} {cert.parts[n]} (max {cert.part_max[n]})" for n in cert.parts)
        return (f" * PFX_ITERATION_BOUND = {budget}: certified BY SAMPLING, not proved: the library's\n"
                f" * {counted} on {cert.demands:,} demands ({parts};\n"
                " * alloc.export.certify.certification_demands).  Enforced on calls with the nominal\n"
                " * limits and no rate window: a demand between the samples that needs more returns\n"
                " * status 2 with the safe answer.\n")
    return f" * PFX_ITERATION_BOUND = {budget}: the per-call {what} given at export.\n"


def bound_text(m: int, levels: int, maxit: int, budget: int, cert: Certificate | None,
               cap_given: bool = False, warm: bool = False) -> str:
    """The header's statement of the iteration bound of an active-set kernel and its argument
    (``cap_given``: ``maxit`` was chosen at export, not the library's cap; ``warm``: the kernel
    has the warm start, whose run the sample does not cover)."""
    worst = analytic_bound(m)
    enforced = _enforced_text(budget, cert, "here levels x cap" if budget == levels * maxit else None, "budget",
                              "active set (whose counts this kernel reproduces) needs at most "
                              f"{cert.bound if cert else 0} iterations a\n * call")
    origin = "set at\n * export" if cap_given else "the\n * library's cap, 50 + 10 (m + k)"
    return f""" *
 * Iteration bound.  Each level stops after at most PFX_MAXIT = {maxit} iterations ({origin}); \
{levels} level(s), so at most PFX_MAXIT_TOTAL = {levels * maxit}
 * iterations a call with a rate window or reduced limits, each of bounded cost (every inner loop
 * has a fixed trip count: the Jacobi SVD at most 40 sweeps over p (p - 1) / 2 column pairs).
{enforced} * Reaching either returns status 2 with the safe answer (the weighted pseudo-inverse of
 * Eq 1.23 clipped to the call's bounds), as the library does at its cap.
 * Analytic bound (a proof in exact arithmetic without ties in the ratio test): each iteration
 * fixes one free effector at a bound (at most m in a row) or ends at the level's minimiser on
 * its working set, where the objective has strictly decreased since the last one, so no
 * working set (each effector free, at its lower or upper bound) recurs there: a level ends
 * within (m + 1) 3^m = {worst} iterations, far above the cap (alloc/export/certify.py).
{_WARM_BOUND if warm else ""}"""


#: the warm-start kernels' addition to :func:`bound_text`
_WARM_BOUND = """ * Warm start: the bounds above hold for the cold start, which the sample runs.  A run from the
 * warm start that reaches the budget is abandoned and the call redone from the cold start under
 * the same budget: at most twice the budget a call (PREFIX_iterations counts both runs).
"""


def simplex_bound_text(maxit: int, budget: int, cert: Certificate | None) -> str:
    """The header's statement of the pivot bound of an ``lp`` kernel and its argument."""
    enforced = _enforced_text(budget, cert, "the library's cap" if budget == maxit - 1 else None, "pivot budget",
                              "simplex (whose pivots this kernel reproduces) needs at most "
                              f"{cert.bound if cert else 0} pivots a call\n *")
    return f""" *
 * Iteration bound.  A call takes at most PFX_MAXIT - 1 = {maxit - 1} pivots (bound flips included:
 * the library's cap 50 (N + k); it refactorises every 32 pivots and at the end of every stage,
 * and every inner loop has a fixed trip count), or on calls with the nominal limits and no
 * rate window at most PFX_ITERATION_BOUND: the pivot beyond it is not taken.
{enforced} * Reaching either returns status 2 with the safe answer (the weighted pseudo-inverse of
 * Eq 1.23 clipped to the call's bounds), as the library does at its cap.  No analytic bound
 * is claimed: the simplex method's worst case is exponential in the size (Klee-Minty).
"""
