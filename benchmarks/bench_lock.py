"""What the allocator's lock costs on the uncontended C call path (alloc/_engine/_fastcall.c).

The same allocator is wired twice, with its lock (as :class:`alloc.api.Allocator` wires it)
and without (the kernel alone: unsafe when shared, measured here only), and the two are
timed in alternating blocks of calls in one process (which goes first alternates too), so
that both see the same machine state.  Printed: per method the fastest block of each (the least disturbed by other work:
an additive cost shows there undiluted), their difference, and the median of the paired
differences, in nanoseconds per call.

    python -m benchmarks.bench_lock [--pairs 301] [--calls 50]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import alloc
import alloc.vehicles
from alloc import api
from alloc.testing import random_demands


def wire(f: api.Allocator, locked: bool) -> None:
    """``Allocator._wire`` with the lock of both paths set to ``locked``."""
    k, m = f.problem.k, f.problem.m
    if f._W is not None:
        kernel, pre, post = api.fused_affine, (f._W,), (api.EXACT_RTOL, api.MAX_MAGNITUDE)
    else:
        kernel, pre, post = f._packed[0], tuple(f._packed[1]), (f._zm, 0.0)
    kernel = api._entry_point(kernel, (*pre, np.zeros(k), *post))
    rkernel, rpre = (None, ()) if f._packed_rate is None else (f._packed_rate[0], tuple(f._packed_rate[1]))
    if rkernel is not None:
        rkernel = api._entry_point(rkernel, (*rpre, np.zeros(k), np.zeros(m), 1.0))
    f._fast_setup(kernel, pre, post, rkernel, rpre, f.method, api._STATUS, api.Result, k, m, api.MAX_MAGNITUDE,
                  locked, locked)


def per_call(f: api.Allocator, V: list[np.ndarray]) -> float:
    t = time.perf_counter()
    for v in V:
        f(v)
    return (time.perf_counter() - t) / len(V)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pairs", type=int, default=301)
    ap.add_argument("--calls", type=int, default=50)
    args = ap.parse_args()
    if not api.has_c_call_path():
        raise SystemExit("alloc._engine._fastcall is not built: nothing to measure")
    p = alloc.vehicles.problem("ice")
    V = list(random_demands(np.random.default_rng(0), p, args.calls))
    print(f"{'method':<12}{'locked min':>12}{'unlocked min':>14}{'min diff':>10}{'paired median diff':>20}"
          f"  (ns per call; ICE, {args.pairs} pairs x {args.calls} calls)")
    for method in ("qp", "wls", "dynamic", "pinv_scale"):
        f = alloc.make_allocator(p, method)
        per_call(f, V)
        locked, unlocked = [], []
        for i in range(args.pairs):
            for lock in (True, False) if i % 2 else (False, True):  # alternate: the block after a re-wire is slower
                wire(f, lock)
                (locked if lock else unlocked).append(per_call(f, V))
        wire(f, True)
        lo, un = min(locked) * 1e9, min(unlocked) * 1e9
        diff = np.median(np.subtract(locked, unlocked)) * 1e9
        print(f"{method:<12}{lo:>12.0f}{un:>14.0f}{lo - un:>10.1f}{diff:>20.1f}")


if __name__ == "__main__":
    main()
