"""The JSBSim F-22 plant: real-time factor per JSBSim step, and the closed loop through failures.

``python -m benchmarks.bench_jsbsim``: simulated seconds per wall-clock second (median of
``--repeats``) of 20 s flights: the plant with the trim command held (plant alone: JSBSim and the
actuator model), and the closed loop of :mod:`sim.plants.jsbsim_loop` (controller, qp allocator,
plant) through its default doublets.  The loop's frame is one JSBSim step.  Then one 20 s flight
per failure (at 5 s), told and blind: whether it diverged and when, peak alpha deviation and RMS
pitch-rate error (command minus measured) after the failure; with the observers fed the
allocator's command (the seed's loop) and, for the stabilator failures, the measured positions.
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from sim.plants.jsbsim import JSBSimPlant
from sim.plants.jsbsim_loop import fly

#: (label, failure) flown told and blind; positions are deviations from trim, deg
FAILURES = (
    ("none", None),
    ("stab_l jammed at trim", ("stab_l", "jam", {"position": 0.0})),
    ("stab_l jammed where it is", ("stab_l", "jam", {})),
    ("stab_r hard-over (+28 deg)", ("stab_r", "hardover", {})),
    ("tvc at 30 % effectiveness", ("tvc", "effectiveness", {"fraction": 0.3})),
    ("stab_l rate 10 deg/s", ("stab_l", "rate_limits", {"rate_min": -10.0, "rate_max": 10.0})),
    ("aileron jammed at +5 deg", ("aileron", "jam", {"position": 5.0})),
)


def plant_alone(h: float, seconds: float) -> float:
    plant = JSBSimPlant(jsbsim_dt=h)
    zero = np.zeros(len(plant.effectors))
    n = int(round(seconds / h))
    start = time.perf_counter()
    for _ in range(n):
        plant.step(zero, h)
    return seconds / (time.perf_counter() - start)


def closed_loop(h: float, seconds: float) -> tuple[float, bool]:
    f = fly(duration=seconds, plant=JSBSimPlant(jsbsim_dt=h))
    return f.real_time_factor, f.diverged


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=20.0)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    fly(duration=0.1)  # compile / load the allocator's kernels outside the timing
    print(f"{'JSBSim step':>12s} {'plant alone':>12s} {'closed loop':>12s}  diverged")
    for hz in (120, 240, 480):
        h = 1.0 / hz
        alone = statistics.median(plant_alone(h, args.seconds) for _ in range(args.repeats))
        loops = [closed_loop(h, args.seconds) for _ in range(args.repeats)]
        print(f"{'1/' + str(hz) + ' s':>12s} {alone:11.0f}x {statistics.median(r for r, _ in loops):11.1f}x  "
              f"{any(d for _, d in loops)}")
    print()
    print("| failure at 5 s | allocator | observers fed | diverged at | peak alpha (deg) "
          "| RMS q error after 5 s (deg/s) |")
    print("|---|---|---|---|---|---|")
    for label, failure in FAILURES:
        inputs = ("command", "position") if failure is None or failure[0].startswith("stab") else ("command",)
        for observer_input in inputs:
            for told in ((True,) if failure is None else (True, False)):
                f = fly(duration=args.seconds, failure=failure, told=told, observer_input=observer_input)
                when = f"{f.t[-1]:.2f} s" if f.diverged else "no"
                print(f"| {label} | {'told' if told else 'blind'} | {observer_input} | {when} | "
                      f"{f.peak('alpha'):.2f} | {f.rms_error('q', after=5.0):.3f} |")


if __name__ == "__main__":
    main()
