"""The facet searches' declared cost model: build time and memory as a function of the facet
generator subsets C(m, k-1) and the entries of ``B``, and the facet limit.

Kept apart from :mod:`alloc.methods.facet_search` (which re-exports these names) so that a
caller that only prices work, such as the service's admission (``service/cost.py``), does not
import the methods' compiled kernels (numba) to do it.
"""

from __future__ import annotations

import numpy as np

__all__ = ["FACET_LIMIT", "FACET_SECONDS", "FACET_BYTES", "NEAR_FLAT_RTOL", "TILES_PER_SUBSET",
           "facet_build_seconds", "facet_build_bytes", "table_build_seconds", "table_build_bytes",
           "lp_build_seconds", "lp_build_bytes", "near_flat_ratio"]

#: The facet limit: ``da``'s ``backend="auto"`` uses the facet search only up to this many
#: facet generator subsets C(m, k-1) (k = 6, m = 64 has 7.6 million).
FACET_LIMIT = 20_000

# Declared build cost and memory (``Method.build_cost``, ``Method.build_memory``): CPU seconds
# and bytes on the project's machine (2 shared cores), fitted to the builds measured by
# ``benchmarks/bench_cost_model.py`` (2026-12-06, load 2-6; every cell and its ratio are in
# docs/contract.md).  S = C(m_free, k-1) facet generator subsets; a tile holds rows of k and
# m numbers (its inverse, corner control and edge steps), so the work is S x (k m + k^3):
#
#   seconds = 1 ms + S (0.15 us k m + 0.02 us k^3) + 0.4 us m^2
#
# (the m^2 term: grouping the columns by direction, pairwise; it dominates only at k = 2).
# Measured per subset and k m entry: 0.10-0.14 us from 3 x 64 to 6 x 28 (0.103 at 3 x 64,
# 0.142 at 3 x 141, 0.112 at 3 x 223, 0.109 at 4 x 32, 0.126 at 6 x 20, 0.128 at 6 x 28);
# the k^3 term from 14 x 17 (0.099-0.20 s: 0.42 us k m + k^3 per subset, the k x k inverses)
# and 8 x 16 (0.25 s; model 0.34 s).  Predicted / measured 0.64-1.2 over the grid.  The
# earlier model (150 us per subset up to k m = 480) was fitted before the vertex enumeration
# left the build and over-predicted 4-15x (measured / declared 0.06-0.25).
#
#   bytes = 64 KiB + 64 S k m                   measured / declared 0.55-0.69 (3 x 64 to 6 x 28),
#                                               1.1 at 2 x 512, 0.42 at 2 x 8 (the base)
#   da_bisect, k = 3: + 60 us S                 the edge table, a Python loop per facet
#                                               (44-65 us per subset measured, 3 x 16 to 3 x 223)
#   da_table, k = 3: + 20 ms + res^2 (20 us + 1.2 us S)   ray casts of about 4 res^2 directions
#                                               against every tile (2 S): 110-129 us per res^2 at
#                                               3 x 16, 2.06 ms at 3 x 64 (resolution 64); the 20 ms:
#                                               3 x 16 at resolution 16 took 35-75 ms under load 5-9
#              bytes + 80 res^2 + 24 min(4 res^2 x 2 S x 3, 2e6)   the candidate table and the
#                                               chunked ray casts' temporaries (<= 2 million tests)
#
# Builds predicted beyond :data:`~alloc.registry.BUILD_LIMIT_SECONDS` or
# :data:`~alloc.registry.BUILD_LIMIT_BYTES` are never started: the facet searches use the LP
# formulation instead (k = 3: m > 223; k = 4: m > 71; k = 6: m > 28, all by memory),
# ``da_table`` refuses a larger table naming ``resolution``.
#: the fixed part of a facet build (problem checks, the allocator's fallback)
FACET_BASE_S = 1e-3
#: seconds per facet generator subset and entry of B (k m)
FACET_SECONDS = 0.15e-6
#: seconds per facet generator subset and k^3 (the tiles' k x k inverses)
FACET_K3_SECONDS = 0.02e-6
#: seconds per pair of columns (grouping the generators by direction)
GENERATOR_PAIR_SECONDS = 0.4e-6
#: bytes per facet generator subset and entry of B (k m) that the facet tables hold
FACET_BYTES = 64
FACET_BASE_BYTES = 64 << 10
_BISECT_SUBSET_SECONDS = 60e-6
_TABLE_BASE_SECONDS, _TABLE_CELL_SECONDS, _TABLE_CELL_SUBSET_SECONDS = 20e-3, 20e-6, 1.2e-6
_TABLE_CELL_BYTES, _TABLE_TEST_BYTES, _TABLE_CHUNK_TESTS = 80, 24, 2_000_000
# Declared call cost (``Method.call_cost``): a nominal call scans every tile (about two per
# subset) with a k x k product, a rate-limited call recomputes every facet's gap, O(m) each;
# declared / worst measured under load: k=3, m=141 33 / 8.9 ms; k=6, m=22 60 / 5.8 ms; k=3, m=200
# (da_bisect) 90 / 22 ms; k=2, m=512 6.3 / 1.5 ms (``benchmarks/bench_cost_bounds.py``).
_CALL_BASE_S, _CALL_SUBSET_K2_S, _CALL_SUBSET_M_S = 1e-3, 0.05e-6, 0.02e-6


