"""Load benchmark of the HTTP service, loopback only, bounded in count and time.

Starts the service (uvicorn, one worker) on a free 127.0.0.1 port with a temporary
database, then measures for ``pinv`` and ``qp`` on the ICE problem (k = 3, m = 11):

1. the library call alone (a built allocator, same process as the client), per demand;
2. closed-loop single requests (one keep-alive connection): allocations/s, p50/p99;
3. closed-loop batch requests (100 and 1,000 demands): allocations/s, p50/p99 per request;
4. open loop at a fixed arrival rate (default 300 requests/s): latency measured from each
   request's *scheduled* send time (no coordinated omission), p50/p99/max, goal p99 < 5 ms;
5. the per-request overhead of the service over the library call, as a ratio of medians;
6. reconfiguration: latency of recording an event (committed with fsync; the allocators
   in use are rebuilt after the response) and of the first allocation after it;
7. across processes: a second service process on the same database; an event through A,
   then allocations through B: event-to-visible latency (event sent -> first allocation
   from B that applies it returned) and how many of B's first allocations were stale (0);
8. under attack: event latency while 16 unauthenticated clients flood distinct-option
   ``da_table`` builds (goal p99 < 50 ms; ``--flood-only RUNS`` runs this alone, with the
   server's ``Server-Timing`` phases of the events: where an event's time went), ``/v1/health`` latency while the issue's hostile
   request (1e300 B, Wu 1e-20) is repeated (goal < 100 ms), and the RSS growth after 25
   distinct inline ``da_facet`` problems at k = 6, m = 20 (bound: cache 128 MiB + one build).

Client and server share the machine (2 cores here): the latencies include the client.
The ``srv`` columns are the service's own time per request, from its ``Server-Timing``
header (request reaching the application to response headers).
Run: ``.venv/bin/python -m benchmarks.bench_service [--rate 300] [--seconds 10] [--n 2000]``.
"""

from __future__ import annotations

import argparse
import asyncio
import gc
import http.client
import json
import multiprocessing
import os
import tempfile
import threading
import time
from collections import deque
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np

import alloc
from alloc.vehicles import ice
from benchmarks.service_attack_table import attack_table
from service.process import ServiceProcess

METHODS = ("pinv", "qp")
DEADLINE_S = 300.0  # the whole run stops by itself within this
KEY = "bench-key"  # the service's API key: writes (events) carry it, the attackers do not


@dataclass
class Stats:
    label: str
    n: int
    seconds: float
    lat: np.ndarray  # seconds
    per_request: int = 1  # allocations per request
    errors: int = 0
    server: np.ndarray | None = None  # the service's own time per request (Server-Timing), seconds
    phases: list[dict[str, float]] | None = None  # each request's Server-Timing phases, ms

    @property
    def rate(self) -> float:
        return self.n * self.per_request / self.seconds

    def row(self) -> str:
        p50, p99 = np.percentile(self.lat, [50, 99]) * 1e3
        if self.server is not None and np.isfinite(self.server).any():
            s50, s99 = np.nanpercentile(self.server, [50, 99]) * 1e3
            srv = f" {s50:>9.3f} {s99:>9.3f}"
        else:
            srv = f" {'-':>9} {'-':>9}"
        return (f"{self.label:<40} {self.n:>6} {self.rate:>12,.0f} {p50:>9.3f} {p99:>9.3f} "
                f"{self.lat.max() * 1e3:>9.3f} {self.errors:>4}" + srv)


HEADER = (f"{'case':<40} {'reqs':>6} {'allocs/s':>12} {'p50 ms':>9} {'p99 ms':>9} {'max ms':>9} {'err':>4}"
          f" {'srv p50':>9} {'srv p99':>9}")


def server_timing(header: str) -> dict[str, float]:
    """``Server-Timing`` as ``{name: ms}`` (``app``: the whole request; the rest its phases)."""
    out: dict[str, float] = {}
    for item in header.split(","):
        name, _, dur = item.strip().partition(";dur=")
        if dur:
            out[name] = float(dur)
    return out


