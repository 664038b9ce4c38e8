"""The declared build-cost capability (``Method.build_cost``) and the service's budget policy.

The numbers are the methods' declared model (measured builds: the fit in ``alloc/facet_cost.py``,
the table in docs/contract.md by ``benchmarks/bench_cost_model.py``); the service only compares
them with its budget.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest

import alloc
from alloc.facet_cost import NEAR_FLAT_RTOL, lp_build_bytes, lp_build_seconds, near_flat_ratio
from alloc.methods.facet_search import FACET_LIMIT, FacetSearch, facet_build_seconds
from alloc.registry import CHEAP_BUILD_SECONDS, get_method

ROOT = Path(__file__).resolve().parents[2]


def _problem(k: int, m: int, seed: int = 1) -> alloc.Problem:
    rng = np.random.default_rng(seed)
    return alloc.Problem(rng.normal(size=(k, m)), [-1.0] * m, [1.0] * m)


@pytest.mark.parametrize("method", alloc.methods())
def test_every_method_declares_a_finite_build_cost(method):
    cost = get_method(method).build_cost(_problem(3, 11))
    assert isinstance(cost, float) and 0.0 < cost < 60.0


def test_closed_form_and_optimisation_methods_are_cheap():
    p = _problem(6, 64)
    for method in ("pinv", "pinv_clip", "pinv_scale", "ganging", "cgi", "daisy", "qp", "wls", "lp", "dynamic"):
        assert get_method(method).build_cost(p) == CHEAP_BUILD_SECONDS
    # da's LP backends declare the ray LP's measured set-up: 2 ms + 2 ns k m (k + m)
    lp = 2e-3 + 2e-9 * 6 * 64 * 70
    assert get_method("da").build_cost(p, backend="daqp") == pytest.approx(lp, rel=1e-12) == lp_build_seconds(6, 64)
    assert get_method("da").build_cost(p) == pytest.approx(lp, rel=1e-12)  # auto: 7.6 million facets -> the LP
    assert get_method("da").build_memory(p) == lp_build_bytes(6, 64) == (64 << 10) + 8 * (8 * 384 + 6 * 64**2 + 4 * 36)


def _facet_seconds(subsets: int, k: int, m: int) -> float:
    """The measured model written out (alloc/facet_cost.py): 1 ms + S (0.15 us k m + 0.02 us k^3) + 0.4 us m^2."""
    return 1e-3 + subsets * (0.15e-6 * k * m + 0.02e-6 * k**3) + 0.4e-6 * m * m


def test_facet_methods_price_their_enumeration():
    p = _problem(6, 20)
    p_jam = alloc.Problem(p.B, [-1.0] * 20, [-1.0] + [1.0] * 19)  # one jammed: C(19, 5)
    for method in ("da_facet", "da_bisect", "da_table"):  # no table nor edge table above k = 3
        assert get_method(method).build_cost(p) == pytest.approx(_facet_seconds(math.comb(20, 5), 6, 20), rel=1e-12)
        assert get_method(method).build_cost(p_jam) == pytest.approx(_facet_seconds(math.comb(19, 5), 6, 20),
                                                                      rel=1e-12)
        assert get_method(method).build_memory(p) == (64 << 10) + 64 * math.comb(20, 5) * 120
    da = get_method("da")
    assert da.build_cost(p, backend="facet") == get_method("da_facet").build_cost(p)
    # the facet backend declares the facet tables' memory, not an LP's
    assert da.build_memory(p, backend="facet") == get_method("da_facet").build_memory(p)


def test_facet_build_grows_with_the_tables_entries_and_rank():
    """Every tile holds rows of k and m numbers and a k x k inverse: S (k m + k^3) work."""
    assert facet_build_seconds(1000, 3, 160) == pytest.approx(_facet_seconds(1000, 3, 160), rel=1e-12)
    grow = facet_build_seconds(1000, 3, 320) - facet_build_seconds(1000, 3, 160)
    assert grow == pytest.approx(1000 * 0.15e-6 * 3 * 160 + 0.4e-6 * (320**2 - 160**2), rel=1e-12)
    p = _problem(3, 200)
    assert get_method("da_facet").build_cost(p) == pytest.approx(_facet_seconds(19_900, 3, 200), rel=1e-12)
    # da_bisect's k = 3 edge table: 60 us per subset more
    assert get_method("da_bisect").build_cost(p) == pytest.approx(
        get_method("da_facet").build_cost(p) + 60e-6 * 19_900, rel=1e-12)
    assert get_method("da_bisect").build_memory(p) == get_method("da_facet").build_memory(p) + 48 * 200**2


def test_da_table_adds_its_direction_table_at_k3():
    p = _problem(3, 64)
    facets = _facet_seconds(math.comb(64, 2), 3, 64)
    table = get_method("da_table")
    # 20 ms + resolution^2 x (20 + 1.2 subsets) us: 7.9-8.5 s measured at m = 64, resolution 64 (declared 10.1 s)
    assert table.build_cost(p) == pytest.approx(facets + 0.02 + 64**2 * (20e-6 + 1.2e-6 * 2016), rel=1e-12)
    assert table.build_cost(p, resolution=8) == pytest.approx(facets + 0.02 + 64 * (20e-6 + 1.2e-6 * 2016),
                                                              rel=1e-12)
    # an unreadable value counts as its default (the library refuses it at build)
    assert table.build_cost(p, resolution="x") == pytest.approx(facets, rel=1e-12)
    # memory: the candidate table and at most 2 million ray-cast tests in flight (24 bytes each)
    tables = get_method("da_facet").build_memory(p)
    assert table.build_memory(p, resolution=64) == tables + 80 * 64**2 + 24 * 2_000_000
    assert table.build_memory(p, resolution=2) == tables + 80 * 4 + 24 * 4 * 4 * 2 * 2016 * 3


def test_service_policy_reads_the_capability():
    pytest.importorskip("fastapi")
    from service.cost import DEFAULT_BUILD_BUDGET_S, build_seconds

    assert DEFAULT_BUILD_BUDGET_S == 3.0
    # the budget admits every enumeration da's backend="auto" would choose (up to FACET_LIMIT subsets)
    assert facet_build_seconds(FACET_LIMIT, 6, 64) <= DEFAULT_BUILD_BUDGET_S
    p = _problem(3, 64)
    for method, options in [("da_table", {"resolution": 256}), ("da_bisect", {}), ("pinv", {}), ("da", {})]:
        assert build_seconds(p, method, options) == get_method(method).build_cost(p, **options)
    assert build_seconds(p, "da_table", {"resolution": 256}) > DEFAULT_BUILD_BUDGET_S  # refused by the service
    assert build_seconds(_problem(6, 20), "da_facet", {}) < DEFAULT_BUILD_BUDGET_S  # 15,504 subsets: admitted


def test_one_definition_of_the_facet_limit():
    """The 20,000-subset facet limit is written once; everything else imports it."""
    hits = set()
    for pkg in ("alloc", "service", "sim", "benchmarks"):
        for path in (ROOT / pkg).rglob("*.py"):
            for line in path.read_text().splitlines():
                if re.match(r"\s*FACET_LIMIT\s*=", line) or (
                        re.search(r"\b(20_?000|2e4)\b", line) and re.search(r"facet|\bnf\b", line, re.I)):
                    hits.add(f"{path.relative_to(ROOT)}: {line.strip()}")
    assert hits == {"alloc/facet_cost.py: FACET_LIMIT = 20_000"}, hits


def _near_flat(k: int, m: int, eps: float, seed: int = 0) -> alloc.Problem:
    """Rank k - 1 plus an ``eps`` Gaussian perturbation (the near-singular conditioning)."""
    rng = np.random.default_rng(seed)
    B = rng.normal(size=(k, k - 1)) @ rng.normal(size=(k - 1, m)) + eps * rng.normal(size=(k, m))
    return alloc.Problem(B, [-1.0] * m, [1.0] * m)


@pytest.mark.parametrize("method", ["da_facet", "da_bisect", "da_table", "da"])
def test_a_nearly_rank_deficient_b_is_routed_to_the_lp_before_enumerating(method):
    """3 x 26 at 1e-9: 15,962 tiles for 325 subsets (da_table declared 3.9 s, took 32-51 s);
    routed to the LP by a k x m SVD, the declared memory is the LP's, the answers da's LP's."""
    p = _near_flat(3, 26, 1e-9)
    options = {"resolution": 64} if method == "da_table" else {}
    if method == "da":
        options = {"backend": "facet"}
    f = alloc.make_allocator(p, method, **options)
    impl = f.impl._facet if method == "da" else f.impl
    assert impl._lp is not None and "nearly rank-deficient" in impl.lp_reason and "B" in impl.lp_reason
    assert not hasattr(impl, "ams")  # no enumeration started
    if method != "da":
        assert get_method(method).build_memory(p, **options) == lp_build_bytes(3, 26)
    reference = alloc.make_allocator(p, "da", backend="highs")
    rng = np.random.default_rng(1)
    for v in rng.normal(size=(20, 3)) * 5.0:
        a, b = f(v), reference(v)
        assert np.isfinite(a.u).all() and (a.u >= p.umin - 1e-9).all() and (a.u <= p.umax + 1e-9).all()
        assert a.status == b.status
        assert np.abs(a.v_achieved - b.v_achieved).max() <= 1e-6 * max(1.0, float(np.abs(v).max()))


