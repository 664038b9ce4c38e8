"""Events never wait for unauthenticated builds (issue 12: "unauthenticated traffic cannot
make an event slower").

Structural, not timed: the build process is frozen with SIGSTOP, so every costly build
in flight is blocked for as long as the test wants; events (and cheap allocations, which
build on threads) must still complete, and apply, while those builds are provably still
blocked.  Latency under the flood is measured by ``benchmarks/bench_service.py``.
"""

from __future__ import annotations

import asyncio
import os
import signal
import threading
import time

import httpx
import pytest

from alloc.vehicles import ice
from service.priority import MAX_WAIT_S, TURNS, PriorityGate
from service.process import ServiceProcess

KEY = "priority-key"
H = {"X-API-Key": KEY}


@pytest.fixture()
def server(tmp_path):
    proc = ServiceProcess(tmp_path, api_key=KEY, env={"ALLOC_BUILD_WORKERS": "1", "ALLOC_BUILD_QUEUE": "4"}
                          ).start(timeout=180.0)
    yield proc
    proc.stop()


def test_events_complete_while_every_build_is_blocked(server):
    with httpx.Client(base_url=server.url, timeout=120.0) as c:
        vid = c.post("/v1/vehicles", json=ice().to_dict(), headers=H).json()["id"]
        # the first costly build starts the build process
        assert c.post(f"/v1/vehicles/{vid}/allocate", json={"v": [0.1, 0.2, 0.0], "method": "da_facet"}
                      ).status_code == 200
    workers = server.build_processes()
    flood: list[int] = []

    def attacker(resolution: int) -> None:  # a distinct costly da_table build each, no key
        with httpx.Client(base_url=server.url, timeout=120.0) as c:
            r = c.post(f"/v1/vehicles/{vid}/allocate", json={"v": [0.1, 0.2, 0.0], "method": "da_table",
                                                             "options": {"resolution": resolution}})
            flood.append(r.status_code)

    for pid in workers:
        os.kill(pid, signal.SIGSTOP)
    try:
        threads = [threading.Thread(target=attacker, args=(20 + i,)) for i in range(8)]
        for t in threads:
            t.start()
        # 1 running + 4 queued builds are blocked; the other 3 requests are refused at once (429)
        deadline = time.monotonic() + 60.0
        while flood.count(429) < 3 and time.monotonic() < deadline:
            time.sleep(0.05)
        assert sorted(flood) == [429, 429, 429], flood
        with httpx.Client(base_url=server.url, timeout=30.0) as c:
            for k in range(6):
                r = c.post(f"/v1/vehicles/{vid}/events",
                           json={"effector": "elevon_l", "kind": "jam", "position": float(k)}, headers=H)
                assert r.status_code == 201, r.text
                for method in ("pinv", "qp"):  # cheap builds: threads, not the blocked process
                    body = c.post(f"/v1/vehicles/{vid}/allocate", json={"v": [0.1, 0.2, 0.0], "method": method}).json()
                    assert body["health_version"] == k + 1 and body["u"][0] == float(k), body
            assert c.get("/v1/health").status_code == 200
        assert sorted(flood) == [429, 429, 429]  # every build is still blocked: the events did not wait for one
    finally:
        for pid in workers:
            os.kill(pid, signal.SIGCONT)
    for t in threads:
        t.join(timeout=120.0)
    assert sorted(flood) == [200] * 5 + [429] * 3, flood  # once resumed, the queued builds answer


