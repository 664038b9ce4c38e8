"""AMS benchmarks: build and rebuild times, facet-search latency, batch rate, coverage.

Run: ``.venv/bin/python -m benchmarks.bench_ams [--quick] [--no-coverage]``.
Prints markdown tables.  Every timing is a median (and p99) over repeated calls in this
process, next to floors measured in the same run (machines are noisy: compare within a run).
Random suites are ``B ~ N(0, 1)`` (3 x m), limits +/-1, seed fixed.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import alloc
from alloc import vehicles
from alloc.ams import AttainableSet, coverage


def timed(fn, n: int) -> np.ndarray:
    out = np.empty(n)
    for i in range(n):
        t0 = time.perf_counter()
        fn()
        out[i] = time.perf_counter() - t0
    return out


def us(x: np.ndarray) -> str:
    return f"{np.median(x) * 1e6:.1f} / {np.percentile(x, 99) * 1e6:.1f}"


def ms(x: np.ndarray) -> str:
    return f"{np.median(x) * 1e3:.2f}"


def random_problem(m: int, seed: int = 0) -> alloc.Problem:
    rng = np.random.default_rng(seed)
    return alloc.Problem(rng.standard_normal((3, m)), -np.ones(m), np.ones(m))


def demands(p: alloc.Problem, n: int, seed: int = 1) -> np.ndarray:
    span = np.abs(AttainableSet(p).vertices).max(axis=0)
    return np.random.default_rng(seed).uniform(-1.2, 1.2, size=(n, p.k)) * span


def floors(n: int) -> None:
    B = np.random.default_rng(0).standard_normal((3, 11))
    v = np.ones(11)
    x = np.zeros(3)
    print("## Floors (same run)\n\n| operation | median / p99 us |\n|---|---|")
    print(f"| Python call returning an array | {us(timed(lambda: x, n))} |")
    print(f"| numpy 3x11 matvec `B @ u` | {us(timed(lambda: B @ v, n))} |")
    M = np.random.default_rng(1).standard_normal((90 * 3, 3))
    print(f"| numpy (270x3) @ 3 (ICE facet inverses, one BLAS call) | {us(timed(lambda: M @ x, n))} |\n")


def builds(suites: dict, n: int) -> None:
    print("## AMS build and rebuild after a failure (median ms)\n")
    print("| suite | m | facets | tiles | AttainableSet | da_facet | da_bisect | da_table (res 64) |"
          " rebuild after jam: AttainableSet | da_facet | da_table |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for name, p in suites.items():
        ams = AttainableSet(p)
        failed = p.with_jam(0, float(np.clip(0.5 * p.umax[0], p.umin[0], p.umax[0])))
        row = [name, p.m, ams.n_facets, ams.n_tiles]
        row.append(ms(timed(lambda: AttainableSet(p), n)))
        for meth in ("da_facet", "da_bisect", "da_table"):
            row.append(ms(timed(lambda: alloc.make_allocator(p, meth), max(3, n // 5 if meth == "da_table" else n))))
        row.append(ms(timed(lambda: AttainableSet(failed), n)))
        row.append(ms(timed(lambda: alloc.make_allocator(failed, "da_facet"), n)))
        row.append(ms(timed(lambda: alloc.make_allocator(failed, "da_table"), max(3, n // 5))))
        print("| " + " | ".join(str(c) for c in row) + " |")
    print()


def latency(suites: dict, n: int) -> None:
    print("## Per-call latency, method's solve only (median / p99 us) and through the allocator (median us)\n")
    methods = ["da", "da_facet", "da_bisect", "da_table"]
    print("| suite | m | " + " | ".join(f"{m} solve" for m in methods) + " | " +
          " | ".join(f"{m} call" for m in methods) + " | da_table fallbacks | da_bisect rounds |")
    print("|---|---|" + "---|" * (2 * len(methods) + 2))
    for name, p in suites.items():
        V = demands(p, n)
        solve_cols, call_cols = [], []
        extra = {}
        for meth in methods:
            if meth == "da_table" and p.m > 30:
                solve_cols.append("-")
                call_cols.append("-")
                continue
            a = alloc.make_allocator(p, meth)
            impl, lo, hi = a.impl, p.umin, p.umax
            it = iter(V)
            solve_cols.append(us(timed(lambda: impl.solve(next(it), lo, hi, None), n)))
            it = iter(V)
            call_cols.append(f"{np.median(timed(lambda: a(next(it)), n)) * 1e6:.1f}")
            if meth == "da_table":
                extra["fb"] = f"{impl.fallbacks}/{2 * n}"
            if meth == "da_bisect":
                rounds = []
                for v in V[: min(n, 300)]:
                    impl.solve(v, lo, hi, None)
                    rounds.append(impl.rounds)
                extra["rounds"] = f"{np.mean(rounds):.2f}"
        print(f"| {name} | {p.m} | " + " | ".join(solve_cols) + " | " + " | ".join(call_cols) +
              f" | {extra.get('fb', '-')} | {extra.get('rounds', '-')} |")
    print()


def compiled_vs_reference(n: int) -> None:
    """The compiled searches (alloc/methods/_facet_kernels.py) next to the numpy reference they replaced."""
    print("## Compiled search vs numpy reference, solve only, nominal and rate-limited (median / p99 us)\n")
    print("Rate-limited: ``u_prev = 0``, ``dt = 0.0005`` s.  Allocator: ``make_allocator(p, name)(v)``.\n")
    print("| suite | method | compiled | reference | compiled, rated | reference, rated | allocator call |"
          " allocator call, rated |\n|---|---|---|---|---|---|---|---|")
    for name, p in {"ICE": vehicles.ice(), "HARV": vehicles.harv_latdir()}.items():
        V = demands(p, n)
        lo_r, hi_r = p.effective_bounds(np.zeros(p.m), 0.0005)
        up = np.zeros(p.m)
        for meth in ("da_facet", "da_bisect", "da_table"):
            a = alloc.make_allocator(p, meth)
            impl = a.impl
            cols = []
            for fn in (impl.solve, impl._solve_reference):
                it = iter(V)
                cols.append(us(timed(lambda: fn(next(it), p.umin, p.umax, None), n)))
            for fn in (impl.solve, impl._solve_reference):
                it = iter(V)
                cols.append(us(timed(lambda: fn(next(it), lo_r, hi_r, up), n)))
            it = iter(V)
            cols.append(us(timed(lambda: a(next(it)), n)))
            it = iter(V)
            cols.append(us(timed(lambda: a(next(it), u_prev=up, dt=0.0005), n)))
            print(f"| {name} | {meth} | " + " | ".join(cols) + " |")
    print()


def batch_rate(n: int) -> None:
    print("## Batch direct allocation (allocations per second)\n")
    print("| suite | da_facet batch | pinv batch (floor) | da per call (LP) |\n|---|---|---|---|")
    for name, p in {"ICE": vehicles.ice(), "HARV": vehicles.harv_latdir(), "random m=30": random_problem(30)}.items():
        V = demands(p, n)
        rates = []
        for meth in ("da_facet", "pinv"):
            a = alloc.make_allocator(p, meth)
            t = np.median(timed(lambda: a.batch(V), 3))
            rates.append(f"{n / t:,.0f}")
        a = alloc.make_allocator(p, "da")
        t = timed(lambda: None, 1)
        t0 = time.perf_counter()
        for v in V[:2000]:
            a(v)
        rates.append(f"{2000 / (time.perf_counter() - t0):,.0f}")
        print(f"| {name} | " + " | ".join(rates) + " |")
    print()


def coverage_tables(samples: int) -> None:
    problems = {
        "ICE (up = 0: AMT/SSD parked at their 0 deg limit)": ("ice", vehicles.ice()),
        "ICE (AMT/SSD prefer 30 deg)": ("ice-mid", vehicles.ice_mid()),
        "F-18/HARV lateral-directional": ("harv", vehicles.harv_latdir()),
    }
    print(f"## Coverage of the AMS (Bordignon-Durham), Monte Carlo N = {samples}, seed 0\n")
    for title, (key, p) in problems.items():
        print(f"### {title}\n\n| method | coverage % | +/- 1 s.e. (%) | 95 % CI (Wilson) | estimator |\n|---|---|---|---|---|")
        for meth in alloc.methods():
            opts = {}
            if meth == "daisy":
                opts = {"groups": vehicles.daisy_groups(key)}
            r = coverage(p, meth, samples=samples, seed=0, **opts)
            se = "exact" if r.estimator == "polytope" else f"{100 * r.stderr:.2f}"
            ci = "-" if r.estimator == "polytope" else f"{100 * r.ci95[0]:.2f} - {100 * r.ci95[1]:.2f}"
            print(f"| {meth} | {100 * r.fraction:.2f} | {se} | {ci} | {r.estimator} |")
        print()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--quick", action="store_true", help="fewer repetitions")
    ap.add_argument("--no-coverage", action="store_true")
    ap.add_argument("--samples", type=int, default=20_000)
    args = ap.parse_args()
    n = 300 if args.quick else 2000
    suites = {"ICE": vehicles.ice(), "HARV": vehicles.harv_latdir(), "random": random_problem(11),
              "random ": random_problem(20), "random  ": random_problem(30)}
    big = {"random   ": random_problem(60), "random    ": random_problem(120)}
    floors(n)
    builds(suites, 20 if args.quick else 50)
    latency({**suites, **big}, n)
    compiled_vs_reference(n)
    batch_rate(20_000 if args.quick else 100_000)
    if not args.no_coverage:
        coverage_tables(args.samples)


if __name__ == "__main__":
    main()
