"""Throughput of the sweep engine with 1, 2, 4 worker processes (``alloc bench scaling``).

Runs the same fixed set of short closed-loop runs (ICE, the seed failure, 8 s, a mix of
methods) on a real loopback ``dask.distributed`` cluster (:func:`.cluster.loopback_cluster`)
and on the local process pool, for each worker count, each time into a fresh temporary
folder, and reports runs per second and the speed-up over one worker.  Cluster start-up is
not timed (the sweep starts once every worker has registered); the local pool's start-up is
(spawned interpreters importing numpy and the simulator), as it is in ``alloc bench``.

The runs are CPU-bound, so the speed-up cannot exceed the number of free cores: on a 2-core
machine shared with other jobs, 4 workers time-share 2 cores.
"""

from __future__ import annotations

import os
import tempfile
import time
from collections.abc import Sequence

from .cluster import loopback_cluster
from .runner import run_sweep
from .sweep import STATIC, Spec, closed_spec

__all__ = ["scaling_specs", "measure_scaling"]


def scaling_specs(n_runs: int) -> list[Spec]:
    """``n_runs`` short ICE runs cycling through a few methods and noise seeds."""
    methods = (STATIC, "pinv", "wls", "qp")
    specs = []
    for i in range(n_runs):
        m = methods[i % len(methods)]
        specs.append(closed_spec("ice", "seed", m, told=m != STATIC, seed=100 + i, duration=8.0, failure_time=4.0,
                                 sim={"pilot_gain": 1.0}))
    return specs


def measure_scaling(worker_counts: Sequence[int] = (1, 2, 4), n_runs: int = 24,
                    engines: Sequence[str] = ("dask", "local")) -> list[dict]:
    """Rows ``engine, workers, runs, wall_s, runs_per_s, speedup`` (speed-up over 1 worker, same engine)."""
    specs = scaling_specs(n_runs)
    rows = []
    for engine in engines:
        base = None
        for n in worker_counts:
            with tempfile.TemporaryDirectory(prefix="alloc-scaling-") as tmp:
                if engine == "dask":
                    with loopback_cluster(n) as address:
                        t0 = time.perf_counter()
                        run_sweep(specs, tmp, scheduler=address, progress=False)
                        wall = time.perf_counter() - t0
                else:
                    t0 = time.perf_counter()
                    run_sweep(specs, tmp, workers=n, progress=False)
                    wall = time.perf_counter() - t0
            rate = len(specs) / wall
            base = rate if base is None else base
            rows.append({"engine": engine, "workers": n, "runs": len(specs), "wall_s": wall, "runs_per_s": rate,
                         "speedup": rate / base, "cores": os.cpu_count(),
                         "load_avg_1min": os.getloadavg()[0]})
    return rows