def test_gate_holds_others_only_while_a_priority_request_is_in_flight():
    gate = PriorityGate("k")
    assert gate.claims("POST", "/v1/vehicles/x/events", [(b"x-api-key", b"k")])
    assert not gate.claims("POST", "/v1/vehicles/x/events", [(b"x-api-key", b"wrong")])
    assert not gate.claims("POST", "/v1/vehicles/x/allocate", [])
    assert not gate.claims("GET", "/v1/vehicles/x", [(b"x-api-key", b"k")])
    assert PriorityGate(None).claims("DELETE", "/v1/vehicles/x", [])
    assert PriorityGate(None).claims("POST", "/v1/vehicles", [])
    assert not PriorityGate(None).claims("POST", "/v1/vehicles/x/allocate", [])  # a read, key or not
    assert not PriorityGate(None).claims("POST", "/v1/vehicles/x/ams", [])

    async def scenario() -> list[str]:
        order: list[str] = []
        gate.enter()

        async def other(name: str) -> None:
            await gate.wait()
            order.append(name)
        tasks = [asyncio.create_task(other(f"other {i}")) for i in range(5)]
        await asyncio.sleep(0.05)  # many loop iterations: nobody passes a closed gate
        order.append("write done")
        gate.leave()
        await asyncio.gather(*tasks)
        await asyncio.wait_for(gate.wait(), 0.01)  # open: passes at once
        return order
    assert asyncio.run(scenario()) == ["write done"] + [f"other {i}" for i in range(5)]  # in arrival order
    assert gate.waited == 5 and gate.active == 0 and MAX_WAIT_S <= 1.0

    # a priority request that never ends holds nobody past MAX_WAIT_S (a fresh gate: its closure
    # budget full, whatever the write above spent of it on a loaded machine)
    gate = PriorityGate("k")

    async def stuck_write() -> float:
        gate.enter()
        t0 = time.monotonic()
        await asyncio.wait_for(gate.wait(), 5.0)
        return time.monotonic() - t0
    assert MAX_WAIT_S * 0.9 <= asyncio.run(stuck_write()) < 5.0


def test_gate_lets_in_at_most_turns_per_loop_iteration():
    gate = PriorityGate(None)

    async def scenario() -> list[int]:
        passed: list[int] = []
        iteration = 0

        async def ticker() -> None:
            nonlocal iteration
            while True:
                await asyncio.sleep(0)
                iteration += 1

        async def other() -> None:
            await gate.wait()
            passed.append(iteration)
        tick = asyncio.create_task(ticker())
        await asyncio.gather(*(other() for _ in range(10)))
        tick.cancel()
        return passed
    passed = asyncio.run(scenario())
    assert max(passed.count(i) for i in set(passed)) <= TURNS and len(passed) == 10


def test_whole_wait_is_the_gate_bound_plus_the_line_ahead():
    """The documented bound (service.priority): with the gate held by a write that never ends and
    Q requests in line, each costing c seconds once in, the last waits at most MAX_WAIT_S + Q c
    (plus scheduling slack); the first ones wait about MAX_WAIT_S."""
    gate, q, cost = PriorityGate(None), 200, 0.0005

    async def scenario() -> list[float]:
        gate.enter()  # never left
        t0 = time.monotonic()
        waits: list[float] = []

        async def other() -> None:
            await gate.wait()
            waits.append(time.monotonic() - t0)
            end = time.perf_counter() + cost  # the request's own work, holding the loop
            while time.perf_counter() < end:
                pass
        await asyncio.gather(*(other() for _ in range(q)))
        return waits
    waits = asyncio.run(scenario())
    # slack for a shared machine: the line costs q c of CPU, which a loaded machine stretches by
    # about the run queue per core
    stretch = max(2.0, os.getloadavg()[0] / (os.cpu_count() or 1))
    assert MAX_WAIT_S * 0.9 <= min(waits) and max(waits) <= MAX_WAIT_S + stretch * q * cost + 0.3, (min(waits),
                                                                                                   max(waits))


def test_writers_back_to_back_close_the_gate_at_most_its_share_of_the_time():
    """Key holders posting writes back to back (telemetry batches of 100 ms each) keep the others
    out for at most CLOSED_SHARE of the time, plus one MAX_WAIT_S; a sparse writer's every write
    closes the gate for all of its duration.  Simulated time (the gate's clock), 1 ms steps."""
    from service.priority import CLOSED_SHARE

    now = [0.0]
    gate = PriorityGate(None, clock=lambda: now[0])

    def write(seconds: float) -> int:
        """One write in flight for ``seconds``: the milliseconds the gate was closed meanwhile."""
        gate.enter()
        closed = 0
        for _ in range(round(seconds * 1000)):
            closed += gate._closed()
            now[0] += 0.001
        gate.leave()
        return closed

    async def scenario() -> tuple[float, list[int]]:
        closed = 0
        start = now[0]
        while now[0] - start < 10.0:
            closed += write(0.1)
            now[0] += 0.001  # the next batch arrives at once
        busy = closed / 1000 / (now[0] - start)
        now[0] += 1.0  # the writers stop: the budget refills
        sparse = []
        for _ in range(5):
            sparse.append(write(0.02))
            now[0] += 1.0
        return busy, sparse
    busy, sparse = asyncio.run(scenario())
    assert CLOSED_SHARE - 0.05 <= busy <= CLOSED_SHARE + MAX_WAIT_S / 10.0, busy
    assert sparse == [20] * 5
