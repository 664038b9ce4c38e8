"""Attainable moment set (seed sections 1.3.4.2 and 1.3.4.9).

* :class:`AttainableSet` -- the AMS as a zonotope: facets (merged polygons for coplanar
  columns), vertices, exact volume, ray exit ``max_in_direction`` (Eq 1.15), ``contains``.
* Facet-search direct allocation registered in the core registry: ``da_facet``
  (sequential, Eqs 1.16-1.17), ``da_bisect`` (Durham's edge bisection), ``da_table``
  (spherical look-up table) -- module :mod:`alloc.ams.search`.
* :func:`coverage` -- the Bordignon-Durham fraction of the AMS a method reaches.
* :mod:`alloc.ams.plot` (matplotlib) and :mod:`alloc.ams.cli` (``alloc ams ...``).
"""

from . import search  # noqa: F401  (registers da_facet, da_bisect, da_table)
from .coverage import CoverageResult, coverage, sample_ams
from .geometry import AttainableSet, Facet, generator_classes, zonotope_volume

__all__ = [
    "AttainableSet", "Facet", "generator_classes", "zonotope_volume",
    "coverage", "CoverageResult", "sample_ams",
]