class Connection:
    """A persistent HTTP/1.1 connection (http.client: the lightest client in the stdlib)."""

    def __init__(self, port: int, api_key: str | None = None) -> None:
        self.conn = http.client.HTTPConnection("127.0.0.1", port, timeout=30)
        self.headers = {"Content-Type": "application/json", **({"X-API-Key": api_key} if api_key else {})}

    def post(self, path: str, body: bytes) -> tuple[int, bytes]:
        self.conn.request("POST", path, body, self.headers)
        r = self.conn.getresponse()
        self.timing = server_timing(r.getheader("server-timing", ""))
        self.server_ms = self.timing.get("app", float("nan"))
        return r.status, r.read()

    def close(self) -> None:
        self.conn.close()


def demands(p: alloc.Problem, n: int, seed: int = 0) -> np.ndarray:
    """Random demands, mostly attainable: B u for u uniform in the middle half of the box."""
    rng = np.random.default_rng(seed)
    mid, half = (p.umin + p.umax) / 2, (p.umax - p.umin) / 4
    U = mid + half * rng.uniform(-1, 1, size=(n, p.m))
    return U @ p.B.T


def bench_library(p: alloc.Problem, method: str, V: np.ndarray) -> Stats:
    allocate = alloc.make_allocator(p, method)
    for v in V[:50]:
        allocate(v)
    lat = np.empty(len(V))
    t_start = time.perf_counter()
    for i, v in enumerate(V):
        t0 = time.perf_counter()
        allocate(v)
        lat[i] = time.perf_counter() - t0
    return Stats(f"library {method} (built allocator)", len(V), time.perf_counter() - t_start, lat)


def bench_closed(port: int, label: str, path: str, bodies: list[bytes], per_request: int = 1) -> Stats:
    conn = Connection(port)
    for b in bodies[:20]:  # warm-up: builds the cached allocator
        conn.post(path, b)
    lat, server = np.empty(len(bodies)), np.empty(len(bodies))
    errors = 0
    t_start = time.perf_counter()
    for i, b in enumerate(bodies):
        t0 = time.perf_counter()
        status, _ = conn.post(path, b)
        lat[i] = time.perf_counter() - t0
        server[i] = conn.server_ms / 1e3
        errors += status != 200
    seconds = time.perf_counter() - t_start
    conn.close()
    return Stats(label, len(bodies), seconds, lat, per_request, errors, server)


async def _open_loop(port: int, path: str, bodies: list[bytes], rate: float, connections: int
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray, int, float]:
    """One thread, asyncio, raw HTTP/1.1 on a pool of keep-alive connections: request ``i``
    is written at ``t0 + i / rate`` (or as soon after as the timer wakes) whatever the
    server is doing; no thread hand-offs in the client."""
    n = len(bodies)
    from_schedule, from_send, server = (np.full(n, np.nan) for _ in range(3))
    errors = 0
    # round robin (FIFO), so no connection idles past the server's keep-alive timeout (5 s)
    idle: deque[tuple[asyncio.StreamReader, asyncio.StreamWriter]] = deque()
    head = f"POST {path} HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Type: application/json\r\n".encode()

    async def connect() -> tuple[asyncio.StreamReader, asyncio.StreamWriter]:
        return await asyncio.open_connection("127.0.0.1", port)

    async def one(i: int, scheduled: float) -> None:
        nonlocal errors
        reader, writer = idle.popleft() if idle else await connect()
        request = head + b"Content-Length: %d\r\n\r\n" % len(bodies[i]) + bodies[i]
        sent = time.perf_counter()
        writer.write(request)
        if not (status_line := await reader.readline()):  # closed by the server: reconnect once
            writer.close()
            reader, writer = await connect()
            writer.write(request)
            status_line = await reader.readline()
        status = int(status_line.split()[1])
        length, timing = 0, float("nan")
        while (line := await reader.readline()) not in (b"\r\n", b""):
            name, _, value = line.decode("latin-1").partition(":")
            if name.lower() == "content-length":
                length = int(value)
            elif name.lower() == "server-timing":
                timing = server_timing(value).get("app", float("nan")) / 1e3
        await reader.readexactly(length)
        done = time.perf_counter()
        from_schedule[i], from_send[i], server[i] = done - scheduled, done - sent, timing
        errors += status != 200
        idle.append((reader, writer))

    idle.extend([await connect() for _ in range(connections)])
    await asyncio.gather(*(one(0, time.perf_counter()) for _ in range(1)))  # warm-up
    tasks = []
    t0 = time.perf_counter() + 0.05
    for i in range(n):
        scheduled = t0 + i / rate
        # the loop's timers have 1 ms granularity: wait coarsely, then sleep the last
        # stretch precisely (blocking the loop for well under a millisecond)
        if (delay := scheduled - time.perf_counter()) > 0.0015:
            await asyncio.sleep(delay - 0.0015)
        if (delay := scheduled - time.perf_counter()) > 0:
            time.sleep(delay)
        tasks.append(asyncio.create_task(one(i, scheduled)))
    await asyncio.gather(*tasks)
    seconds = time.perf_counter() - t0
    for _, writer in idle:
        writer.close()
    return from_schedule, from_send, server, errors, seconds


