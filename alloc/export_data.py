"""What a built method shows the C generator: frozen, typed descriptions of its kernel.

A method that can be exported declares the kind of kernel it is at registration
(``@register("name", export="affine")``, :data:`KINDS`) and returns the matching description
from :meth:`alloc.method.Method.export_data`; :meth:`alloc.Allocator.export_data` adds the
allocator's safe answer.  The generator (:mod:`alloc.export`) reads these and nothing else of
a method, so a method's private attributes stay its own, and a new method of an existing kind
is exported by declaring the kind.

A leaf of the library: the methods build these, :mod:`alloc.export` reads them.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import ClassVar

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "KINDS",
    "ActiveSetData",
    "AffineData",
    "CascadeData",
    "ExportData",
    "KernelData",
    "ScaledData",
    "SimplexData",
]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class AffineData:
    """``u = clip(c + P v)`` (``pinv``, ``pinv_clip``, ``ganging``; the safe answer)."""

    kind: ClassVar[str] = "affine"
    #: constant term, shape (m,)
    c: FloatArray
    #: distribution matrix, shape (m, k)
    P: FloatArray


@dataclass(frozen=True)
class ScaledData:
    """The increment ``P (v - B base)`` from the preferred position clipped into the call's
    bounds, scaled by one factor into them (``pinv_scale``)."""

    kind: ClassVar[str] = "scaled"
    #: distribution matrix, shape (m, k)
    P: FloatArray


@dataclass(frozen=True)
class CascadeData:
    """The cascaded generalized inverse over a table of every free set's pseudo-inverse (``cgi``)."""

    kind: ClassVar[str] = "cascade"
    #: the axes of each priority level, most important first; ``None`` for one level
    groups: tuple[np.ndarray, ...] | None
    #: ``free_set_pinv(free) -> P``: the weighted pseudo-inverse over the effectors where the
    #: boolean mask ``free`` is set, rows of the free effectors first (the method's own bits)
    free_set_pinv: Callable[[np.ndarray], FloatArray]
    #: ``level_pinv(level, free) -> P``: level ``level``'s prioritised pseudo-inverse over ``free``,
    #: the columns of that level's own axes (the method's own bits)
    level_pinv: Callable[[int, np.ndarray], FloatArray]


@dataclass(frozen=True)
class ActiveSetData:
    """The compiled lexicographic least-squares active set (``wls``, ``qp``, ``dynamic``)."""

    kind: ClassVar[str] = "active_set"
    #: each solver instance's packed state (:func:`alloc._engine._active_set.pack`): one for ``qp`` and
    #: ``wls``, two for ``dynamic`` (without and with ``u_prev``)
    states: tuple[tuple[np.ndarray, ...], ...]


@dataclass(frozen=True)
class SimplexData:
    """The compiled lexicographic simplex (:class:`alloc._engine._simplex.LexicographicL1`, ``lp``)."""

    kind: ClassVar[str] = "simplex"
    #: the scaled tableau (k x N), its row scales (k,), the half-widths (m,), the stages' costs
    F: FloatArray
    rho: FloatArray
    D: FloatArray
    costs: FloatArray
    #: the library's pivot cap, ``50 (N + k)``
    max_iter: int
    #: ``pivots(v, lo, hi)``: the pivots the library's simplex takes on ``v`` within ``[lo, hi]``
    pivots: Callable[[np.ndarray, np.ndarray, np.ndarray], int]


KernelData = AffineData | ScaledData | CascadeData | ActiveSetData | SimplexData
#: the kinds of kernel a method may declare (``@register(name, export=kind)``)
KINDS = tuple(cls.kind for cls in (AffineData, ScaledData, CascadeData, ActiveSetData, SimplexData))


@dataclass(frozen=True)
class ExportData:
    """A built allocator as the C generator sees it (:meth:`alloc.Allocator.export_data`)."""

    #: the registered method name
    method: str
    #: the method's kernel (its declared kind)
    kernel: KernelData
    #: the safe answer (Eq 1.23 clipped), or ``None`` where the pseudo-inverse could not be formed
    #: (the safe answer is then the preferred position clipped)
    safe: AffineData | None
