"""Attainable moment set (seed sections 1.3.4.2 and 1.3.4.9): geometry, facet-search
direct allocation (``da_facet``, ``da_bisect``, ``da_table``) and method coverage."""

from .geometry import AttainableSet, Facet, generator_classes, zonotope_volume

__all__ = ["AttainableSet", "Facet", "generator_classes", "zonotope_volume", "coverage", "CoverageResult", "sample_ams"]
from . import search  # noqa: E402,F401  (registers da_facet, da_bisect, da_table)
from .coverage import CoverageResult, coverage, sample_ams  # noqa: E402