def bench_open(port: int, label: str, path: str, bodies: list[bytes], rate: float,
               connections: int = 4) -> tuple[Stats, Stats]:
    """Open loop at ``rate``: latency from the scheduled send time (no coordinated omission;
    includes the client's own lateness) and from the actual send."""
    gc.collect()
    gc.disable()  # a collector pause in the client would count as service latency
    try:
        sched, sent, server, errors, seconds = asyncio.run(_open_loop(port, path, bodies, rate, connections))
    finally:
        gc.enable()
    return (Stats(label + " (from schedule)", len(bodies), seconds, sched, 1, errors, server),
            Stats(label + " (from send)", len(bodies), seconds, sent, 1, errors, server))


def toggle_event(i: int) -> dict[str, Any]:
    """The i-th event of the benchmarks' sequence: jam elevon_l (even i, varying position), repair (odd i)."""
    if i % 2 == 0:
        return {"effector": "elevon_l", "kind": "jam", "position": 5.0 + i % 7}
    return {"effector": "elevon_l", "kind": "repair"}


def record_events(conn: Connection, vid: str, n: int, label: str,
                  after: Callable[[int, bytes, float], None] = lambda i, reply, sent: None) -> Stats:
    """``n`` events of :func:`toggle_event` through ``conn``, each followed by ``after(i, reply,
    sent)`` (``sent``: the event's send time); the events' latency and ``Server-Timing``."""
    lat, server = np.empty(n), np.empty(n)
    phases: list[dict[str, float]] = []
    errors = 0
    t_start = time.perf_counter()
    for i in range(n):
        t0 = time.perf_counter()
        status, reply = conn.post(f"/v1/vehicles/{vid}/events", json.dumps(toggle_event(i)).encode())
        lat[i], server[i] = time.perf_counter() - t0, conn.server_ms / 1e3
        phases.append(conn.timing)
        errors += status != 201
        after(i, reply, t0)
    return Stats(label, n, time.perf_counter() - t_start, lat, 1, errors, server, phases)


def bench_events(port: int, vid: str, n: int = 40) -> tuple[Stats, Stats]:
    """Alternate jam / repair events, each followed at once by a qp allocation."""
    conn = Connection(port, KEY)
    alloc_body = json.dumps({"v": [0.5, 1.0, 0.2], "method": "qp"}).encode()
    conn.post(f"/v1/vehicles/{vid}/allocate", alloc_body)
    first_lat, first_srv = np.empty(n), np.empty(n)
    first_errors = 0

    def allocate(i: int, reply: bytes, sent: float) -> None:
        nonlocal first_errors
        t0 = time.perf_counter()
        status, _ = conn.post(f"/v1/vehicles/{vid}/allocate", alloc_body)
        first_lat[i], first_srv[i] = time.perf_counter() - t0, conn.server_ms / 1e3
        first_errors += status != 200
    events = record_events(conn, vid, n, "POST /v1/vehicles/{id}/events", allocate)
    conn.close()
    return events, Stats("first qp allocate after event", n, events.seconds, first_lat, 1, first_errors, first_srv)


