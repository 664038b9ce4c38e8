"""The base class of allocation methods and their registration.

A method is a class deriving from :class:`Method`, registered with ``@register("name")``.
It is constructed once per allocator with the problem and its options (precomputing
whatever it can) and then called with a demand and the effective bounds of that call
(position limits, or the rate-limited bounds of Eq 1.28).  Adding a method is one new
module plus one decorator.

This module sits below the methods (every built-in method module imports it); the look-ups
that load the built-in methods first (:func:`alloc.registry.get_method`, ``methods``,
``method_info``, ``build``) sit above them, in :mod:`alloc.registry`, which re-exports the
names defined here.  So no method module imports the module that imports it.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Any, ClassVar

import numpy as np
from numpy.typing import NDArray

from .export_data import KINDS, KernelData
from .options import Option
from .problem import Problem

__all__ = ["Method", "register", "FloatArray", "CHEAP_BUILD_SECONDS", "BUILD_LIMIT_SECONDS", "BUILD_LIMIT_BYTES",
           "CALL_LIMIT_SECONDS", "CAPABILITIES"]

FloatArray = NDArray[np.float64]

#: name -> method class; filled by :func:`register` (the built-ins when :mod:`alloc.methods` is
#: imported), read by :mod:`alloc.registry`
_REGISTRY: dict[str, type[Method]] = {}
#: seconds: the declared build cost of a method that enumerates nothing (:meth:`Method.build_cost`)
#: at the sizes the service builds on its threads (up to about 6 x 64)
CHEAP_BUILD_SECONDS = 1e-3

# The bounds the declared costs keep.  Costs are CPU seconds on the project's machine (2 cores
# shared with other work; measured under load, so a quiet machine is faster), conservative.
#: No build starts whose declared :meth:`Method.build_cost` exceeds this: the facet searches
#: then use the LP formulation, ``da_table`` refuses the table (OptionError naming ``resolution``).
BUILD_LIMIT_SECONDS = 20.0
#: No build starts whose declared :meth:`Method.build_memory` exceeds this (1 GiB; the same
#: redirect to the LP).
BUILD_LIMIT_BYTES = 1 << 30
#: No allocator is built whose declared :meth:`Method.call_cost` exceeds this (``cgi`` refuses
#: ``priorities`` levels at sizes where its level-by-level cascade would: OptionError naming
#: ``priorities``).  The slowest call measured at the size caps: 1.2 s (``qp`` with 32
#: priority levels at 32 x 512, under load).
CALL_LIMIT_SECONDS = 3.0
# Default per-call models of the methods that declare none, fitted to the worst call of each
# cell of seeded random problems up to the size caps (``benchmarks/bench_cost_bounds.py``):
# an affine method (pinv, pinv_clip, ganging) is one O(k m) pass after the allocator's own checks
# (20-30 us a call at 3 x 8 under load, worst 160 us), 0.1 ms + 0.1 us k m; any other
# (pinv_scale, the compiled active set of qp/wls/dynamic, the simplex, the LP backends) at most
# 0.3 ms + 0.2 us k m (k + m) + 0.03 us k^3 m (priority levels and active-set iterations grow
# with k).  Declared / worst measured under load: 32 x 512 2.3 s / 1.2 s (qp, 32 levels);
# 32 x 64 102 / 67 ms (qp, 32 levels); 6 x 512 322 / 146 ms (da); 16 x 128 75 / 18 ms;
# 6 x 64 6.3 / 4.4 ms (dynamic).
_AFFINE_CALL_S, _AFFINE_CALL_KM_S = 1e-4, 1e-7
_CALL_BASE_S, _CALL_KMKM_S, _CALL_K3M_S = 3e-4, 2e-7, 3e-8
# Default build model: an SVD or QP/LP set-up is O(k m (k + m)): CHEAP_BUILD_SECONDS up to
# k m = 384 (6 x 64, where the service builds on its threads), beyond it 0.3 us k m (k + m)
# (2.7 s at 32 x 512, where builds of 0.3-2.9 s were measured under load).
_CHEAP_BUILD_ENTRIES, _BUILD_KMKM_S = 6 * 64, 3e-7


class Method(ABC):
    """Base class of allocation methods.

    Subclasses set the class attributes and implement :meth:`solve`.  ``solve``
    may return a command slightly outside ``[lo, hi]`` (round-off); the allocator
    clips it and computes the status.  It raises :class:`~alloc.exceptions.SolverError`
    when its backend fails; the allocator then returns the safe fallback.
    """

    #: registry name
    name: ClassVar[str] = ""
    #: where the method comes from (seed equation numbers)
    equation: ClassVar[str] = ""
    #: one line: what the method optimises
    summary: ClassVar[str] = ""
    #: accepted options: name -> typed specification (:mod:`alloc.options`), validated once by
    #: :func:`build`; shown by ``alloc methods`` and the service
    options: ClassVar[dict[str, Option]] = {}

    # Capabilities, declared at registration (``@register(name, affine=True, ...)``) and read
    # by the service, the coverage tools and the benchmarks; never guessed from module names.
    #: without rate limits the method is an affine map ``u = clip(c + P v)``
    affine: ClassVar[bool] = False
    #: the build enumerates the attainable moment set's facets (cost grows as C(m, k-1))
    needs_ams: ClassVar[bool] = False
    #: accepts the ``priorities`` option (axes met level by level)
    supports_priorities: ClassVar[bool] = False
    #: implements a vectorised :meth:`solve_batch`
    supports_batch: ClassVar[bool] = False
    #: the kind of C kernel :func:`alloc.export.export_c` writes for it (one of
    #: :data:`alloc.export_data.KINDS`; the method returns that kind's description from
    #: :meth:`export_data`), or ``None``: not exported
    export: ClassVar[str | None] = None
    #: the allocation the method computes, named by its family's first method: methods of one
    #: family return the same allocation by different algorithms (``da``, ``da_bisect``,
    #: ``da_facet``, ``da_table``: direct allocation); by default the method's own name
    family: ClassVar[str] = ""
    #: the option that takes a static distribution matrix (m x k) acting on the demand (``G``
    #: of ``ganging``), or ``None``; a simulator fills it with its scenario's design distribution
    distribution_option: ClassVar[str | None] = None

    @classmethod
    def facet_subsets(cls, problem: Problem, options: dict[str, Any]) -> int:
        """Facet generator subsets the build enumerates, C(m_free, k-1); 0 if none.

        The facet-search methods price their build with it (:meth:`build_cost`; the one
        facet limit is :data:`alloc.facet_cost.FACET_LIMIT`).
        """
        if not cls.needs_ams:
            return 0
        import math

        free = int((problem.umax > problem.umin).sum())
        return math.comb(free, max(problem.k - 1, 0))

    @classmethod
    def build_cost(cls, problem: Problem, **options: Any) -> float:
        """Declared build time of ``cls(problem, **options)`` in seconds (measured on the
        project's 2-core machine, conservative).  Read by the service before it builds;
        ``options`` may be unvalidated (an unreadable value counts as its default).

        Default: a closed form, an SVD or a QP/LP set-up, ``O(k m (k + m))``:
        :data:`CHEAP_BUILD_SECONDS` up to ``k m = 384`` (6 x 64), ``3e-7 k m (k + m)`` s beyond
        (2.7 s at the size caps, 32 x 512, where builds of 0.3-2.9 s were measured under load).
        """
        k, m = problem.k, problem.m
        if k * m <= _CHEAP_BUILD_ENTRIES:
            return CHEAP_BUILD_SECONDS
        return max(CHEAP_BUILD_SECONDS, _BUILD_KMKM_S * k * m * (k + m))

    @classmethod
    def build_memory(cls, problem: Problem, **options: Any) -> int:
        """Declared bytes the build allocates (its tables), conservative; ``options`` as for
        :meth:`build_cost`.  Default: a few dense ``k x m`` and ``m x m`` factors."""
        k, m = problem.k, problem.m
        return 8 * (8 * k * m + 2 * m * m + 4 * k * k)

    @classmethod
    def call_cost(cls, problem: Problem, **options: Any) -> float:
        """Declared worst-case CPU seconds of one call of ``cls(problem, **options)`` (nominal
        or rate-limited), conservative, on the project's machine; finite and positive.  The
        service prices a batch per row with it.  ``options`` as for :meth:`build_cost`.

        Default, fitted to the worst calls measured (``benchmarks/bench_cost_bounds.py``) of
        every method that declares none: ``0.1 ms + 0.1 us k m`` for an :attr:`affine` method,
        else ``0.3 ms + 0.2 us k m (k + m) + 0.03 us k^3 m`` (the compiled active set, the
        simplex, the LP backends; 2.3 s at the size caps, where 0.8-1.2 s was the worst
        measured under load).
        """
        k, m = problem.k, problem.m
        if cls.affine:
            return _AFFINE_CALL_S + _AFFINE_CALL_KM_S * k * m
        return _CALL_BASE_S + _CALL_KMKM_S * k * m * (k + m) + _CALL_K3M_S * k ** 3 * m

    #: ``(c, P)`` when the method is ``u = clip(c + P v)`` without rate limits: the
    #: allocator then runs it as one compiled call (pseudo-inverse family, ganging).
    fused: tuple[FloatArray, FloatArray] | None = None
    #: ``(kernel, state)`` when a call is one compiled call ``kernel(*state, v, u_prev, dt) -> out``
    #: (the allocator's fast path, see :func:`alloc._engine._active_set.lexico_call`; ``dt = 0`` without
    #: rate limits); ``packed_rate`` the same for rate-limited calls.
    packed: tuple[Any, tuple[Any, ...]] | None = None
    packed_rate: tuple[Any, tuple[Any, ...]] | None = None

    def __init__(self, problem: Problem) -> None:
        self.problem = problem

    @abstractmethod
    def solve(
        self, v: FloatArray, lo: FloatArray, hi: FloatArray, u_prev: FloatArray | None
    ) -> tuple[FloatArray, int]:
        """Return ``(u, iterations)`` for demand ``v`` within bounds ``[lo, hi]``."""

    def solve_batch(self, V: FloatArray, lo: FloatArray, hi: FloatArray) -> FloatArray | None:
        """Vectorised allocation of the rows of ``V`` (N, k); ``None`` if not vectorised."""
        return None

    def batch_finished(self, V: FloatArray) -> tuple[FloatArray, FloatArray, np.ndarray] | None:
        """``(U, B U, codes)`` for the rows of ``V`` within the position limits, each row
        exactly what the allocator's single call returns (its :func:`alloc._engine._kernels.finish`
        codes: 0 exact, 1 unattainable, anything else a row to redo one by one), solved and
        classified in one compiled pass; ``None`` where the method has no such pass."""
        return None

    def affine_map(self) -> tuple[FloatArray, FloatArray] | None:
        """``(c, P)`` when, without rate limits, the method returns ``u = c + P v`` wherever
        that is admissible (and something else, never ``B u = v``, where it is not); ``None``
        for any other method.  The coverage tools compute such a method's exact region as a
        polytope (:func:`alloc.ams.coverage`).  Default: the :attr:`fused` map.
        """
        return self.fused

    def export_data(self) -> KernelData | None:
        """The description of this built method's kernel, of its declared :attr:`export` kind
        (:mod:`alloc.export_data`), for the C generator; ``None`` where this instance cannot be
        exported (not exportable, or options such as another backend).  Default ``None``."""
        return None


#: the capability attributes a registration may set (``@register(name, affine=True, ...)``)
CAPABILITIES = ("affine", "needs_ams", "supports_priorities", "supports_batch")


def register(name: str, *, export: str | None = None, family: str | None = None, **capabilities: bool):
    """Class decorator registering an allocation method under ``name``.

    ``capabilities`` set the declared capability attributes of :class:`Method`
    (``affine``, ``needs_ams``, ``supports_priorities``, ``supports_batch``); ``export`` the
    kind of C kernel it exports as (:attr:`Method.export`, one of
    :data:`alloc.export_data.KINDS`); ``family`` the allocation it computes
    (:attr:`Method.family`, default ``name``).
    """
    unknown = sorted(set(capabilities) - set(CAPABILITIES))
    if unknown:
        raise TypeError(f"register: unknown capabilities {unknown}; accepted: {', '.join(CAPABILITIES)}")
    if export is not None and export not in KINDS:
        raise TypeError(f"register: unknown export kind {export!r}; accepted: {', '.join(KINDS)}")

    def deco(cls: type[Method]) -> type[Method]:
        if name in _REGISTRY:
            raise ValueError(f"method {name!r} registered twice")
        cls.name = name
        for cap, value in capabilities.items():
            setattr(cls, cap, bool(value))
        # set on every registered class: a subclass registered under its own name must not
        # inherit its parent's kernel or family by accident
        cls.export = export
        cls.family = name if family is None else family
        _REGISTRY[name] = cls
        return cls

    return deco
