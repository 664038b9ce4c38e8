"""Start-up independent of load: ``--workers N`` comes up on a CPU-loaded machine with no
worker killed while it starts, and readiness is separate from liveness.

The load is made by the test: CPU-burning processes (one per core and worker, at normal
priority) for the whole start-up.  The supervisor (``service.supervisor``) logs
``Child process [pid] ready after X s`` for each worker and ``... starting a new one`` for
each restart; uvicorn logs ``Child process [pid] died`` for one it replaced.
"""

from __future__ import annotations

import contextlib
import multiprocessing
import os
import re
import subprocess
import sys
import threading
import time
from pathlib import Path

import httpx
import pytest
from fastapi.testclient import TestClient

from service.config import Settings
from service.main import create_app
from service.process import ServiceProcess


def _burn(seconds: float) -> None:
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        pass


def test_ready_is_separate_from_health(tmp_path):
    app = create_app(Settings(data_dir=tmp_path, warmup=False))
    with TestClient(app) as c:
        r = c.get("/v1/ready")
        assert r.status_code == 200 and r.json()["status"] == "ready" and r.json()["startup_seconds"] >= 0
    r = TestClient(app).get("/v1/ready")  # the lifespan is over: stopped, not ready (health would still answer)
    assert r.status_code == 503 and r.headers["content-type"].startswith("application/problem+json")


ROOT = Path(__file__).resolve().parents[2]
#: ``(a|aa)+b`` against n a's: the regex engine backtracks in C without releasing the GIL
_GIL_PATTERN = re.compile(r"(a|aa)+b")


def _gil_hold_length(seconds: float) -> int:
    """The n for which one failing match holds the GIL about ``seconds`` (calibrated here)."""
    n = 16
    while True:
        t0 = time.perf_counter()
        _GIL_PATTERN.fullmatch("a" * n)
        if time.perf_counter() - t0 > seconds / 8:
            return n + 4  # each further a multiplies the time by about 1.6
        n += 1


async def gil_holding_app(scope, receive, send):
    """Start-up holds the GIL for seconds (as a worker loading kernels on a loaded machine)."""
    if scope["type"] == "lifespan":
        while True:
            message = await receive()
            if message["type"] == "lifespan.startup":
                _GIL_PATTERN.fullmatch("a" * int(os.environ["GIL_HOLD_N"]))
                await send({"type": "lifespan.startup.complete"})
            else:
                await send({"type": "lifespan.shutdown.complete"})
                return
    await send({"type": "http.response.start", "status": 200, "headers": []})
    await send({"type": "http.response.body", "body": b"ok"})


_SUPERVISE = """
import sys, threading, uvicorn
from uvicorn.supervisors.multiprocess import Multiprocess
from service.supervisor import ReadinessSupervisor
config = uvicorn.Config("test_workers:gil_holding_app", host="127.0.0.1", port=0, workers=2,
                        timeout_worker_healthcheck=1, log_level="info")
sockets = [config.bind_socket()]
supervisor = ReadinessSupervisor(config, sockets, 60.0) if sys.argv[1] == "ours" else Multiprocess(config, sockets)
threading.Timer(float(sys.argv[2]), supervisor.should_exit.set).start()
# the test says when it has seen enough (a line on stdin); the timer is the cap
threading.Thread(target=lambda: (sys.stdin.readline(), supervisor.should_exit.set()), daemon=True).start()
supervisor.run()
"""
#: the supervised run's cap, and how long "ours" is watched after both workers are ready
#: (three health-check periods: a kill after readiness would show in it)
_CAP_S, _AFTER_READY_S = 15.0, 3.0
_KILL = re.compile(r"died|starting a new one")


