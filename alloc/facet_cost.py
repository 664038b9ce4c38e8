"""The facet searches' declared cost model: build time and memory as a function of the facet
generator subsets C(m, k-1) and the entries of ``B``, and the facet limit.

Kept apart from :mod:`alloc.methods.facet_search` (which re-exports these names) so that a
caller that only prices work, such as the service's admission (``service/cost.py``), does not
import the methods' compiled kernels (numba) to do it.
"""

from __future__ import annotations

__all__ = ["FACET_LIMIT", "FACET_SECONDS", "FACET_BYTES", "facet_build_seconds", "facet_build_bytes"]

#: The facet limit: ``da``'s ``backend="auto"`` uses the facet search only up to this many
#: facet generator subsets C(m, k-1) (k = 6, m = 64 has 7.6 million), and the service's
#: default build budget is the declared build cost of an enumeration this large (3.0 s).
FACET_LIMIT = 20_000

# Declared build cost and memory (``Method.build_cost``, ``Method.build_memory``), CPU seconds
# and RSS growth measured on the project's machine (2 shared cores at load 8-11, 2026-12-01;
# ``benchmarks/bench_cost_bounds.py``), per facet generator subset S = C(m_free, k-1):
#
#   method      problem              S        build     per subset   RSS growth
#   da_facet    k=3, m=64            2,016    0.14 s    68 us        18 MiB
#   da_facet    k=3, m=141           9,870    0.81 s    82 us        199 MiB
#   da_facet    k=3, m=200           19,900   2.38 s    120 us       513 MiB
#   da_facet    k=3, m=283           39,903   7.35 s    184 us       1,295 MiB
#   da_facet    k=6, m=20            15,504   0.72 s    46 us        60-71 MiB
#   da_bisect   k=3, m=64 / 141 / 200         0.40 / 2.04 / 5.10 s (about 200 us per subset)
#   da_table    k=3, m=64 / 100, resolution 64  9.1 / 22.0 s (the direction table dominates)
#   largest admitted (declared / measured): k=3, m=223 da_facet 5.2 / 3.4 s, da_bisect
#   12.1 / 6.4 s, 1,011 / 683 MiB; k=6, m=28 14.7 / 8.2-9.1 s, 1,008 / 743 MiB; k=4, m=71
#   8.6 / 3.2-3.9 s, 991 / 603 MiB
#
# High rank (2026-12-05, under load; the vertex enumeration no longer runs at build and the
# cross product is a QR beyond k = 6): k=14, m=17 0.26 s / 28 MiB (declared 0.36 s / 35 MiB;
# before, 14.5 s and 3 GiB); k=16, m=19 0.26 s / 59 MiB (0.58 s / 72 MiB); k=20, m=23 1.1 s /
# 205 MiB (1.3 s / 249 MiB); k=24, m=27 1.4-2.1 s / 554 MiB (3.6 s / 694 MiB).
#
# Every table holds a row of m (or (k-1) x m) numbers per tile, so time and memory grow
# with S x k m.  The model: FACET_SECONDS per subset up to k m = 480, growing in proportion
# beyond; da_bisect adds 200 us per subset at k = 3 (its edge table, a Python loop per
# facet), growing the same way; da_table adds resolution^2 x (300 + 2 S) us (ray casts of the
# cell centres and corners against every tile); FACET_BYTES per subset and k m entry.  It
# over-predicts every measurement above, by 1.1-3.3x (time) and 1.3-2x (memory), and predicts
# the worst builds reported in issue 22 within 1.0-1.3x (k = 3, m = 447: da_facet 41.8 s
# declared / 41 s measured, da_bisect 97 / 77 s, da_table 860 / 781 s, 8.0 GiB / 5 GB;
# m = 69, resolution 128: 82 / 81 s).  Builds predicted beyond
# :data:`~alloc.registry.BUILD_LIMIT_SECONDS` or :data:`~alloc.registry.BUILD_LIMIT_BYTES`
# are never started: the facet searches use the LP formulation instead (k = 3: m > 223 by
# memory; k = 4: m > 71; k = 6: m > 28), ``da_table`` refuses a larger table naming ``resolution``.
#: seconds per facet generator subset enumerated at build, up to k m = 480 entries
FACET_SECONDS = 150e-6
_FACET_REFERENCE_ENTRIES = 480
#: bytes per facet generator subset and entry of B (k m) that the facet tables hold
FACET_BYTES = 64
_BISECT_SUBSET_SECONDS = 200e-6
_TABLE_CELL_SECONDS, _TABLE_CELL_SUBSET_SECONDS = 300e-6, 2.0e-6
_TABLE_TEMPORARY_BYTES = 96 << 20
# Declared call cost (``Method.call_cost``): a nominal call scans every tile (about two per
# subset) with a k x k product, a rate-limited call recomputes every facet's gap, O(m) each;
# declared / worst measured under load: k=3, m=141 33 / 8.9 ms; k=6, m=22 60 / 5.8 ms; k=3, m=200
# (da_bisect) 90 / 22 ms; k=2, m=512 6.3 / 1.5 ms (``benchmarks/bench_cost_bounds.py``).
_CALL_BASE_S, _CALL_SUBSET_K2_S, _CALL_SUBSET_M_S = 1e-3, 0.05e-6, 0.02e-6


def facet_build_seconds(subsets: int, entries: int = 0) -> float:
    """Declared build time (s) of a facet enumeration over ``subsets`` generator subsets of a
    ``B`` with ``entries = k m`` entries (0: the per-subset cost at small sizes)."""
    return FACET_SECONDS * subsets * max(1.0, entries / _FACET_REFERENCE_ENTRIES)


def facet_build_bytes(subsets: int, entries: int) -> int:
    """Declared memory (bytes) of the facet tables over ``subsets`` subsets of ``entries = k m``."""
    return FACET_BYTES * subsets * entries