def bench_cross_process(port_a: int, port_b: int, vid: str, n: int = 60) -> tuple[Stats, int]:
    """Event through A, then allocations through B until one applies it."""
    a, b = Connection(port_a, KEY), Connection(port_b)
    body = json.dumps({"v": [0.5, 1.0, 0.2], "method": "qp"}).encode()
    b.post(f"/v1/vehicles/{vid}/allocate", body)
    visible = np.empty(n)
    stale = 0

    def poll_b(i: int, reply: bytes, sent: float) -> None:
        nonlocal stale
        version = json.loads(reply)["health"]["health_version"]
        first = True
        while True:
            _, out = b.post(f"/v1/vehicles/{vid}/allocate", body)
            if json.loads(out)["health_version"] >= version:
                break
            stale += first
            first = False
        visible[i] = time.perf_counter() - sent
    events = record_events(a, vid, n, "event", poll_b)
    a.close()
    b.close()
    return Stats("event via A -> applied by B's allocation", n, events.seconds, visible), stale


def _flood(port: int, path_body: list[tuple[str, bytes]], statuses: list[int], stop: threading.Event) -> None:
    conn = Connection(port)
    for path, body in path_body:
        if stop.is_set():
            break
        try:
            status, _ = conn.post(path, body)
        except (OSError, http.client.HTTPException):
            conn.close()
            conn = Connection(port)
            status = -1
        statuses.append(status)
    conn.close()


def _flood_process(port: int, jobs: list[list[tuple[str, bytes]]], out: Any, stop: Any) -> None:
    """The attackers, in a process of their own (their threads must not share the measuring
    client's GIL): one thread per job list; the status codes are sent back through ``out``."""
    statuses: list[int] = []
    flag = threading.Event()
    threads = [threading.Thread(target=_flood, args=(port, job, statuses, flag)) for job in jobs]
    for t in threads:
        t.start()
    stop.wait()
    flag.set()
    for t in threads:
        t.join()
    out.put(statuses)


class Attack:
    """Start ``jobs`` (lists of (path, body)) in a forked process; ``stop()`` returns the status counts."""

    def __init__(self, port: int, jobs: list[list[tuple[str, bytes]]]) -> None:
        ctx = multiprocessing.get_context("fork")
        self._out, self._stop = ctx.Queue(), ctx.Event()
        self._proc = ctx.Process(target=_flood_process, args=(port, jobs, self._out, self._stop))
        self._proc.start()

    def stop(self) -> dict[int, int]:
        self._stop.set()
        statuses = self._out.get(timeout=600)
        self._proc.join(timeout=60)
        return {code: statuses.count(code) for code in sorted(set(statuses))}


def bench_events_under_flood(port: int, vid: str, n: int = 40, clients: int = 16) -> tuple[Stats, dict[int, int]]:
    """Events (with the API key) while unauthenticated clients request distinct da_table options.

    Client ``c`` asks for resolutions ``8 + c, 24 + c, 40 + c, ...``: every client starts
    with builds within the budget (about 90 of them up to resolution ~98 on ICE), then
    goes on with options refused for their cost, until the events are done.
    """
    jobs = [[(f"/v1/vehicles/{vid}/allocate",
              json.dumps({"v": [0.5, 1.0, 0.2], "method": "da_table",
                          "options": {"resolution": 8 + c + clients * j}}).encode()) for j in range(2000)]
            for c in range(clients)]
    attack = Attack(port, jobs)
    time.sleep(0.5)
    conn = Connection(port, KEY)
    events = record_events(conn, vid, n, f"event during {clients}-client option flood",
                           lambda i, reply, sent: time.sleep(0.05))
    counts = attack.stop()
    conn.close()
    return events, counts


def phase_summary(stats: Stats) -> str:
    """p50 / max of each Server-Timing phase of ``stats``' requests (ms)."""
    names = list(dict.fromkeys(name for t in stats.phases or () for name in t))
    cols = {name: np.array([t.get(name, np.nan) for t in stats.phases or ()]) for name in names}
    return ", ".join(f"{name} {np.nanpercentile(c, 50):.1f}/{np.nanmax(c):.1f}" for name, c in cols.items())


