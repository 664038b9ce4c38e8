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
from alloc.methods.facet_search import FACET_LIMIT, FACET_SECONDS
from alloc.registry import CHEAP_BUILD_SECONDS, get_method

ROOT = Path(__file__).resolve().parents[1]


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
    for method in ("da_facet", "da_bisect", "da_table"):  # no table above k = 3
        assert get_method(method).build_cost(p) == pytest.approx(FACET_SECONDS * math.comb(20, 5), rel=1e-12)
        assert get_method(method).build_cost(p_jam) == pytest.approx(FACET_SECONDS * math.comb(19, 5), rel=1e-12)
    assert get_method("da").build_cost(p, backend="facet") == pytest.approx(FACET_SECONDS * math.comb(20, 5))


def test_da_table_adds_its_direction_table_at_k3():
    p = _problem(3, 64)
    facets = FACET_SECONDS * math.comb(64, 2)
    table = get_method("da_table")
    # resolution^2 x (270 + 0.75 x subsets) us: 7.3 s measured at m = 64, resolution 64
    assert table.build_cost(p) == pytest.approx(facets + 64**2 * (270e-6 + 0.75e-6 * 2016), rel=1e-12)
    assert table.build_cost(p, resolution=8) == pytest.approx(facets + 64 * (270e-6 + 0.75e-6 * 2016), rel=1e-12)
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
    assert hits == {"alloc/methods/facet_search.py: FACET_LIMIT = 20_000"}, hits