def facet_build_seconds(subsets: int, k: int, m: int) -> float:
    """Declared build time (s) of a facet enumeration over ``subsets`` generator subsets of a
    k x m ``B`` (the fit above)."""
    return (FACET_BASE_S + subsets * (FACET_SECONDS * k * m + FACET_K3_SECONDS * k ** 3)
            + GENERATOR_PAIR_SECONDS * m * m)


def facet_build_bytes(subsets: int, k: int, m: int) -> int:
    """Declared memory (bytes) of the facet tables over ``subsets`` subsets of a k x m ``B``."""
    return FACET_BASE_BYTES + FACET_BYTES * subsets * k * m


def table_build_seconds(subsets: int, resolution: int) -> float:
    """Declared build time (s) of ``da_table``'s (resolution x 2 resolution) direction table."""
    return _TABLE_BASE_SECONDS + float(resolution) ** 2 * (_TABLE_CELL_SECONDS + _TABLE_CELL_SUBSET_SECONDS * subsets)


def table_build_bytes(subsets: int, resolution: int) -> int:
    """Declared bytes of ``da_table``'s direction table and its ray casts' temporaries (k = 3)."""
    tests = min(4 * resolution ** 2 * 2 * subsets * 3, _TABLE_CHUNK_TESTS)
    return _TABLE_CELL_BYTES * resolution ** 2 + _TABLE_TEST_BYTES * tests

#: A ``B`` whose unit active columns have a singular value ratio in ``[1e-10, NEAR_FLAT_RTOL)``
#: is nearly rank-deficient: above 1e-10 the attainable set counts as full rank, but its
#: hyperplane search (``DIRECTION_TOL`` = 1e-9) merges directions for some hyperplanes and not
#: for others, and one subset then lands in many facets.  Measured (rank k-1 plus a Gaussian
#: perturbation, ``benchmarks/bench_cost_model.py``): 3 x 26 at 1e-9, 15,962 tiles for 325
#: subsets (da_table 51 s against 3.9 s declared; da_facet 3 x 64, 893,114 tiles, 8.8 s and
#: 2.1 GiB against 0.3 s and 24 MiB); at ratios 3e-7 to 1e-6 at most 1.1 tiles per 2 subsets.
#: Such a ``B`` is routed to the LP before any enumeration.
NEAR_FLAT_RTOL = 1e-7
_RANK_RTOL = 1e-10  # the attainable set's own rank cut (alloc.ams.geometry)
#: the most tiles per facet generator subset a build enumerates (2 in general position; more,
#: from uneven merging that the near-flat test did not see, sends the build to the LP)
TILES_PER_SUBSET = 3


def near_flat_ratio(problem) -> float:
    """The smallest singular value ratio of ``problem``'s unit active columns that lies in
    ``[1e-10, NEAR_FLAT_RTOL)``, or 0.0 when none does (a cheap SVD of a k x m matrix)."""
    B = problem.B[:, problem.umax > problem.umin]
    norms = np.linalg.norm(B, axis=0)
    B = B[:, norms > 0]
    if B.shape[1] == 0 or not np.isfinite(B).all():
        return 0.0
    s = np.linalg.svd(B / np.linalg.norm(B, axis=0), compute_uv=False)
    ratios = s / s[0]
    near = ratios[(ratios >= _RANK_RTOL) & (ratios < NEAR_FLAT_RTOL)]
    return float(near.min()) if near.size else 0.0


# The LP route (``da``'s LP backends and the facet searches' redirect, the ray LP of
# alloc.methods._direct_lp): a scaled copy of B, a row basis, the DAQP model and the compiled
# simplex's tableau.  Measured through make_allocator (the allocator's own checks and safe
# answer included): 1.1-1.5 ms from 3 x 26 to 6 x 29, 2.6-3.4 ms at 3 x 224; the bare set-up
# 0.25-0.42 ms up to 16 x 128, 6.2 ms at 32 x 512; traced peak 51 KiB at 3 x 26, 76 KiB at
# 6 x 29, 236 KiB at 4 x 72, 1.7 MiB at 3 x 224 (the allocator's m x m weighted factors).
_LP_BASE_S, _LP_KMKM_S = 2e-3, 2e-9
_LP_BASE_BYTES = 64 << 10


def lp_build_seconds(k: int, m: int) -> float:
    """Declared build time (s) of the ray LP: ``2 ms + 2 ns k m (k + m)``."""
    return _LP_BASE_S + _LP_KMKM_S * k * m * (k + m)


def lp_build_bytes(k: int, m: int) -> int:
    """Declared bytes of the ray LP's build: ``64 KiB + 8 (8 k m + 6 m^2 + 4 k^2)``."""
    return _LP_BASE_BYTES + 8 * (8 * k * m + 6 * m * m + 4 * k * k)
