"""Allocation latency on ICE (3 x 11), warm, through the make_allocator path.

Prints, per method, the median and p99 microseconds per call and the ratio to a floor
measured in the same run (a precomputed 11 x 3 numpy matrix-vector product), with and
without rate limits; then allocate_batch throughput (allocations per second) for N
demands.  Usage::

    python -m benchmarks.bench_alloc [--calls 5000] [--batch 100000] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time

import numpy as np

import alloc
from alloc.vehicles import ice


def timed(fn, V, n: int) -> np.ndarray:
    ts = np.empty(n)
    clock = time.perf_counter_ns
    for i in range(n):
        v = V[i % len(V)]
        t0 = clock()
        fn(v)
        ts[i] = clock() - t0
    return ts / 1e3


def demands(p: alloc.Problem, n: int, seed: int = 0) -> np.ndarray:
    """Half attainable (B u, u admissible), half scaled past the AMS, as flight sees both."""
    rng = np.random.default_rng(seed)
    V = rng.uniform(p.umin, p.umax, size=(n, p.m)) @ p.B.T
    V[n // 2:] *= 2.5
    return V


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--calls", type=int, default=5000, help="timed calls per method")
    ap.add_argument("--batch", type=int, default=100_000, help="N for allocate_batch throughput")
    ap.add_argument("--json", help="write the tables as JSON here")
    args = ap.parse_args(argv)

    p = ice()
    V = demands(p, 2000)
    P = np.ascontiguousarray(alloc.make_allocator(p, "pinv").impl.P)
    floor = timed(lambda v: P @ v, V, args.calls)
    f_med = float(np.median(floor))
    print(f"# ICE 3 x 11, {args.calls} warm calls per method, {platform.processor() or platform.machine()}, "
          f"{os.cpu_count()} cores, numpy {np.__version__}")
    print(f"floor (P @ v, 11 x 3): median {f_med:.2f} us, p99 {np.percentile(floor, 99):.2f} us\n")
    print("(the floor is re-measured just before each method: this machine drifts between quiet")
    print(" and noisy states within a run, and a ratio to a distant floor would mislead)\n")
    print(f"{'method':<11} {'median us':>10} {'p99 us':>9} {'floor us':>9} {'x floor':>8} | "
          f"{'rate-limited median':>20} {'p99':>8} | fallbacks")
    rows = []
    u_prev = np.zeros(p.m)
    for name in alloc.methods():
        allocate = alloc.make_allocator(p, name)
        for v in V[:50]:
            allocate(v)
            allocate(v, u_prev=u_prev, dt=0.0005)
        near = float(np.median(timed(lambda v: P @ v, V, args.calls)))
        plain = timed(allocate, V, args.calls)
        rated = timed(lambda v: allocate(v, u_prev=u_prev, dt=0.0005), V, args.calls)
        fallbacks = sum(allocate(v).status is alloc.Status.FALLBACK for v in V[:1000])
        row = dict(method=name, median_us=float(np.median(plain)), p99_us=float(np.percentile(plain, 99)),
                   floor_us=near, ratio=float(np.median(plain)) / near, rate_median_us=float(np.median(rated)),
                   rate_p99_us=float(np.percentile(rated, 99)), fallbacks_per_1000=int(fallbacks))
        rows.append(row)
        print(f"{name:<11} {row['median_us']:>10.1f} {row['p99_us']:>9.1f} {near:>9.2f} {row['ratio']:>8.1f} | "
              f"{row['rate_median_us']:>20.1f} {row['rate_p99_us']:>8.1f} | {fallbacks}")

    print(f"\nallocate_batch, N = {args.batch}")
    print(f"{'method':<11} {'seconds':>8} {'allocations/s':>14}")
    VB = demands(p, args.batch, seed=1)
    batch_rows = []
    for name in ("pinv", "pinv_clip", "pinv_scale", "ganging", "da", "da_facet"):
        if name not in alloc.methods():
            continue
        n = args.batch
        t0 = time.perf_counter()
        alloc.allocate_batch(p, VB[:n], name)
        dt = time.perf_counter() - t0
        batch_rows.append(dict(method=name, n=n, seconds=dt, per_second=n / dt))
        print(f"{name:<11} {dt:>8.3f} {n / dt:>14,.0f}" + ("  (N = %d, one call each)" % n if n != args.batch else ""))
    out = dict(floor_median_us=f_med, calls=rows, batch=batch_rows)
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(out, fh, indent=2)
    return out


if __name__ == "__main__":
    main()
