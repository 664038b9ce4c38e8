"""Telemetry cost: the detector's worst case per sample, and a 100-sample batch through the service.

``--worst``
    per ``(m, N, hop)``: the CPU seconds per sample of :class:`alloc.estimation.FailureDetector`
    on the most expensive stream found -- a vehicle with two identical columns and the first of
    them jammed, so every test alarms and no isolation can decide between the two (the alarm
    stays pending, isolated again at every test, dropped, raised again; both commanded alike) -- next to the cost
    :func:`service.telemetry.batch_seconds` declares.  The ratio ``measured / declared`` must
    stay below 1 for the service's batch price to be a bound.
``--service``
    the wall time of ``POST /v1/vehicles/{id}/telemetry`` with 100 samples (ICE-sized: m = 11,
    k = 6; the simulator's design, 0.1 s samples and a 0.4 s window, but hop 2), healthy samples, through
    a real server process (``service.process.ServiceProcess``, loopback): median, p99 and
    max over ``--requests`` batches; the same batches replayed through the library's detector
    in this process (the floor: what the service adds is parsing, the database and HTTP).

Prints tables; ``--json PATH`` writes the numbers.  Loopback only, stops by itself.
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from typing import Any

import numpy as np

import alloc
from alloc.estimation import FailureDetector
from service.telemetry import DetectorSettings, batch_seconds


def _ambiguous(m: int, k: int, seed: int) -> tuple[alloc.Problem, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    B = rng.normal(size=(k, m))
    B[:, 1] = B[:, 0]  # two effectors no response can tell apart
    p = alloc.Problem(B, -np.full(m, 20.0), np.full(m, 20.0), rate_min=-np.full(m, 60.0), rate_max=np.full(m, 60.0))
    n = 400
    U = rng.uniform(-10, 10, (n, m))
    U[:, 1] = U[:, 0]  # commanded alike: the same signature on both
    actual = U.copy()
    actual[:, 0] = 5.0
    Y = actual @ B.T + rng.normal(0, 0.05, (n, k))
    return p, U, Y


def worst(grid: list[tuple[int, int, int]], samples: int) -> list[dict[str, Any]]:
    rows = []
    for m, N, hop in grid:
        k = 6
        p, U, Y = _ambiguous(m, k, m * 1000 + N)
        dt = 0.01
        settings = DetectorSettings(sample_time=dt, noise_std=[0.05] * k, window=N * dt, hop=hop)
        det = settings.detector(p)
        for i in range(2 * N):  # the buffer full: the steady state
            det.update(U[i], Y[i], time=dt * (i + 1))
        t0 = time.process_time()
        for i in range(2 * N, 2 * N + samples):
            det.update(U[i % len(U)], Y[i % len(U)], time=dt * (i + 1))
        measured = (time.process_time() - t0) / samples
        declared = batch_seconds(settings, m, 1)
        rows.append({"m": m, "window": N, "hop": hop, "alarms": det.alarm_count, "detections": len(det.detections),
                     "measured_s": measured, "declared_s": declared, "ratio": measured / declared})
        print(f"m {m:3d}  N {N:3d}  hop {hop:2d}  alarms {det.alarm_count:4d}  detections {len(det.detections):3d}  "
              f"measured {measured * 1e3:8.3f} ms/sample  declared {declared * 1e3:8.3f}  ratio {measured / declared:5.2f}")
    return rows


def service(requests: int, size: int) -> dict[str, Any]:
    import httpx

    from service.process import ServiceProcess
    from sim.detection import DEFAULT_DESIGN

    rng = np.random.default_rng(20261202)
    m, k = 11, 6
    B = rng.normal(size=(k, m))
    vehicle = {"name": "bench", "B": B.tolist(), "umin": [-30.0] * m, "umax": [30.0] * m}
    # hop 2, not the simulator's 1: at hop 1 the declared worst case of 100 samples at m = 11
    # (3.4 s) is over the default batch budget (2 s) and the batch would be refused
    settings = {"policy": "auto", "sample_time": DEFAULT_DESIGN.sample_time, "noise_std": 0.5,
                "window": DEFAULT_DESIGN.window, "hop": 2}
    n = requests * size
    t = np.arange(1, n + 1) * DEFAULT_DESIGN.sample_time
    U = rng.uniform(-20, 20, (n, m))
    Y = U @ B.T + rng.normal(0, 0.5, (n, k))
    key = "bench-key"
    walls, app_ms = [], []
    with tempfile.TemporaryDirectory() as tmp, ServiceProcess(tmp, api_key=key) as proc, \
            httpx.Client(base_url=proc.url, timeout=60.0, headers={"X-API-Key": key}) as http:
        vid = http.post("/v1/vehicles", json=vehicle).json()["id"]
        assert http.put(f"/v1/vehicles/{vid}/telemetry", json=settings).status_code == 200
        for i in range(requests):
            sl = slice(i * size, (i + 1) * size)
            body = {"t": t[sl].tolist(), "u": U[sl].tolist(), "y": Y[sl].tolist()}
            t0 = time.perf_counter()
            r = http.post(f"/v1/vehicles/{vid}/telemetry", json=body)
            walls.append(time.perf_counter() - t0)
            assert r.status_code == 200, r.text
            app_ms.append(float(r.headers["server-timing"].split("dur=")[1].split(",")[0]))
    problem = alloc.Problem(B, [-30.0] * m, [30.0] * m)
    det = FailureDetector(problem, 0.5, DEFAULT_DESIGN.sample_time, window=DEFAULT_DESIGN.window, hop=2)
    floor = []
    for i in range(requests):
        t0 = time.perf_counter()
        for j in range(i * size, (i + 1) * size):
            det.update(U[j], Y[j], time=float(t[j]))
        floor.append(time.perf_counter() - t0)

    def stats(x: list[float]) -> dict[str, float]:
        a = np.asarray(x) * 1e3
        return {"median_ms": float(np.median(a)), "p99_ms": float(np.percentile(a, 99)), "max_ms": float(a.max())}
    out = {"requests": requests, "samples_per_request": size, "m": m, "k": k, "settings": settings,
           "wall": stats(walls),
           "server_timing_app_ms": {"median_ms": float(np.median(app_ms)), "p99_ms": float(np.percentile(app_ms, 99))},
           "library_floor": stats(floor)}
    print(f"{requests} batches of {size} samples (m = {m}, k = {k}):  wall median {out['wall']['median_ms']:.1f} ms, "
          f"p99 {out['wall']['p99_ms']:.1f} ms, max {out['wall']['max_ms']:.1f} ms;  Server-Timing app median "
          f"{out['server_timing_app_ms']['median_ms']:.1f} ms;  the library's detector alone: median "
          f"{out['library_floor']['median_ms']:.1f} ms, p99 {out['library_floor']['p99_ms']:.1f} ms")
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--worst", action="store_true")
    parser.add_argument("--service", action="store_true")
    parser.add_argument("--samples", type=int, default=200, help="samples timed per --worst row")
    parser.add_argument("--requests", type=int, default=200)
    parser.add_argument("--size", type=int, default=100)
    parser.add_argument("--json", default=None)
    args = parser.parse_args()
    out: dict[str, Any] = {"load_average": open("/proc/loadavg").read().split()[:3]}
    print(f"load average {' '.join(out['load_average'])}")
    if args.worst:
        grid = [(m, N, hop) for m in (4, 11, 64) for N in (4, 16, 32) for hop in (1, max(1, N // 4))]
        out["worst"] = worst(sorted(set(grid)), args.samples)
    if args.service:
        out["service"] = service(args.requests, args.size)
    if args.json:
        with open(args.json, "w") as f:
            json.dump(out, f, indent=1)


if __name__ == "__main__":
    main()
