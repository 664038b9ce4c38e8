"""Simulated seconds per wall second for ICE (40 s at dt = 0.5 ms) per allocation method.

Run: ``python -m benchmarks.bench_sim [--duration S] [--methods static pinv qp da] [--rates 2000 100]``.

``--rates``: flight-control frame rates (Hz); 2000 is the seed rate (allocator every
0.5 ms step), 100 Hz calls the allocator 20x less often (once per 20 steps), with the
default frame-rate rules (boundary layer scaled with T, anti-windup: README, Frame rate).
A diverged run's row times the simulated seconds actually flown.
One core, noise off, pilot gain 1, seed failure at t = 20 s (a diverged run
stops early; its simulated time is what counts).  Each method first runs
0.1 s untimed so numba compilation (cached on disk after the first
process) and allocator set-up are not counted.

Columns: wall seconds of the whole run (set-up included) and the median and
90th percentile of the per-step wall time (allocator call plus the compiled
step, ``step_times`` of :func:`sim.engine.simulate`).  The issue's goal: >= 20x real time with
``pinv`` and >= 5x with ``qp``, i.e. <= 25 us per step with ``pinv``.
"""

from __future__ import annotations

import argparse
import os
import platform
import time

import numpy as np

from sim.scenarios import get_scenario

SETTINGS = dict(failure="seed", noise=False, pilot_gain=1.0)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=40.0)
    parser.add_argument("--methods", nargs="*", default=["static", "pinv", "qp", "da"])
    parser.add_argument("--rates", nargs="*", type=float, default=[2000.0, 100.0])
    args = parser.parse_args()
    run = get_scenario("ice")
    load = ", ".join(f"{x:.2f}" for x in os.getloadavg())
    print(f"ICE {args.duration:g} s, dt = 0.5 ms, {SETTINGS}; python {platform.python_version()}, "
          f"{os.cpu_count()} CPUs, load average {load}")
    print(f"{'frame Hz':>8} {'method':<8} {'simulated s':>12} {'wall s':>8} {'x real time':>12} "
          f"{'us/step median':>15} {'us/step p90':>12} {'median / static':>16}")
    floor: dict[float, float] = {}
    for hz in args.rates:
        for method in args.methods:
            run(method=method, duration=0.1, frame_period=1.0 / hz, **SETTINGS)  # warm-up: compilation, caches
            times: list[np.ndarray] = []
            t0 = time.perf_counter()
            r = run(method=method, duration=args.duration, step_times=times, frame_period=1.0 / hz, **SETTINGS)
            wall = time.perf_counter() - t0
            steps = 1e6 * times[0]
            median = float(np.median(steps))
            floor.setdefault(hz, median)  # the first method of each rate (static by default) is the floor
            print(f"{hz:>8.0f} {method:<8} {r.duration:>12.1f} {wall:>8.2f} {r.duration / wall:>12.1f} "
                  f"{median:>15.1f} {np.percentile(steps, 90):>12.1f} {median / floor[hz]:>16.2f}")


if __name__ == "__main__":
    main()
