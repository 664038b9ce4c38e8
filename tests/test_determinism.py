"""History independence: a long-lived allocator returns what a fresh one returns.

For every registry method (and every backend of ``lp`` and ``da``), 1,000 mixed demands
(attainable and not, half of them with rate limits from a random previous command) are
allocated twice: by one allocator in sequence, and each by a fresh allocator (a deep copy
of one that was never called, which is a fresh build's state; built anew where the state
cannot be copied).  The answers agree to 1e-12.
"""

from __future__ import annotations

import copy

import numpy as np
import pytest

import alloc
from alloc.testing import random_problem
from alloc.vehicles import ice

N_DEMANDS = 1000

VARIANTS = [(m, {}) for m in alloc.methods()]
VARIANTS += [("lp", {"backend": "highs"}), ("lp", {"backend": "daqp"}), ("da", {"backend": "daqp"}), ("da", {"backend": "highs"})]
VARIANTS += [("qp", {"backend": "daqp"}), ("wls", {"backend": "daqp"})]


def mixed_calls(p: alloc.Problem, n: int, seed: int):
    rng = np.random.default_rng(seed)
    U = rng.uniform(p.umin, p.umax, size=(n, p.m))
    V = U @ p.B.T
    V[n // 3:] *= rng.uniform(1.0, 3.0, size=(n - n // 3, 1))
    calls = []
    for i, v in enumerate(V):
        if i % 2:
            calls.append((v, dict(u_prev=rng.uniform(p.umin, p.umax), dt=float(rng.choice([0.005, 0.02, 0.1])))))
        else:
            calls.append((v, {}))
    return calls


def _fresh_factory(p, method, options):
    template = alloc.make_allocator(p, method, **options)
    try:  # the Problem is immutable: shared, not copied
        copy.deepcopy(template, {id(p): p})
    except (TypeError, ValueError, AttributeError, copy.Error):
        return lambda: alloc.make_allocator(p, method, **options)
    return lambda: copy.deepcopy(template, {id(p): p})


@pytest.mark.parametrize("method,options", VARIANTS, ids=[f"{m}-{o.get('backend', 'default')}" for m, o in VARIANTS])
def test_long_lived_equals_fresh(method, options):
    p = ice()
    if method == "lp":
        p = p.replace(Wv=np.diagonal(p.Wv))
    calls = mixed_calls(p, N_DEMANDS, seed=17)
    long_lived = alloc.make_allocator(p, method, **options)
    fresh = _fresh_factory(p, method, options)
    worst = 0.0
    for v, kw in calls:
        a = long_lived(v, **kw)
        b = fresh()(v, **kw)
        assert a.status == b.status
        worst = max(worst, float(np.abs(a.u - b.u).max()))
    assert worst <= 1e-12, f"{method} {options}: long-lived and fresh differ by {worst:.3g}"


@pytest.mark.parametrize("method", ["lp", "qp", "wls", "da"])
def test_long_lived_equals_fresh_random_problem(method):
    """The same on a random 4 x 10 problem with rate limits and weights (200 calls)."""
    p = random_problem(np.random.default_rng(4), 4, 10, "coplanar")
    p = p.replace(Wv=np.diagonal(p.Wv))
    calls = mixed_calls(p, 200, seed=5)
    long_lived = alloc.make_allocator(p, method)
    fresh = _fresh_factory(p, method, {})
    for v, kw in calls:
        np.testing.assert_allclose(long_lived(v, **kw).u, fresh()(v, **kw).u, rtol=0, atol=1e-12)
