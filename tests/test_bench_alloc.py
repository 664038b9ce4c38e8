"""benchmarks/bench_alloc.py: its tail tables and the cache behaviour the README's long-lived row rests on."""

from __future__ import annotations

import numpy as np

import alloc
from alloc._active_set import _MISC
from alloc.vehicles import ice
from benchmarks.bench_alloc import markdown, random_sequence, tail_rows


def _misses(f, V) -> int:
    ivecs = f._packed[1][2]  # row _MISC, column 0: the next free cache slot
    before = int(ivecs[_MISC, 0])
    for v in V:
        f(v)
    return int(ivecs[_MISC, 0]) - before


def test_long_lived_allocator_meets_few_new_free_sets():
    """The README judges the warm p99 on an allocator that has met 10,000 earlier demands:
    its cache then holds (almost) every free set new random ICE demands reach, and a fresh
    one does not."""
    p = ice()
    V = random_sequence(p, 3000)
    for name in ("qp", "wls"):
        fresh = alloc.make_allocator(p, name)
        first = _misses(fresh, V)
        lived = alloc.make_allocator(p, name)
        _misses(lived, random_sequence(p, 10000, seed=1))
        again = _misses(lived, V)
        assert first > 100, (name, first)  # a fresh allocator factorises hundreds on this pass
        assert again <= 0.01 * len(V), (name, again)


def test_tail_rows_prior_and_markdown():
    p = ice()
    V = random_sequence(p, 200)
    first = tail_rows(p, V, names=("wls",), runs=2)
    lived = tail_rows(p, V, names=("wls",), runs=2, prior=random_sequence(p, 3000, seed=1))
    assert first[0]["prior"] == 0 and lived[0]["prior"] == 3000
    assert lived[0]["new_sets_total"] < first[0]["new_sets_total"]
    for r in first + lived:
        assert np.isfinite([r["median_us"], r["p99_us"], r["ratio_min"], r["ratio_runs"]]).all()
    out = {"latency": {}, "tail": first, "tail_long_lived": lived,
           "batch": [dict(method="wls", threads=1, batch_s=1.0, loop_s=3.0, speedup=3.0, n=10)],
           "scaling": [], "goals": [dict(goal="wls p99 <= 3x median", value=2.0, limit=3.0, met=True)]}
    md = markdown(out)
    assert "First-pass tail" in md and "first met 3,000 other random demands" in md and "2 fresh allocators" in md and "1.5 s of calls" in md
