"""Simulated seconds per wall second for ICE (40 s at dt = 0.5 ms) with pinv, qp, da.

Run: ``python -m benchmarks.bench_sim [--duration S]``.  One core, noise on,
seed failure at t = 20 s (a diverged run stops early; its simulated time is
what counts).
"""

from __future__ import annotations

import argparse
import time

from sim.scenarios import get_scenario


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--duration", type=float, default=40.0)
    parser.add_argument("--methods", nargs="*", default=["static", "pinv", "qp", "da"])
    args = parser.parse_args()
    run = get_scenario("ice")
    print(f"{'method':<8} {'simulated s':>12} {'wall s':>8} {'x real time':>12}")
    for method in args.methods:
        t0 = time.perf_counter()
        r = run(method=method, failure="seed", duration=args.duration, noise=False, pilot_gain=1.0)
        wall = time.perf_counter() - t0
        print(f"{method:<8} {r.duration:>12.1f} {wall:>8.2f} {r.duration / wall:>12.1f}")


if __name__ == "__main__":
    main()