def test_the_near_flat_band_is_where_the_merging_is_uneven():
    """Flat (below 1e-10) and well-conditioned sets enumerate; the band between is routed."""
    assert FacetSearch.redirected(_near_flat(3, 26, 1e-14)) == ""  # flat: rank 2, exact tiling
    assert FacetSearch.redirected(_near_flat(3, 26, 1e-5)) == ""
    assert near_flat_ratio(_near_flat(3, 26, 1e-5)) == 0.0
    for eps in (1e-10, 1e-9, 1e-8):
        assert 1e-10 <= near_flat_ratio(_near_flat(3, 26, eps)) < NEAR_FLAT_RTOL
        assert "nearly rank-deficient" in FacetSearch.redirected(_near_flat(3, 26, eps))


def test_a_tiling_beyond_its_limit_is_refused_before_it_is_built():
    """The safety net behind the near-flat test: the tile count is checked from the facets'
    free directions before any tile exists; the facet searches then use the LP."""
    from alloc.ams import AttainableSet
    from alloc.exceptions import ProblemError

    p = _near_flat(3, 26, 1e-9)
    assert AttainableSet(p).n_tiles == 11_920  # uneven merging: 37 tiles per 2 subsets
    with pytest.raises(ProblemError, match="11,920 facet tiles exceed the limit of 975"):
        AttainableSet(p, tile_limit=3 * math.comb(26, 2))
    well = _problem(3, 26)
    assert AttainableSet(well, tile_limit=2 * math.comb(26, 2)).n_tiles == 2 * math.comb(26, 2)