def bench_health_under_hostile(port: int, seconds: float = 5.0) -> tuple[Stats, dict[int, int]]:
    hostile = json.dumps({"B": [[1e300, 1, 2, 0.5], [1e300, 3, 1, 0.1], [1e300, -1, 2, 3]],
                          "umin": [-1, -1, -1, -1], "umax": [1, 1, 1, 1], "Wu": [1e-20, 1, 1, 1],
                          "v": [1, 2, 3]}).encode()
    attack = Attack(port, [[("/v1/allocate", hostile)] * 100_000 for _ in range(4)])
    conn = http.client.HTTPConnection("127.0.0.1", port, timeout=30)
    lat: list[float] = []
    t_end = time.perf_counter() + seconds
    while time.perf_counter() < t_end:
        t0 = time.perf_counter()
        conn.request("GET", "/v1/health")
        r = conn.getresponse()
        r.read()
        lat.append(time.perf_counter() - t0)
        time.sleep(0.01)
    counts = attack.stop()
    conn.close()
    return Stats("GET /v1/health during hostile requests", len(lat), seconds, np.array(lat)), counts


def bench_memory_attack(server: ServiceProcess, n: int = 25) -> tuple[int, int, int, float]:
    """(RSS before, RSS after, peak RSS seen, seconds) for n distinct inline da_facet problems, k = 6,
    m = 20: the RSS of the service process and its build processes together."""
    rng = np.random.default_rng(12)
    conn = Connection(server.port)
    before = peak = server.rss()
    t0 = time.perf_counter()
    for _ in range(n):
        body = json.dumps({"B": rng.normal(size=(6, 20)).tolist(), "umin": [-1.0] * 20, "umax": [1.0] * 20,
                           "v": [0.1] * 6, "method": "da_facet"}).encode()
        conn.post("/v1/allocate", body)
        peak = max(peak, server.rss())
    conn.close()
    return before, server.rss(), peak, time.perf_counter() - t0


def bench_noise_floor(n: int = 2000) -> Stats:
    """How late ``sleep(0.5 ms)`` wakes up: the machine's own scheduling noise, a floor
    under any latency measured here (other jobs on the same cores show up in it)."""
    lat = np.empty(n)
    t_start = time.perf_counter()
    for i in range(n):
        t0 = time.perf_counter()
        time.sleep(0.0005)
        lat[i] = time.perf_counter() - t0 - 0.0005
    return Stats("sleep(0.5 ms) overshoot", n, time.perf_counter() - t_start, lat)


def _environment() -> str:
    import importlib.util

    loop = "uvloop" if importlib.util.find_spec("uvloop") else "asyncio"
    parser = "httptools" if importlib.util.find_spec("httptools") else "h11"
    load = ", ".join(f"{x:.2f}" for x in os.getloadavg())
    return f"uvicorn 1 worker ({loop}, {parser}); {os.cpu_count()} CPU(s); load average {load}"


def table(title: str, rows: Iterable[Stats]) -> None:
    """Print a titled table of ``rows``."""
    print(f"\n{title}")
    print(HEADER)
    for stats in rows:
        print(stats.row())


