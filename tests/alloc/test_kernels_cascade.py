"""The compiled cascades (``cgi``, ``daisy``, ``pinv_scale``) against their numpy originals.

Each method keeps its numpy implementation as ``_solve_reference``; the compiled
``solve`` must return the same command (to 1e-12 relative) and the same iteration count
on random problems of every kind, with and without rate limits.
"""

from __future__ import annotations

import numpy as np
import pytest

import alloc
from alloc.testing import KINDS, random_demands, random_problem

CASES = 10_000  # (problem, demand, bounds) triples per method
RTOL = 1e-12


def random_groups(rng: np.random.Generator, m: int) -> list[list[int]]:
    """Effector groups for daisy chaining: a random partition of a random subset."""
    order = rng.permutation(m)[: rng.integers(1, m + 1)]
    cuts = np.sort(rng.choice(np.arange(1, len(order)), size=min(len(order) - 1, rng.integers(0, 4)), replace=False))
    return [g.tolist() for g in np.split(order, cuts)]


def cases(seed: int, method: str):
    """Yield ``(impl, v, lo, hi, u_prev)``: problems of all kinds, k = 1..6, m = 1..30, some
    with a full (non-diagonal) ``Wu``."""
    rng = np.random.default_rng(seed)
    n = 0
    while n < CASES:
        kind = KINDS[rng.integers(len(KINDS))]
        k = int(rng.integers(1, 7))
        m = int(rng.integers(1, 31))
        p = random_problem(rng, k, m, kind, weights=bool(rng.random() < 0.8))
        if rng.random() < 0.15:  # a full Wu: cgi computes new inverses in numpy, not compiled
            L = rng.normal(size=(m, m))
            p = p.replace(Wu=L @ L.T + m * np.eye(m))
        if method == "daisy":
            options = {"groups": random_groups(rng, m)} if rng.random() < 0.6 else {}
        elif method == "pinv_scale":
            options = {"incremental": bool(rng.random() < 0.5)}
        else:
            options = {"priorities": [1] * k} if rng.random() < 0.1 else {}  # one level: the cascade
        impl = alloc.make_allocator(p, method, **options).impl
        for v in random_demands(rng, p, 25):
            if rng.random() < 0.5:
                lo, hi, u_prev = p.umin, p.umax, None
            else:
                u_prev = rng.uniform(p.umin, p.umax)
                lo, hi = p.effective_bounds(u_prev, float(rng.uniform(0.001, 0.2)))
            yield impl, v, lo, hi, u_prev
            n += 1


def assert_same(fast, ref):
    (u, it), (u_ref, it_ref) = fast, ref
    assert it == it_ref
    u, u_ref = np.asarray(u), np.asarray(u_ref)
    nan = np.isnan(u_ref)
    assert (np.isnan(u) == nan).all()
    err = np.abs(u - u_ref)[~nan]
    assert (err <= RTOL * np.maximum(1.0, np.abs(u_ref[~nan]))).all(), err.max()


@pytest.mark.parametrize("method", ["cgi", "daisy", "pinv_scale"])
def test_compiled_matches_numpy(method):
    seen = 0
    for impl, v, lo, hi, u_prev in cases(7, method):
        assert_same(impl.solve(v, lo, hi, u_prev), impl._solve_reference(v, lo, hi, u_prev))
        seen += 1
    assert seen == CASES


def test_cgi_full_cache_is_emptied_and_answers_do_not_depend_on_it():
    """Past the cache limit the cache is emptied and refilled: every answer is bit for bit a
    fresh allocator's (the compiled cascade's), whatever the cache held before."""
    rng = np.random.default_rng(3)
    p = random_problem(rng, 3, 12)
    impl = alloc.make_allocator(p, "cgi").impl
    impl._cache_slots = 2
    refills = 0
    for v in random_demands(rng, p, 200, attainable_fraction=0.2):
        before = impl._banked
        u, it = impl.solve(v, p.umin, p.umax, None)
        refills += impl._banked < before
        fresh = alloc.make_allocator(p, "cgi").impl
        assert np.array_equal(u, fresh.solve(v, p.umin, p.umax, None)[0])
        assert_same((u, it), impl._solve_reference(v, p.umin, p.umax, None))
        assert impl._banked <= 2
    assert refills > 10


def test_cgi_cache_is_bounded_in_bytes():
    """At the size caps the cache holds 512 free sets (64 MiB), not 4,096 (512 MiB)."""
    from alloc.methods.cascade import CGI_CACHE_BYTES
    rng = np.random.default_rng(4)
    assert alloc.make_allocator(random_problem(rng, 3, 11), "cgi").impl._cache_slots == 4096
    big = alloc.make_allocator(random_problem(rng, 32, 512, weights=False, rates=False), "cgi").impl
    assert big._cache_slots == 512 and big._cache_slots * 8 * 32 * 512 == CGI_CACHE_BYTES


def test_cgi_cache_grows_past_its_first_bank():
    """More free sets than the initial bank holds: the bank is enlarged, answers kept."""
    rng = np.random.default_rng(5)
    p = random_problem(rng, 2, 20)
    impl = alloc.make_allocator(p, "cgi").impl
    first = impl._bank.shape[0]
    for v in random_demands(rng, p, 400, attainable_fraction=0.0):
        assert_same(impl.solve(v, p.umin, p.umax, None), impl._solve_reference(v, p.umin, p.umax, None))
    assert impl._banked > first


def test_cgi_by_level_cache_keeps_answers_bit_for_bit():
    """The by-level pseudo-inverses are cached per (level, free set): a long-lived allocator
    answers every demand exactly as a fresh one, also when its cache is emptied mid-way."""
    rng = np.random.default_rng(6)
    p = random_problem(rng, 4, 10)
    pr = [2, 1, 1, 0]
    f = alloc.make_allocator(p, "cgi", priorities=pr)
    V = random_demands(rng, p, 120, attainable_fraction=0.3)
    for i, v in enumerate(V):
        if i == 60:
            f.impl._level_cache.clear()
            f.impl._level_bytes = 0
        assert np.array_equal(f(v).u, alloc.make_allocator(p, "cgi", priorities=pr)(v).u)
    assert 0 < len(f.impl._level_cache) and f.impl._level_bytes == sum(P.nbytes for P in f.impl._level_cache.values())
