"""Scheduled effectiveness: the cost of ``B(x)`` per call against rebuilding the vehicle at ``x``.

A PX4 tiltrotor VTOL as PX4 ships it (``tests/alloc/data/px4_airframes/13100_generic_vtol_tiltrotor``)
is imported once with its ``[schedule]`` (tilt, airspeed).  Along a transition of ``--steps`` points
(tilt 90 -> 0 deg while the airspeed goes 0 -> ``--cruise``; PX4's tilt is 0 in hover, so this is
the back transition's path, the same set of points as the forward one), each point is evaluated

* by the schedule: ``ScheduledEffectiveness.evaluate`` (a few sines and one matrix-vector product
  into a buffer it owns), and
* by a rebuild: ``vehicle_from_params(params, at=...)``, the importer's path (every column from the
  geometry, a validated vehicle document), and by ``problem_at``, the schedule plus a new
  validated ``Problem`` (what a caller needing a Problem per step pays);

and the largest difference between the schedule's ``B`` and the rebuild's is printed with the
per-call medians (``--repeat`` rounds over the path, ``time.perf_counter_ns``).

    python -m benchmarks.bench_schedule --steps 50 --repeat 5
"""

from __future__ import annotations

import argparse
import statistics
import time
import warnings
from pathlib import Path

import numpy as np

from alloc.exceptions import SkippedLinesWarning
from alloc.importers.px4 import read_params, vehicle_from_params

AIRFRAME = Path(__file__).parents[1] / "tests" / "alloc" / "data" / "px4_airframes" / "13100_generic_vtol_tiltrotor"


def transition(steps: int, cruise: float) -> list[dict[str, float]]:
    """Tilt 90 -> 0 deg while the airspeed goes 0 -> cruise, ``steps`` points."""
    return [{"tilt": float(t), "airspeed": float(v)}
            for t, v in zip(np.linspace(90.0, 0.0, steps), np.linspace(0.0, cruise, steps))]


def per_call_us(call, points: list[dict[str, float]], repeat: int) -> float:
    """Median over ``repeat`` rounds of the mean time per point, in microseconds."""
    rounds = []
    for _ in range(repeat):
        start = time.perf_counter_ns()
        for x in points:
            call(x)
        rounds.append((time.perf_counter_ns() - start) / len(points) / 1e3)
    return statistics.median(rounds)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--steps", type=int, default=50)
    parser.add_argument("--cruise", type=float, default=18.0, help="airspeed at the end of the path, m/s")
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args(argv)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SkippedLinesWarning)
        params = read_params(AIRFRAME)
    points = transition(args.steps, args.cruise)
    print(f"PX4 13100_generic_vtol_tiltrotor, {args.steps} points (tilt 90 -> 0 deg, airspeed 0 -> {args.cruise:g} m/s),"
          f" median of {args.repeat} rounds")
    print(f"{'normalize':10} {'schedule us':>12} {'problem_at us':>14} {'rebuild us':>11} {'ratio':>7} "
          f"{'max |B - rebuild|':>18}")
    for normalize in ("none", "px4"):
        vehicle = vehicle_from_params(params, normalize=normalize)
        scheduled = vehicle.scheduled()
        worst = max(float(np.abs(scheduled.evaluate(x) - vehicle_from_params(params, normalize=normalize, at=x)
                                 .problem().B).max()) for x in points)
        t_schedule = per_call_us(scheduled.evaluate, points, args.repeat)
        t_problem = per_call_us(vehicle.problem_at, points, args.repeat)
        t_rebuild = per_call_us(lambda x: vehicle_from_params(params, normalize=normalize, at=x), points, args.repeat)
        print(f"{normalize:10} {t_schedule:12.1f} {t_problem:14.1f} {t_rebuild:11.1f} {t_rebuild / t_schedule:7.0f} "
              f"{worst:18.2e}")


if __name__ == "__main__":
    main()
