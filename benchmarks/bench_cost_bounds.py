"""Declared costs against measured ones: every method's build and calls, up to the size caps.

For each cell (k, m) and each method (default options; ``cgi``, ``qp`` and ``lp`` also with one
priority level per axis) a seeded random problem is built and called on random demands (a
fifth of them 20x outside the attainable set, every other call rate-limited).  The table gives
the build's CPU seconds against :meth:`~alloc.registry.Method.build_cost`, the median and the
worst call against :meth:`~alloc.registry.Method.call_cost` (CPU time, ``time.process_time``,
BLAS threads included), and ``ratio`` = declared / worst measured (>= 1: the declaration
holds).  With ``--facets`` it measures the facet-search builds instead, each in a fresh
interpreter: CPU seconds and peak RSS growth against ``build_cost`` and ``build_memory``.
An allocator the bounds refuse (``alloc.registry.CALL_LIMIT_SECONDS``, ``BUILD_LIMIT_*``) is
listed as ``refused`` with its field; a facet search sent to the LP as ``-> lp``.

Usage: ``nice -n 10 python -m benchmarks.bench_cost_bounds [--cells 3x8,6x64,32x512] [--calls 40]``
and ``python -m benchmarks.bench_cost_bounds --facets [--cells 3x64,3x200,6x20]``.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time

import numpy as np

import alloc
from alloc.exceptions import AllocError
from alloc.registry import get_method
from alloc.testing import random_demands, random_problem


def configs(k: int) -> list[tuple[str, dict]]:
    levels = [i % k for i in range(k)]
    extra = [("cgi", {"priorities": levels}), ("qp", {"priorities": levels}), ("lp", {"priorities": levels})]
    return [(name, {}) for name in alloc.methods()] + (extra if k > 1 else [])


def call_times(f: alloc.Allocator, p: alloc.Problem, V: np.ndarray) -> np.ndarray:
    u = p.up.copy()
    f(V[0]), f(V[0], u_prev=u, dt=0.01)
    out = []
    for i, v in enumerate(V):
        t0 = time.process_time()
        r = f(v) if i % 2 == 0 else f(v, u_prev=u, dt=0.01)
        out.append(time.process_time() - t0)
        u = np.asarray(r.u)
    return np.array(out)


def calls(cells: list[tuple[int, int]], n: int, seed: int) -> None:
    print(f"{'k':>2} {'m':>3}  {'method':<16} {'build_s':>8} {'declared':>8}  {'med_ms':>8} {'max_ms':>8} "
          f"{'declared':>9} {'ratio':>6}")
    for k, m in cells:
        for name, options in configs(k):
            rng = np.random.default_rng(seed + 1000 * k + m)
            p = random_problem(rng, k, m, "general", weights=False)
            label = name + (" levels" if options else "")
            cls = get_method(name)
            try:
                t0 = time.process_time()
                f = alloc.make_allocator(p, name, **options)
                build = time.process_time() - t0
            except AllocError as exc:
                print(f"{k:2d} {m:3d}  {label:<16} refused ({exc.field}): declared call {cls.call_cost(p, **options):.3g} s",
                      flush=True)
                continue
            V = random_demands(rng, p, n)
            V[::5] *= 20.0
            t = call_times(f, p, V)
            declared = cls.call_cost(p, **options)
            lp = " -> lp" if getattr(f.impl, "uses_lp", False) else ""
            print(f"{k:2d} {m:3d}  {label:<16} {build:8.3f} {cls.build_cost(p, **options):8.3g}  "
                  f"{1e3 * np.median(t):8.3f} {1e3 * t.max():8.3f} {1e3 * declared:9.3f} {declared / t.max():6.1f}{lp}",
                  flush=True)


_BUILD = """
import json, resource, sys, time, numpy as np, alloc
from alloc.testing import random_problem
name, k, m, options = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), json.loads(sys.argv[4])
rng = np.random.default_rng(0)
p = random_problem(rng, k, m, "general", weights=False, rates=False)
alloc.make_allocator(random_problem(rng, k, k + 1, "general", weights=False), name, **options)
r0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
t0 = time.process_time()
try:
    f = alloc.make_allocator(p, name, **options)
    lp = bool(getattr(f.impl, "uses_lp", False))
except alloc.AllocError as exc:
    print(json.dumps({"refused": str(exc)})); raise SystemExit
t1 = time.process_time()
r1 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
print(json.dumps({"cpu": t1 - t0, "rss": (r1 - r0) * 1024, "lp": lp}))
"""


def facets(cells: list[tuple[int, int]]) -> None:
    print(f"{'k':>2} {'m':>3}  {'method':<10} {'subsets':>8} {'build_s':>8} {'declared':>8} {'rss_MiB':>8} "
          f"{'declared':>8}")
    for k, m in cells:
        p = random_problem(np.random.default_rng(0), k, m, "general", weights=False, rates=False)
        for name in ("da_facet", "da_bisect", "da_table"):
            cls = get_method(name)
            run = subprocess.run([sys.executable, "-c", _BUILD, name, str(k), str(m), "{}"], capture_output=True,
                                 text=True, timeout=900)
            got = json.loads(run.stdout.strip().splitlines()[-1])
            head = f"{k:2d} {m:3d}  {name:<10} {cls.facet_subsets(p, {}):8d}"
            if "refused" in got:
                print(f"{head}  refused: {got['refused']}", flush=True)
                continue
            lp = "  -> lp" if got["lp"] else ""
            print(f"{head} {got['cpu']:8.2f} {cls.build_cost(p):8.3g} {got['rss'] / 2**20:8.0f} "
                  f"{cls.build_memory(p) / 2**20:8.0f}{lp}", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cells", default="")
    ap.add_argument("--calls", type=int, default=40)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--facets", action="store_true", help="the facet-search builds (time and memory)")
    args = ap.parse_args()
    default = "3x64,3x141,3x200,6x20,6x26" if args.facets else "3x8,6x64,16x128,32x64,6x512,32x512"
    cells = [tuple(int(x) for x in c.split("x")) for c in (args.cells or default).split(",")]
    facets(cells) if args.facets else calls(cells, args.calls, args.seed)


if __name__ == "__main__":
    main()
