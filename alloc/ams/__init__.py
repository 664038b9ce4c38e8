"""Attainable moment set geometry (seed sections 1.3.4.2 and 1.3.4.9): pure zonotope geometry.

* :class:`AttainableSet` -- the AMS as a zonotope: facets (merged polygons for coplanar
  columns), vertices, exact volume, ray exit ``max_in_direction`` (Eq 1.15), ``contains``,
  and :attr:`~AttainableSet.tiling` (:class:`FacetTiling`: the facet tiles as arrays, what a
  facet search reads).  The facet-search allocation methods built on it (``da_facet``,
  ``da_bisect``, ``da_table``) live with the other methods in :mod:`alloc.methods.facet_search`.
* :func:`coverage` -- the Bordignon-Durham fraction of the AMS a method reaches.
* :mod:`alloc.ams.plot` (matplotlib) and :mod:`alloc.ams.cli` (``alloc ams ...``).

Two layers share this package: :mod:`alloc.ams.geometry` sits below the allocation methods
(the facet searches build on it) and imports none of them; :mod:`alloc.ams.coverage` sits
above the allocator (it allocates to measure a method).  So the names are loaded on first
use (PEP 562): ``from alloc.ams import AttainableSet`` loads the geometry alone, not the
allocator nor ``scipy.optimize`` (``tests/test_layering.py``).
"""

from __future__ import annotations

import importlib
import types
from typing import TYPE_CHECKING, Any

from .. import _lazy

if TYPE_CHECKING:  # the lazily loaded names, for type checkers and IDEs
    from .coverage import CoverageResult, coverage, sample_ams
    from .geometry import DIRECTION_TOL, AttainableSet, Facet, FacetTiling, generator_classes, zonotope_volume

#: public name -> the submodule defining it (loaded on first attribute access)
_LAZY: dict[str, str] = {
    "AttainableSet": "geometry", "Facet": "geometry", "FacetTiling": "geometry", "DIRECTION_TOL": "geometry",
    "generator_classes": "geometry", "zonotope_volume": "geometry",
    "CoverageResult": "coverage", "sample_ams": "coverage",
}

__all__ = [
    "AttainableSet", "Facet", "FacetTiling", "DIRECTION_TOL", "generator_classes", "zonotope_volume",
    "coverage", "CoverageResult", "sample_ams",
]


def _submodule(name: str) -> types.ModuleType:
    module = _LAZY[name]
    return importlib.import_module(f".{module}", __name__)


def _coverage_function() -> Any:
    return importlib.import_module(".coverage", __name__).coverage


__getattr__, __dir__ = _lazy.attach(__name__, _LAZY, __all__, _submodule)
# the submodule ``alloc.ams.coverage`` has the name of the function ``alloc.ams.coverage()``
_lazy.keep_function(__name__, "coverage", _coverage_function)