def flood_only(runs: int) -> None:
    """Section 8's option flood alone, ``runs`` times: each run's events on a fresh vehicle (so its
    da_table builds are not cached by an earlier run), after the same events without the flood."""
    problem = ice().to_dict()
    print(f"alloc service benchmark, option flood only ({runs} runs); {_environment()}")
    print(HEADER + "  goal")
    with tempfile.TemporaryDirectory(prefix="alloc-bench-") as tmp, ServiceProcess(tmp, api_key=KEY) as server:
        for run in range(runs):
            conn = Connection(server.port, KEY)  # a new one per run: the last one idled past the keep-alive
            vid = json.loads(conn.post("/v1/vehicles", json.dumps({**problem, "name": "ice"}).encode())[1])["id"]
            floor = record_events(conn, vid, 40, f"run {run + 1}: event, no flood", lambda i, reply, sent: time.sleep(0.05))
            flood, counts = bench_events_under_flood(server.port, vid)
            p99 = float(np.percentile(flood.lat, 99)) * 1e3
            ratio = p99 / (float(np.percentile(floor.lat, 99)) * 1e3)
            print(floor.row())
            print(flood.row() + f"  p99 < 50 ms {'met' if p99 < 50 else 'MISSED'}; p99 / floor p99 {ratio:.1f}")
            print(f"  flood answers by status: {counts}; load average {os.getloadavg()[0]:.2f}")
            print(f"  server phases, p50/max ms, no flood: {phase_summary(floor)}")
            print(f"  server phases, p50/max ms, flood:    {phase_summary(flood)}")
            for w in np.argsort(flood.lat)[-3:]:
                print(f"  slowest: {flood.lat[w] * 1e3:.1f} ms, server: " +
                      ", ".join(f"{k} {v:.1f}" for k, v in (flood.phases or [])[w].items()))
            conn.close()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=2000, help="closed-loop single requests per case")
    parser.add_argument("--rate", type=float, default=300.0, help="open-loop arrival rate, requests/s")
    parser.add_argument("--seconds", type=float, default=10.0, help="open-loop duration per case")
    parser.add_argument("--nice", type=int, default=0,
                        help="niceness increment of the client and the server (negative needs root): "
                             "shows the latency of a rig that gives the service priority over other jobs")
    parser.add_argument("--attacks-only", action="store_true", help="skip the open-loop cases")
    parser.add_argument("--flood-only", type=int, default=0, metavar="RUNS",
                        help="only the option flood: RUNS runs, each on a fresh vehicle, each next to a no-flood floor")
    parser.add_argument("--attack-suite", metavar="REPORT.json", default=None,
                        help="run the standing attack suite (tests/service/test_attacks.py) writing its figures "
                             "to REPORT.json, then print them as a markdown table")
    parser.add_argument("--attack-table", metavar="REPORT.json", default=None,
                        help="print the markdown table of an attack-suite report already written")
    parser.add_argument("--markdown", metavar="FILE", default=None,
                        help="with --attack-suite/--attack-table: also write the table to FILE "
                             "(benchmarks/reference/service_attacks.md is the one docs/service.md includes)")
    args = parser.parse_args()
    if args.nice:
        os.nice(args.nice)
    if args.attack_suite or args.attack_table:
        attack_table(args.attack_suite or args.attack_table, run=bool(args.attack_suite), markdown=args.markdown)
        return
    if args.flood_only:
        flood_only(args.flood_only)
        return
    n = max(100, min(args.n, 20_000))
    n_open = int(max(1, min(args.seconds, 60.0)) * args.rate)

    p = ice()
    V = demands(p, max(n, n_open, 1000))
    problem = p.to_dict()
    started = time.monotonic()
    print(f"alloc service benchmark: ICE problem k={p.k}, m={p.m}; loopback; {_environment()}")

    # the server process inherits the client's --nice
    with tempfile.TemporaryDirectory(prefix="alloc-bench-") as tmp, ServiceProcess(tmp, api_key=KEY) as server:
        vid = json.loads(Connection(server.port, KEY).post("/v1/vehicles", json.dumps({**problem, "name": "ice"}).encode())[1])["id"]
        noise = bench_noise_floor()
        lib: dict[str, Stats] = {}
        single: list[Stats] = []
        for method in METHODS:
            lib[method] = bench_library(p, method, V[:n])
            inline = [json.dumps({**problem, "v": v.tolist(), "method": method}).encode() for v in V[:n]]
            vehicle = [json.dumps({"v": v.tolist(), "method": method}).encode() for v in V[:n]]
            single.append(bench_closed(server.port, f"POST /v1/allocate {method}", "/v1/allocate", inline))
            single.append(bench_closed(server.port, f"POST /v1/vehicles/{{id}}/allocate {method}",
                                       f"/v1/vehicles/{vid}/allocate", vehicle))
        batch: list[Stats] = []
        for method in METHODS:
            for size, reps in ((100, 50), (1000, 10)):
                bodies = [json.dumps({**problem, "V": V[(r * size) % len(V):][:size].tolist(), "method": method}).encode()
                          for r in range(reps)]
                batch.append(bench_closed(server.port, f"POST /v1/allocate/batch {method} x{size}",
                                          "/v1/allocate/batch", bodies, per_request=size))
        reconfig = bench_events(server.port, vid)
        if args.attacks_only:
            open_loop_methods: tuple[str, ...] = ()
        else:
            open_loop_methods = METHODS
        open_loop: list[Stats] = []
        for method in open_loop_methods:
            if time.monotonic() - started > DEADLINE_S:
                break
            bodies = [json.dumps({"v": v.tolist(), "method": method}).encode() for v in V[:n_open]]
            open_loop.extend(bench_open(server.port, f"{args.rate:g}/s vehicle {method}",
                                        f"/v1/vehicles/{vid}/allocate", bodies, args.rate))
            bodies = [json.dumps({**problem, "v": v.tolist(), "method": method}).encode() for v in V[:n_open]]
            open_loop.extend(bench_open(server.port, f"{args.rate:g}/s inline {method}",
                                        "/v1/allocate", bodies, args.rate))
        with ServiceProcess(tmp, api_key=KEY) as second:  # a replica on the same database
            cross, stale = bench_cross_process(server.port, second.port, vid)
        flood, flood_counts = bench_events_under_flood(server.port, vid)
        hostile, hostile_counts = bench_health_under_hostile(server.port)
        memory = bench_memory_attack(server)

    print(f"niceness increment of client and server: {args.nice}")
    table("Scheduling noise floor of this machine (client process)", [noise])
    table("Library call (same machine, no HTTP)", lib.values())
    table("Closed loop, single requests (one keep-alive connection)", single)
    table("Closed loop, batch requests (allocs/s counts demands; latency per request)", batch)
    print(f"\nOpen loop at {args.rate:g} requests/s (latency from the scheduled send time; goal p99 < 5 ms)")
    print(HEADER + "  goal")
    for s in open_loop:
        p99 = float(np.percentile(s.lat, 99)) * 1e3
        print(s.row() + ("  met" if p99 < 5.0 else "  MISSED"))
    table("Reconfiguration (event committed with fsync + allocators rebuilt, then the next allocation)", reconfig)
    table("Across processes (two service processes on one SQLite file)", [cross])
    print(f"B's first allocation after the event's response was stale: {stale} of {cross.n} (must be 0)")
    print("\nUnder attack")
    print(HEADER + "  goal")
    p99 = float(np.percentile(flood.lat, 99)) * 1e3
    print(flood.row() + (f"  p99 < 50 ms {'met' if p99 < 50 else 'MISSED'}"))
    print(f"  flood answers by status: {flood_counts}; floor (no flood): event p50/p99 "
          f"{np.percentile(reconfig[0].lat, 50) * 1e3:.2f}/{np.percentile(reconfig[0].lat, 99) * 1e3:.2f} ms")
    print(f"  server phases under the flood, p50/max ms: {phase_summary(flood)}")
    worst = float(hostile.lat.max()) * 1e3
    print(hostile.row() + (f"  max < 100 ms {'met' if worst < 100 else 'MISSED'}"))
    print(f"  hostile answers by status: {hostile_counts}")
    before, after, peak, secs = memory
    print(f"memory attack: 25 distinct inline da_facet k=6 m=20 in {secs:.1f} s: RSS {before / 2**20:.0f} MiB -> "
          f"{after / 2**20:.0f} MiB (peak {peak / 2**20:.0f} MiB; bound: start + 128 MiB cache + ~100 MiB build)")
    print("\nPer-request overhead over the library call (ratio of medians, closed loop)")
    print(f"{'case':<40} {'service p50 us':>15} {'library p50 us':>15} {'ratio':>8} {'overhead us':>12}")
    for s in single:
        method = s.label.split()[-1]
        svc, libm = float(np.median(s.lat)) * 1e6, float(np.median(lib[method].lat)) * 1e6
        print(f"{s.label:<40} {svc:>15.1f} {libm:>15.1f} {svc / libm:>8.1f} {svc - libm:>12.1f}")
    print(f"\ntotal {time.monotonic() - started:.1f} s; at the end: {_environment()}")


if __name__ == "__main__":
    main()
