"""One registry of allocation methods, all with the same signature.

A method is a class deriving from :class:`Method`, registered with
``@register("name")``.  It is constructed once per allocator with the problem
and its options (precomputing whatever it can) and then called with a demand
and the effective bounds of that call (position limits, or the rate-limited
bounds of Eq 1.28).  Adding a method is one new module plus one decorator.
"""

from __future__ import annotations

import importlib
from abc import ABC, abstractmethod
from typing import Any, ClassVar

import numpy as np
from numpy.typing import NDArray

from .exceptions import UnknownMethodError
from .options import Option, validate
from .problem import Problem

__all__ = ["Method", "register", "get_method", "methods", "method_info", "DEFAULT_METHOD"]

FloatArray = NDArray[np.float64]

_REGISTRY: dict[str, type[Method]] = {}
#: seconds: the declared build cost of a method that enumerates nothing (:meth:`Method.build_cost`)
CHEAP_BUILD_SECONDS = 1e-3
#: the method used wherever none is named (library, command line, HTTP): ``qp`` meets every
#: attainable demand exactly (seed Eqs 1.20-1.21), which the pseudo-inverse family (Eq 1.23) does not
DEFAULT_METHOD = "qp"


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

    @classmethod
    def facet_subsets(cls, problem: Problem, options: dict[str, Any]) -> int:
        """Facet generator subsets the build enumerates, C(m_free, k-1); 0 if none.

        The facet-search methods price their build with it (:meth:`build_cost`; the one
        facet limit is :data:`alloc.methods.facet_search.FACET_LIMIT`).
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

        Default: :data:`CHEAP_BUILD_SECONDS` -- a closed form, an SVD or a QP/LP set-up
        within the size caps (6 x 64) builds in milliseconds.
        """
        return CHEAP_BUILD_SECONDS

    #: ``(c, P)`` when the method is ``u = clip(c + P v)`` without rate limits: the
    #: allocator then runs it as one compiled call (pseudo-inverse family, ganging).
    fused: tuple[FloatArray, FloatArray] | None = None
    #: ``(kernel, state)`` when a call is one compiled call ``kernel(*state, v, u_prev, dt) -> out``
    #: (the allocator's fast path, see :func:`alloc._active_set.lexico_call`; ``dt = 0`` without
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
        exactly what the allocator's single call returns (its :func:`alloc._kernels.finish`
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


_CAPABILITIES = ("affine", "needs_ams", "supports_priorities", "supports_batch")


def register(name: str, **capabilities: bool):
    """Class decorator registering an allocation method under ``name``.

    ``capabilities`` set the declared capability attributes of :class:`Method`
    (``affine``, ``needs_ams``, ``supports_priorities``, ``supports_batch``).
    """
    unknown = sorted(set(capabilities) - set(_CAPABILITIES))
    if unknown:
        raise TypeError(f"register: unknown capabilities {unknown}; accepted: {', '.join(_CAPABILITIES)}")

    def deco(cls: type[Method]) -> type[Method]:
        if name in _REGISTRY:
            raise ValueError(f"method {name!r} registered twice")
        cls.name = name
        for cap, value in capabilities.items():
            setattr(cls, cap, bool(value))
        _REGISTRY[name] = cls
        return cls

    return deco


def _load_builtin() -> None:
    # Importing the packages registers the built-in methods (one module per family).  By
    # full name: ``from . import methods`` would find the function ``alloc.methods``.
    importlib.import_module("alloc.methods")


def get_method(name: str) -> type[Method]:
    """The method class registered as ``name``; unknown names list the registered ones."""
    _load_builtin()
    if not isinstance(name, str) or name not in _REGISTRY:
        raise UnknownMethodError(f"method: unknown method {name!r}; registered: {', '.join(sorted(_REGISTRY))}")
    return _REGISTRY[name]


def methods() -> list[str]:
    """Names of the registered allocation methods."""
    _load_builtin()
    return sorted(_REGISTRY)


def method_info(name: str) -> dict[str, Any]:
    """Name, seed equation, summary, options and capabilities of a method (CLI and service).

    ``options`` maps each option to one descriptive line; ``option_specs`` gives the typed
    specification (type, default, constraint, doc).
    """
    cls = get_method(name)
    return {"name": name, "equation": cls.equation, "summary": cls.summary,
            "options": {opt: spec.describe() for opt, spec in cls.options.items()},
            "option_specs": {opt: spec.to_dict() for opt, spec in cls.options.items()},
            "capabilities": {cap: bool(getattr(cls, cap)) for cap in _CAPABILITIES}}


def build(problem: Problem, name: str, options: dict[str, Any]) -> Method:
    """Construct method ``name`` for ``problem`` with validated options.

    Unknown options and inadmissible values raise :class:`~alloc.exceptions.OptionError`
    (a ``TypeError``) naming the option (:func:`alloc.options.validate`).
    """
    cls = get_method(name)
    values = validate(name, cls.options, options)
    if not isinstance(problem, Problem):
        raise TypeError(f"problem: expected alloc.Problem, got {type(problem).__name__}")
    return cls(problem, **values)
