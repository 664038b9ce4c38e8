"""Scheduled effectiveness through the service: what an allocation at a request's ``at`` costs.

PX4's tiltrotor VTOL as PX4 ships it (``tests/alloc/data/px4_airframes/13100_generic_vtol_tiltrotor``)
is posted as a PX4 airframe file; along a transition of ``--steps`` points (tilt 90 -> 0 deg while
the airspeed goes 0 -> 18 m/s) one demand is allocated per point, ``--repeat`` rounds, per method:

* ``nominal``: no ``at``, the vehicle's stored ``B`` (the allocator cached after the first call);
* ``at``: ``"at": {"tilt": ..., "airspeed": ...}``, a build per request (no library method
  follows a new ``B`` without one), priced and built on a build thread;
* ``at held``: the same ``at`` every request (a vehicle holding its tilt): the allocator kept for
  the last ``at`` answers;

and, in this process without the service, the parts of an ``at`` request: the problem at ``at``
(:func:`service.schedule.at_values` and :func:`~service.schedule.problem_at_values`: the values
checked, ``B(x)``, a validated Problem, the health), that and the build
(:func:`alloc.make_allocator`) and the call.  Medians in microseconds per request, in-process
(``TestClient``: the ASGI app without sockets, so HTTP framing is not counted).

    python -m benchmarks.bench_service_schedule --steps 50 --repeat 5
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np
from fastapi.testclient import TestClient

import alloc
from service.config import Settings
from service.main import create_app
from service.schedule import at_values, problem_at_values

AIRFRAME = Path(__file__).parents[1] / "tests" / "alloc" / "data" / "px4_airframes" / "13100_generic_vtol_tiltrotor"
V = [0.1, -0.05, 0.02, -5.0]


def transition(steps: int) -> list[dict[str, float]]:
    return [{"tilt": float(t), "airspeed": float(v)}
            for t, v in zip(np.linspace(90.0, 0.0, steps), np.linspace(0.0, 18.0, steps))]


def medians_us(calls: list, points: list, repeat: int) -> list[float]:
    """Per call, the median over ``repeat`` rounds of the mean time per point, microseconds; the
    calls take turns within each round, so a change of the machine's load hits them alike."""
    rounds: list[list[float]] = [[] for _ in calls]
    for _ in range(repeat):
        for call, times in zip(calls, rounds):
            start = time.perf_counter_ns()
            for x in points:
                call(x)
            times.append((time.perf_counter_ns() - start) / len(points) / 1e3)
    return [statistics.median(times) for times in rounds]


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--steps", type=int, default=50)
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--methods", default="pinv,qp,wls")
    args = parser.parse_args(argv)
    points = transition(args.steps)
    with tempfile.TemporaryDirectory() as data, TestClient(create_app(Settings(data_dir=Path(data)))) as client:
        created = client.post("/v1/vehicles", content=AIRFRAME.read_bytes(), headers={"content-type": "text/plain"},
                              params={"import": "px4-airframe"})
        vehicle_id = created.json()["id"]
        state = client.app.state.store.get(vehicle_id)
        evaluator = client.app.state.pool.schedules.of(state)

        def problem_at(x):
            return problem_at_values(state, evaluator, at_values(evaluator, x))
        url = f"/v1/vehicles/{vehicle_id}/allocate"
        print(f"PX4 13100_generic_vtol_tiltrotor (k = {state.problem.k}, m = {state.problem.m}), {args.steps} points "
              f"(tilt 90 -> 0 deg, airspeed 0 -> 18 m/s), median of {args.repeat} rounds, us per request")
        print(f"{'method':8} {'nominal':>9} {'at':>9} {'at held':>9} {'problem_at':>11} {'+ build':>9} {'call':>9}")
        for method in args.methods.split(","):
            def nominal(x, method=method):
                assert client.post(url, json={"v": V, "method": method}).status_code == 200

            def scheduled(x, method=method):
                assert client.post(url, json={"v": V, "method": method, "at": x}).status_code == 200

            def held(x, method=method):
                assert client.post(url, json={"v": V, "method": method, "at": points[0]}).status_code == 200

            def built(x, method=method):
                return alloc.make_allocator(problem_at(x), method)

            nominal(points[0])  # the cached allocator, built once
            scheduled(points[0])
            allocator = built(points[0])
            times = medians_us([nominal, scheduled, held, lambda x: problem_at(x), built,
                                lambda x, a=allocator: a(V)], points, args.repeat)
            print(f"{method:8} {times[0]:9.0f} {times[1]:9.0f} {times[2]:9.0f} {times[3]:11.1f} {times[4]:9.0f} "
                  f"{times[5]:9.1f}")

if __name__ == "__main__":
    main()
