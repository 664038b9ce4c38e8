"""Per-call allocator latency, measured apart from the sweep: one process, nothing else of ours running.

Timing inside the sweep's worker processes measures the other workers as much as the
allocator (an ``lp`` p99 of about 4 ms there against 80 µs alone), so the report's latency
columns come from this dedicated pass, run by ``alloc bench`` after the pool has shut down.

For each problem and method: warm-up calls, then ``calls`` timed calls of the full allocator
(validation included) cycling through seeded demands inside and outside the AMS; median and
99th percentile.  A *floor* is measured in the same pass, interleaved with the methods: a
Python call doing one ``B @ u`` matvec on the same problem, so every latency is also given as a
ratio to a cost measured under the same machine load.
"""

from __future__ import annotations

import csv
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np

import alloc
from alloc.ams import AttainableSet, sample_ams

from .openloop import method_options, problem_by_name, unattainable_demands

__all__ = ["measure_latency", "write_timings", "WARMUP", "TIMINGS_CSV"]

WARMUP = 20
TIMINGS_CSV = "latency.csv"
FIELDS = ("problem", "method", "calls", "median_us", "p99_us", "floor_median_us", "median_over_floor")


def _time_calls(fn, V: np.ndarray, calls: int) -> np.ndarray:
    clock = time.perf_counter_ns
    times = np.empty(calls)
    for i in range(calls):
        v = V[i % len(V)]
        t0 = clock()
        fn(v)
        times[i] = clock() - t0
    return times / 1e3


def measure_latency(problems: Sequence[str], methods: Sequence[str], *, calls: int = 2000,
                    demands: int = 200, seed: int = 0) -> list[dict]:
    """Rows ``problem, method, calls, median_us, p99_us, floor_median_us, median_over_floor``."""
    rows = []
    for name in problems:
        problem = problem_by_name(name)
        ams = AttainableSet(problem)
        rng = np.random.default_rng([seed, len(name)])
        u0 = np.clip(problem.up, problem.umin, problem.umax)
        V = np.vstack([sample_ams(ams, demands, rng), unattainable_demands(ams, u0, demands, rng)])
        B = problem.B

        def floor(v: np.ndarray, B: np.ndarray = B, u: np.ndarray = u0) -> np.ndarray:
            return B @ u

        for method in methods:
            allocate = alloc.make_allocator(problem, method, **method_options(name, method))
            for v in V[:WARMUP]:
                allocate(v)
                floor(v)
            t_method = _time_calls(allocate, V, calls)
            t_floor = _time_calls(floor, V, calls)
            med, fl = float(np.median(t_method)), float(np.median(t_floor))
            rows.append({"problem": name, "method": method, "calls": calls, "median_us": med,
                         "p99_us": float(np.percentile(t_method, 99)), "floor_median_us": fl,
                         "median_over_floor": med / fl})
    return rows


def write_timings(out: Path | str, rows: Sequence[dict]) -> Path:
    """Write the rows to ``out/latency.csv``."""
    path = Path(out) / TIMINGS_CSV
    with path.open("w", newline="") as fh:
        w = csv.DictWriter(fh, FIELDS, lineterminator="\n")
        w.writeheader()
        w.writerows(rows)
    return path
