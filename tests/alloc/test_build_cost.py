"""The declared build-cost capability (``Method.build_cost``) and the service's budget policy.

The numbers are the methods' declared model (measured builds, table in
``alloc/methods/facet_search.py``); the service only compares them with its budget.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest

import alloc
from alloc.methods.facet_search import FACET_LIMIT, FACET_SECONDS, facet_build_seconds
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
    assert get_method("da").build_cost(p, backend="daqp") == CHEAP_BUILD_SECONDS
    assert get_method("da").build_cost(p) == CHEAP_BUILD_SECONDS  # auto: 7.6 million facets -> the LP


def test_facet_methods_price_their_enumeration():
    p = _problem(6, 20)
    p_jam = alloc.Problem(p.B, [-1.0] * 20, [-1.0] + [1.0] * 19)  # one jammed: C(19, 5)
    for method in ("da_facet", "da_bisect", "da_table"):  # no table nor edge table above k = 3
        assert get_method(method).build_cost(p) == pytest.approx(FACET_SECONDS * math.comb(20, 5), rel=1e-12)
        assert get_method(method).build_cost(p_jam) == pytest.approx(FACET_SECONDS * math.comb(19, 5), rel=1e-12)
    assert get_method("da").build_cost(p, backend="facet") == pytest.approx(FACET_SECONDS * math.comb(20, 5))


def test_facet_build_grows_with_the_tables_rows():
    """Every tile holds rows of m numbers: beyond k m = 480 the per-subset cost grows with k m
    (measured 68 us per subset at k = 3, m = 64; 184 us at m = 283)."""
    assert facet_build_seconds(1000, 480) == pytest.approx(1000 * FACET_SECONDS, rel=1e-12)
    assert facet_build_seconds(1000, 960) == pytest.approx(2000 * FACET_SECONDS, rel=1e-12)
    p = _problem(3, 200)
    assert get_method("da_facet").build_cost(p) == pytest.approx(FACET_SECONDS * 19_900 * 600 / 480, rel=1e-12)
    # da_bisect's k = 3 edge table: 200 us per subset more, growing alike
    assert get_method("da_bisect").build_cost(p) == pytest.approx(
        get_method("da_facet").build_cost(p) + 200e-6 * 600 / 480 * 19_900, rel=1e-12)


def test_da_table_adds_its_direction_table_at_k3():
    p = _problem(3, 64)
    facets = FACET_SECONDS * math.comb(64, 2)
    table = get_method("da_table")
    # resolution^2 x (300 + 2 x subsets) us: 9.1 s measured at m = 64, resolution 64 under load
    assert table.build_cost(p) == pytest.approx(facets + 64**2 * (300e-6 + 2e-6 * 2016), rel=1e-12)
    assert table.build_cost(p, resolution=8) == pytest.approx(facets + 64 * (300e-6 + 2e-6 * 2016), rel=1e-12)
    # an unreadable value counts as its default (the library refuses it at build)
    assert table.build_cost(p, resolution="x") == pytest.approx(facets, rel=1e-12)


def test_service_policy_reads_the_capability():
    pytest.importorskip("fastapi")
    from service.cost import DEFAULT_BUILD_BUDGET_S, build_seconds

    assert DEFAULT_BUILD_BUDGET_S == pytest.approx(FACET_SECONDS * FACET_LIMIT) == pytest.approx(3.0)
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
