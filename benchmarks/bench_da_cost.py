"""Per-call cost of ``da``'s two backends (facet search, LP) and of ``backend="auto"``.

Issue 11's goal: ``da``'s backend chosen by measured cost per call, never more than 1.5x the
cheaper backend on k = 1..6, m up to 64.  For every cell of the grid (k = 1..6, m = 4..64,
seeded ``general`` random problems, half the demands unattainable) the three allocators
(``backend="facet"``, ``backend="daqp"`` and ``backend="auto"``) are built and called on the
same demands, interleaved by blocks (the machine is shared: only ratios within one run mean
anything); the table gives the median per call, ``ratio`` = the auto allocator's median /
min(facet, LP), and ``choice`` = the median of the backend auto chose / min(facet, LP) (the
model's decision without the timing noise of a third allocator).

Cells with more facet generator subsets C(m, k-1) than :data:`FACET_LIMIT` are not enumerated
(the build would take seconds to minutes and hundreds of MiB); there the facet search's cost
is bounded below by the fitted model :func:`alloc.methods.direct.facet_call_us` (the sequential
search tests every tile, so its cost grows with C(m, k-1)) and printed in brackets.

The LP backend timed is the one ``auto`` uses, the compiled ray simplex (``backend="simplex"``).

``--large``: ``da`` at k = 4 and m = 6 .. 192 (``auto``, its ray simplex, the DAQP model it
replaced) and the cascaded methods ``cgi`` and ``daisy``, each as the median us per call and as a
ratio to a floor measured in the same run (``pinv``, one compiled affine call), with the
machine's load before and after.

Usage: ``nice -n 10 python -m benchmarks.bench_da_cost [--calls 300] [--seed 0] [--large]``.
"""

from __future__ import annotations

import argparse
import math
import os
import time

import numpy as np

import alloc
from alloc.methods.direct import facet_call_us, facet_is_cheaper, lp_call_us
from alloc.methods.facet_search import FACET_LIMIT
from alloc.testing import random_demands, random_problem

GOAL = 1.5
MS = (4, 6, 8, 12, 16, 20, 24, 32, 48, 64)


def _medians(allocators: list[alloc.Allocator], V: np.ndarray, rng: np.random.Generator,
             block: int = 10) -> list[float]:
    """Median us per call of each allocator on the rows of ``V``, interleaved by blocks of
    ``block`` consecutive calls in a random order per block: an allocator is timed the way a
    controller calls it (repeatedly, its tables warm), while drift on the shared machine hits
    all of them alike.  Per-call interleaving would charge the call after a 10 ms facet search
    over 15,504 facets with that search's cache misses."""
    for f in allocators:
        for v in V[:20]:
            f(v)
    times: list[list[int]] = [[] for _ in allocators]
    for s in range(0, len(V), block):
        for q in rng.permutation(len(allocators)):
            f, ts = allocators[q], times[q]
            for v in V[s:s + block]:
                t0 = time.perf_counter_ns()
                f(v)
                ts.append(time.perf_counter_ns() - t0)
    return [float(np.median(ts)) / 1e3 for ts in times]


LARGE_MS = (6, 12, 24, 48, 96, 192)
LARGE = (("pinv", {}), ("da", {}), ("da", {"backend": "simplex"}), ("da", {"backend": "daqp"}), ("cgi", {}),
         ("daisy", {"groups": "halves"}))


def large(calls: int, seed: int) -> None:
    """``da`` and the cascaded methods at k = 4, m = 6 .. 192 (see the module docstring)."""
    rng = np.random.default_rng(seed)
    print("load average before: {:.2f} {:.2f} {:.2f}".format(*os.getloadavg()))
    labels = [name + ("" if not o or "groups" in o else f"[{o['backend']}]") for name, o in LARGE]
    print("k  m   " + "  ".join(f"{x:>14}" for x in labels) + "   (median us per call; x floor = pinv)")
    for m in LARGE_MS:
        p = random_problem(rng, 4, m, "general", rates=False)
        V = random_demands(rng, p, calls)
        allocators = []
        for name, options in LARGE:
            if "groups" in options:
                options = {"groups": [list(range(m // 2)), list(range(m // 2, m))]}
            allocators.append(alloc.make_allocator(p, name, **options))
        us = _medians(allocators, V, rng)
        cells = [f"{u:7.1f} {u / us[0]:5.1f}x" for u in us]
        print(f"4  {m:3d} " + "  ".join(cells), flush=True)
    print("load average after: {:.2f} {:.2f} {:.2f}".format(*os.getloadavg()))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--calls", type=int, default=300)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--large", action="store_true", help="da and the cascades at k = 4, m = 6 .. 192")
    args = ap.parse_args()
    if args.large:
        large(args.calls, args.seed)
        return
    rng = np.random.default_rng(args.seed)
    print("k  m   facets  facet_us  lp_us   auto  auto_us  ratio  choice  model_facet  model_lp")
    worst = worst_choice = 0.0
    for k in range(1, 7):
        for m in MS:
            if m < k:
                continue
            nf = math.comb(m, k - 1)
            p = random_problem(rng, k, m, "general", rates=False)
            V = random_demands(rng, p, args.calls)
            auto = "facet" if facet_is_cheaper(m, k) else "lp"
            if nf <= FACET_LIMIT:
                backends = ("facet", "simplex", "auto")
                facet_us, lp_us, auto_us = _medians([alloc.make_allocator(p, "da", backend=b) for b in backends], V, rng)
                facet_txt = f"{facet_us:8.1f}"
            else:
                lp_us, auto_us = _medians([alloc.make_allocator(p, "da", backend=b) for b in ("simplex", "auto")], V, rng)
                facet_us = facet_call_us(m, k)
                facet_txt = f"[{facet_us:6.0f}]"
            cheaper = min(facet_us, lp_us)
            ratio = auto_us / cheaper  # the auto allocator itself, timed in the same run
            choice = (facet_us if auto == "facet" else lp_us) / cheaper  # the backend it chose
            worst, worst_choice = max(worst, ratio), max(worst_choice, choice)
            print(f"{k}  {m:2d} {nf:8d}  {facet_txt}  {lp_us:6.1f}  {auto:>5}  {auto_us:6.1f}  {ratio:5.2f}  {choice:6.2f}"
                  f"  {facet_call_us(m, k):11.1f}  {lp_call_us(m, k):8.1f}", flush=True)
    for name, value in (("auto", worst), ("chosen backend", worst_choice)):
        print(f"worst {name} / cheaper backend: {value:.2f} (goal <= {GOAL}: {'met' if value <= GOAL else 'NOT met'})")


if __name__ == "__main__":
    main()
