"""Attainable moment set geometry (seed sections 1.3.4.2 and 1.3.4.9): pure zonotope geometry.

* :class:`AttainableSet` -- the AMS as a zonotope: facets (merged polygons for coplanar
  columns), vertices, exact volume, ray exit ``max_in_direction`` (Eq 1.15), ``contains``,
  and :attr:`~AttainableSet.tiling` (:class:`FacetTiling`: the facet tiles as arrays, what a
  facet search reads).  The facet-search allocation methods built on it (``da_facet``,
  ``da_bisect``, ``da_table``) live with the other methods in :mod:`alloc.methods.facet_search`.
* :func:`coverage` -- the Bordignon-Durham fraction of the AMS a method reaches.
* :mod:`alloc.ams.plot` (matplotlib) and :mod:`alloc.ams.cli` (``alloc ams ...``).

This package imports nothing from :mod:`alloc.methods` (``tests/test_layering.py``).
"""

from .coverage import CoverageResult, coverage, sample_ams
from .geometry import DIRECTION_TOL, AttainableSet, Facet, FacetTiling, generator_classes, zonotope_volume

__all__ = [
    "AttainableSet", "Facet", "FacetTiling", "DIRECTION_TOL", "generator_classes", "zonotope_volume",
    "coverage", "CoverageResult", "sample_ams",
]