def _supervise(which: str, env: dict) -> str:
    """Run the supervisor ``which`` until it has answered the question (or the cap); its log.

    uvicorn's: until its first kill.  Ours: until both workers are up, then ``_AFTER_READY_S``.
    """
    proc = subprocess.Popen([sys.executable, "-c", _SUPERVISE, which, str(_CAP_S)], cwd=ROOT, env=env,
                            stdin=subprocess.PIPE, stderr=subprocess.PIPE, text=True, errors="replace")
    lines: list[str] = []
    reader = threading.Thread(target=lambda: lines.extend(iter(proc.stderr.readline, "")), daemon=True)
    reader.start()
    ready_at = None
    try:
        while proc.poll() is None:
            log = "".join(lines)
            if which == "uvicorn" and _KILL.search(log):
                break
            if which == "ours" and ready_at is None and log.count("Application startup complete") >= 2:
                ready_at = time.monotonic()
            if ready_at is not None and time.monotonic() - ready_at >= _AFTER_READY_S:
                break
            time.sleep(0.1)
        with contextlib.suppress(BrokenPipeError):  # it may have reached its cap meanwhile
            proc.stdin.write("stop\n")
            proc.stdin.close()
        proc.wait(timeout=180)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    reader.join(timeout=30)
    return "".join(lines)


def test_starting_workers_are_not_health_checked_until_ready():
    """Workers whose start-up holds the GIL longer than the health check's 1 s: uvicorn's own
    supervisor kills them (watched until the first kill); ours waits for them (0 restarts, both
    ready, and none in the ``_AFTER_READY_S`` after)."""
    n = _gil_hold_length(3.0)
    env = {**os.environ, "GIL_HOLD_N": str(n), "PYTHONPATH": f"{Path(__file__).resolve().parent}:{ROOT}"}
    logs = {which: _supervise(which, env) for which in ("uvicorn", "ours")}
    started = {k: log.count("Application startup complete") for k, log in logs.items()}
    kills = {k: len(_KILL.findall(log)) for k, log in logs.items()}
    print(f"\nGIL held {n} a's at start-up: uvicorn's supervisor {kills['uvicorn']} kills, "
          f"{started['uvicorn']} started; ours {kills['ours']} kills, {started['ours']} started")
    assert kills["ours"] == 0 and started["ours"] == 2, logs["ours"][-3000:]
    assert kills["uvicorn"] > 0, logs["uvicorn"][-3000:]  # the failure this supervisor removes


@pytest.mark.slow
@pytest.mark.parametrize("workers", [2, 4])
def test_workers_come_up_under_cpu_load_with_no_kills(tmp_path, workers):
    burners = 2 * (os.cpu_count() or 1) + workers
    ctx = multiprocessing.get_context("spawn")
    load = [ctx.Process(target=_burn, args=(600.0,), daemon=True) for _ in range(burners)]
    for p in load:
        p.start()
    server = ServiceProcess(tmp_path / "data", workers=workers, log_level="info",
                            env={"ALLOC_STARTUP_TIMEOUT_S": "300"})
    t0 = time.monotonic()
    try:
        server.start(timeout=300.0)
        log = ""
        while time.monotonic() - t0 < 300.0:
            log = server.log_path.read_text(errors="replace")
            if len(re.findall(r"Child process \[\d+\] ready after", log)) >= workers:
                break
            time.sleep(0.5)
        elapsed = time.monotonic() - t0
        load_seen = os.getloadavg()[0]
        ready = re.findall(r"Child process \[\d+\] ready after ([\d.]+) s", log)
        kills = re.findall(r"starting a new one|Child process \[\d+\] died", log)
        print(f"\n{workers} workers under {burners} CPU burners: all ready in {elapsed:.1f} s "
              f"(each after {', '.join(ready)} s), {len(kills)} restarts, load {load_seen:.1f}")
        assert len(ready) == workers, log[-3000:]
        assert kills == [], log[-3000:]
        with httpx.Client(base_url=server.url, timeout=30.0) as c:
            assert c.get("/v1/ready").status_code == 200
    finally:
        server.stop()
        for p in load:
            p.terminate()
        for p in load:
            p.join()
