"""Built-in allocation methods, one module per family; importing registers them."""

from . import (cascade, direct, dynamic, edge_bisect, facet_search, ganging, linear, pseudo_inverse,
               px4, quadratic, spherical_table)

__all__ = ["cascade", "direct", "dynamic", "edge_bisect", "facet_search", "ganging", "linear", "pseudo_inverse",
           "px4", "quadratic", "spherical_table"]
