"""Built-in allocation methods, one module per family; importing registers them."""

from . import cascade, direct, dynamic, facet_search, ganging, linear, pseudo_inverse, quadratic  # noqa: F401

__all__ = ["cascade", "direct", "dynamic", "facet_search", "ganging", "linear", "pseudo_inverse", "quadratic"]
