"""A real ``dask.distributed`` cluster on loopback, as separate processes (tests, scaling runs).

:func:`loopback_cluster` starts ``dask scheduler`` and ``n_workers`` ``dask worker``
processes from the running interpreter's ``bin`` directory (the same venv), each worker one
process with one thread and no nanny (so the process we start is the process that computes,
and we stop exactly the processes we started, by their pid), waits until every worker has
registered, yields the scheduler address (``tcp://127.0.0.1:<port>``), and always tears the
processes down.  It is what a user does by hand on several machines::

    dask scheduler --host 0.0.0.0 --port 8786
    dask worker tcp://HOST:8786 --nthreads 1        # on each machine, repo installed
    alloc bench quick --scheduler tcp://HOST:8786
"""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from .runner import BLAS_ENV

__all__ = ["loopback_cluster", "free_port"]


def free_port() -> int:
    """A TCP port on 127.0.0.1 free at the time of asking."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _stop(procs: list[subprocess.Popen], grace_s: float = 10.0) -> None:
    for p in procs:
        if p.poll() is None:
            p.terminate()
    deadline = time.monotonic() + grace_s
    for p in procs:
        try:
            p.wait(timeout=max(0.1, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait(timeout=5)


@contextmanager
def loopback_cluster(n_workers: int, *, timeout_s: float = 90.0, log_dir: Path | None = None,
                     pythonpath: str | None = None) -> Iterator[str]:
    """Scheduler plus ``n_workers`` worker processes on 127.0.0.1; yields the scheduler address.

    ``pythonpath`` (default: the current ``sys.path[0]``-style repository root, i.e. the
    ``PYTHONPATH`` of this process) is given to the workers so they import the same code.
    """
    from distributed import Client

    bin_dir = Path(sys.executable).parent
    dask = str(bin_dir / "dask")
    port = free_port()
    address = f"tcp://127.0.0.1:{port}"
    env = {**os.environ, **BLAS_ENV}
    root = str(Path(__file__).resolve().parents[2])
    env["PYTHONPATH"] = pythonpath or os.pathsep.join(p for p in (root, os.environ.get("PYTHONPATH")) if p)
    logs = []

    def log(name: str):
        if log_dir is None:
            return subprocess.DEVNULL
        fh = (Path(log_dir) / f"{name}.log").open("w")
        logs.append(fh)
        return fh

    procs: list[subprocess.Popen] = []
    try:
        procs.append(subprocess.Popen(
            [dask, "scheduler", "--host", "127.0.0.1", "--port", str(port), "--no-dashboard"],
            env=env, stdout=log("scheduler"), stderr=subprocess.STDOUT))
        for i in range(n_workers):
            procs.append(subprocess.Popen(
                [dask, "worker", address, "--host", "127.0.0.1", "--nthreads", "1", "--nworkers", "1",
                 "--no-nanny", "--no-dashboard", "--name", f"w{i}", "--memory-limit", "0"],
                env=env, stdout=log(f"worker{i}"), stderr=subprocess.STDOUT))
        deadline = time.monotonic() + timeout_s
        with Client(address, timeout=timeout_s) as client:
            client.wait_for_workers(n_workers, timeout=max(1.0, deadline - time.monotonic()))
        yield address
    finally:
        _stop(procs)
        for fh in logs:
            fh.close()
