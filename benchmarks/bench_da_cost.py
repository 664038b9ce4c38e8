"""Per-call cost of ``da``'s two backends (facet search, LP) over k = 1..6, m = 8..64.

The table behind ``alloc.methods.direct.facet_is_cheaper`` (a linear cost model fitted to
it: facet ~ a + b C(m, k-1), LP ~ c + d m + e k).  Usage: ``python -m benchmarks.bench_da_cost``.
"""

import time, math, numpy as np, alloc
from alloc.testing import random_problem, random_demands
rng = np.random.default_rng(0)
print("k m facets facet_us lp_us")
for k in range(1, 7):
    for m in (8, 12, 16, 20, 24, 32, 48, 64):
        if m <= k: continue
        nf = math.comb(m, k - 1)
        if nf > 20000: continue
        p = random_problem(rng, k, m, "general", rates=False)
        V = random_demands(rng, p, 300)
        res = []
        for be in ("facet", "daqp"):
            f = alloc.make_allocator(p, "da", backend=be)
            for v in V[:20]: f(v)
            ts = []
            for v in V:
                t0 = time.perf_counter_ns(); f(v); ts.append(time.perf_counter_ns() - t0)
            res.append(np.median(ts) / 1e3)
        print(k, m, nf, round(res[0], 1), round(res[1], 1), flush=True)
