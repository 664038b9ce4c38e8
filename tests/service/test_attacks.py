"""The standing attack suite: a real uvicorn process on loopback, one attack class at a time,
and the reconfiguration promise measured during each (issue 23).

Each attack runs for a bounded time while a probe records, round after round, an
authenticated event (a jam), the first allocation after it (``qp`` at the vehicle's new
health) and ``/v1/health``.  The same probe without an attack gives the floor of the run.
Targets on a quiet machine (issue 23): event p99 < 50 ms, first allocation after an event
p99 < 100 ms, ``/v1/health`` < 100 ms.  A shared machine is not quiet (an fsync'd event
alone took 100-400 ms at load 8 on 2 cores), so each attack is held to the larger of the
target scaled by the run queue per core (``os.getloadavg()[0] / os.cpu_count()``, at least
1) and :data:`FLOOR_FACTOR` times the floor's p99 measured in the same run without an
attack.  The figures are printed (and written to ``$ALLOC_ATTACK_REPORT`` as JSON when set).

Attack classes (default run, bounded in count and time; larger under ``-m slow``):
batch pricing (the most expensive batches the service admits, and refusals of the rest),
validation-error floods, header floods (size and count), answers that are never read,
and slowloris with reconnects from other loopback addresses.
"""

from __future__ import annotations

import asyncio
import gc
import json
import multiprocessing
import os
import selectors
import shutil
import socket
import subprocess
import tempfile
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

import httpx
import numpy as np
import pytest

from alloc.vehicles import ice
from service.process import ServiceProcess

KEY = "attack-key"
H = {"X-API-Key": KEY}
MiB = 1024 * 1024
ANSWER_BUDGET = 48 * MiB
WRITE_TIMEOUT_S = 10.0
#: rounds per probe.  A p99 of n samples ignores the largest one only when n >= 101 (numpy's
#: linear interpolation puts it at index 0.99 (n - 1)); at 40 rounds it was 0.61 of the maximum,
#: so one fsync outlier of the disk (an idle SQLite commit loop here: p50 0.6 ms, max 85 ms in
#: 300) decided the verdict
ROUNDS = 120
TARGETS_MS = {"event": 50.0, "allocation": 100.0, "health": 100.0}
#: an attack may slow the reconfiguration path by at most this factor over the same run's floor
FLOOR_FACTOR = 3.0
#: large bodies' parses an event may wait for: the one running when it arrived (no other
#: starts while a priority write is in flight: service.bodies)
PARSES_WAITED = 1
#: the floor itself, on any machine this suite runs on
FLOOR_LIMIT_MS = 2000.0
REPORT: dict[str, dict] = {}
FLOOR: dict[str, float] = {}
#: the server's RSS after the floor (its start-up, the vehicle, the probe's allocators), and the
#: largest seen by the last probe (service and build processes together)
RSS: dict[str, int] = {}
#: the variable part of the documented memory bound (service/config.py) at the suite's settings:
#: the allocator cache (128 MiB), 1,024 vehicle states (~70 MiB), one build in flight (~90 MiB),
#: the body budget (64 MiB), uvicorn's read buffer per open connection (512 x 128 KiB) and the
#: answer budget
MEMORY_BOUND = (128 + 70 + 90 + 64 + 64) * MiB + ANSWER_BUDGET
SLOWEST: dict[str, tuple[float, str]] = {}  # of the last probe: where the slowest request's time went


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    env = {"ALLOC_REQUEST_TIMEOUT_S": "3", "ALLOC_WRITE_TIMEOUT_S": str(WRITE_TIMEOUT_S),
           "ALLOC_ANSWER_BYTES_IN_FLIGHT": str(ANSWER_BUDGET)}
    data = tmp_path_factory.mktemp("attacks")
    # The database on tmpfs: this machine's disk stalls an fsync'd SQLite commit now and then
    # (35-273 ms, 14 times in three runs of this module; no attack here writes to the disk), and
    # two such stalls in a probe's 120 events decide its p99.  What is measured is then what
    # the attacks do to the service; durability on a disk is tested by the kill -9 tests.
    shm = tempfile.mkdtemp(prefix="alloc-attacks-", dir="/dev/shm") if os.access("/dev/shm", os.W_OK) else None
    url = f"sqlite:///{shm}/alloc.sqlite3" if shm else None
    if shm is None:
        print("\nattack suite: /dev/shm is not writable; the database is on the disk, whose fsync stalls count")
    proc = ServiceProcess(data, api_key=KEY, env=env, database_url=url).start(timeout=300.0)
    yield proc
    proc.stop()
    if shm:
        shutil.rmtree(shm, ignore_errors=True)
    if path := os.environ.get("ALLOC_ATTACK_REPORT"):
        commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                                cwd=os.path.dirname(__file__)).stdout.strip() or "?"
        with open(path, "w") as fh:
            json.dump({"database": "tmpfs" if shm else "disk", "loadavg": os.getloadavg(), "cpus": os.cpu_count(),
                       "nice": os.nice(0),
                       "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), "commit": commit,
                       "targets_ms": TARGETS_MS, "attacks": REPORT}, fh, indent=1)


@pytest.fixture(scope="module")
def vehicle(server) -> str:
    with httpx.Client(base_url=server.url, timeout=60.0) as c:
        vid = c.post("/v1/vehicles", json=ice().to_dict(), headers=H).json()["id"]
        assert c.post(f"/v1/vehicles/{vid}/allocate", json={"v": [0.1, 0.2, 0.0], "method": "qp"}).status_code == 200
    return vid


def rss_now(server) -> int:
    """RSS of the service and of the build processes it has now (``server.rss()`` waits for them
    to exist; the probe must not)."""
    try:
        pids = [server.proc.pid, *server.build_processes(timeout=0.05)]
    except RuntimeError:
        pids = [server.proc.pid]
    total = 0
    for pid in pids:
        for line in open(f"/proc/{pid}/status").read().splitlines():
            if line.startswith("VmRSS:"):
                total += int(line.split()[1]) * 1024
    return total


def slack() -> float:
    return max(1.0, os.getloadavg()[0] / (os.cpu_count() or 1))


def p99(values: list[float]) -> float:
    return float(np.percentile(values, 99)) if values else float("nan")


def connected(server) -> httpx.Client:
    """A client whose connection is open already (a writer keeps its connection, as a ground
    station or flight computer does): opened before an attack, its requests need no accept."""
    c = httpx.Client(base_url=server.url, timeout=30.0)
    c.__enter__()  # opened here, closed by the probe that uses it
    assert c.get("/v1/health").status_code == 200
    return c


def probe(server, vid: str, seconds: float, rounds_max: int = ROUNDS,
          client: httpx.Client | None = None) -> dict[str, list[float]]:
    """Event, the first allocation after it, health: ms each, for ``seconds`` (at most ``rounds_max`` rounds).

    The collector of this process is off meanwhile: its full collections (50-73 ms in a
    pytest process holding the suite) would count as the service's latency."""
    out: dict[str, list[float]] = {"event": [], "allocation": [], "health": []}
    timings: dict[str, tuple[float, str]] = {}  # the slowest of each kind and its Server-Timing
    deadline = time.monotonic() + seconds
    c = client or httpx.Client(base_url=server.url, timeout=30.0).__enter__()
    RSS["peak"] = rss_now(server)
    gc.collect()
    gc.disable()
    try:
        k = 0
        while time.monotonic() < deadline and k < rounds_max:
            position = float(k % 7 - 3)
            t0 = time.perf_counter()
            r = c.post(f"/v1/vehicles/{vid}/events", json={"effector": "elevon_l", "kind": "jam", "position": position},
                       headers=H)
            t1 = time.perf_counter()
            assert r.status_code == 201, r.text
            version = r.json()["health"]["health_version"]
            a = c.post(f"/v1/vehicles/{vid}/allocate", json={"v": [0.1, 0.2, 0.0], "method": "qp"})
            t2 = time.perf_counter()
            assert a.status_code == 200, a.text
            assert a.json()["health_version"] == version and a.json()["u"][0] == position  # the event applied
            h = c.get("/v1/health")
            t3 = time.perf_counter()
            assert h.status_code == 200
            for kind, ms, reply in (("event", (t1 - t0) * 1e3, r), ("allocation", (t2 - t1) * 1e3, a),
                                    ("health", (t3 - t2) * 1e3, h)):
                out[kind].append(ms)
                if ms > timings.get(kind, (0.0, ""))[0]:
                    timings[kind] = (ms, reply.headers.get("server-timing", ""))
            k += 1
            RSS["peak"] = max(RSS["peak"], rss_now(server))
            time.sleep(0.01)
    finally:
        gc.enable()
        c.close()
    SLOWEST.update(timings)
    return out


def check(name: str, figures: dict[str, list[float]], allowance_ms: float = 0.0, **extra: object) -> None:
    """Record the figures and assert the bounds (module docstring), plus ``allowance_ms`` where
    the service's construction allows a stated extra wait."""
    if not FLOOR:
        pytest.skip("the floor was not measured (run the module, or test_floor first)")
    s = slack()
    if "rss_growth_mib" not in extra and "start" in RSS:  # memory growth during the attack, against the bound
        grown = RSS["peak"] - RSS["start"]
        extra = {**extra, "rss_growth_mib": round(grown / MiB, 1), "bound_mib": round(MEMORY_BOUND / MiB, 1)}
        assert grown < MEMORY_BOUND, (name, grown / MiB, MEMORY_BOUND / MiB)
    row = {k: {"p50_ms": round(float(np.median(v)), 2), "p99_ms": round(p99(v), 2), "n": len(v)}
           for k, v in figures.items()}
    REPORT[name] = {**row, "slack": round(s, 2), "loadavg": os.getloadavg()[0], "allowance_ms": allowance_ms, **extra}
    print(f"\n{name}: " + ", ".join(f"{k} p50 {r['p50_ms']} ms p99 {r['p99_ms']} ms (n={r['n']})"
                                     for k, r in row.items()) + f"; load {os.getloadavg()[0]:.1f}, slack {s:.1f}")
    for kind, target in TARGETS_MS.items():
        assert figures[kind], f"{name}: no {kind} measured"
        bound = max(target * s, FLOOR_FACTOR * FLOOR[kind]) + allowance_ms
        assert p99(figures[kind]) < bound, (f"{name}: {kind} p99 {p99(figures[kind]):.1f} ms >= {bound:.0f} ms; "
                                            f"slowest's Server-Timing: {SLOWEST.get(kind)}")


@contextmanager
def attack(fn: Callable[[Any], list], clients: int) -> Iterator[list]:
    """``clients`` processes running ``fn(stop)`` until the block ends; the block's value is
    filled, when it ends, with what they returned (concatenated).  Processes, not threads: an
    attacker's thread would take the probe's GIL in this process, and its latency would count
    against the service (forked, so ``fn`` may be a closure)."""
    ctx = multiprocessing.get_context("fork")
    stop, out = ctx.Event(), ctx.Queue()

    def run() -> None:
        try:
            out.put(("ok", fn(stop)))
        except BaseException as exc:  # noqa: BLE001 - reported after the block
            out.put(("error", repr(exc)))
    procs = [ctx.Process(target=run, daemon=True) for _ in range(clients)]
    for p in procs:
        p.start()
    time.sleep(0.5)  # the attack is under way before the probe starts
    results: list = []
    try:
        yield results
    finally:
        stop.set()
        answers = [out.get(timeout=120) for _ in procs]
        for p in procs:
            p.join(timeout=60)
    errors = [value for kind, value in answers if kind == "error"]
    assert not errors, errors[0]
    for _, value in answers:
        results.extend(value)


def test_floor(server, vehicle):
    server.build_processes(timeout=300.0)  # warm-up done, build processes up: part of start-up RSS
    figures = probe(server, vehicle, 4.0)
    for kind, values in figures.items():
        assert p99(values) < FLOOR_LIMIT_MS, (kind, p99(values))
        FLOOR[kind] = p99(values)
    RSS["start"] = rss_now(server)
    check("no attack (floor)", figures)


# ------------------------------------------------------------------ batch pricing
def _cgi_body(rows: int) -> dict:
    rng = np.random.default_rng(3)
    m = 64
    return {"B": rng.normal(size=(6, m)).tolist(), "umin": [-1.0] * m, "umax": [1.0] * m,
            "V": rng.normal(size=(rows, 6)).tolist(), "method": "cgi",
            "options": {"priorities": [float(i) for i in range(6)]}}


def test_batch_pricing_refuses_before_running_and_admitted_batches_do_not_delay_events(server, vehicle):
    """The issue's batch (10,000 rows, m = 64, cgi, 6 priority levels: ~7 minutes) is refused at
    once naming the budget; batches at the largest admitted size flood the service meanwhile."""
    with httpx.Client(base_url=server.url, timeout=60.0) as c:
        t0 = time.perf_counter()
        r = c.post("/v1/allocate/batch", json=_cgi_body(10_000))
        refused_ms = (time.perf_counter() - t0) * 1e3
        assert r.status_code == 422 and r.json()["errors"][0]["pointer"] == "/V", r.text
        detail = r.json()["detail"]
        assert "ALLOC_BATCH_BUDGET_S" in detail and "predicted batch time" in detail
        fits = int(detail.split("send at most ")[1].split(" rows")[0].replace(",", ""))
    assert 0 < fits < 10_000
    body = json.dumps(_cgi_body(max(fits, 1)))
    def flood(stop: Any) -> list[int]:
        statuses = []
        with httpx.Client(base_url=server.url, timeout=120.0) as c:
            while not stop.is_set():
                statuses.append(c.post("/v1/allocate/batch", content=body,
                                       headers={"content-type": "application/json"}).status_code)
        return statuses
    with attack(flood, clients=4) as statuses:
        figures = probe(server, vehicle, 4.0)
    assert statuses and set(statuses) <= {200, 429, 503}, statuses
    check("batch pricing (4 clients, largest admitted cgi batch at m = 64)", figures,
          refused_ms=round(refused_ms, 1), admitted_rows=fits, batches=statuses.count(200))


# ---------------------------------------------------------- validation-error floods
def _heavy_turn_order(light_open_s: float, max_wait_s: float, monkeypatch) -> tuple[list[str], float]:
    """What passes in which order when a large body's parse asks for its turn while a light
    request is open for ``light_open_s`` (its allocation awaiting a build), and how long the
    parse waited."""
    from service import priority
    monkeypatch.setattr(priority, "MAX_WAIT_S", max_wait_s)
    order: list[str] = []
    passed: list[float] = []

    async def scenario() -> float:
        gate = priority.PriorityGate("key")
        ticket = priority.LightTicket(gate)  # its head arrived: the protocol opened it
        t0 = time.perf_counter()
        heavy = asyncio.create_task(gate.wait(heavy=True))
        heavy.add_done_callback(lambda _: (order.append("parse"), passed.append(time.perf_counter())))
        await gate.wait()
        order.append("allocation")
        await asyncio.sleep(light_open_s)  # the allocation's build, on a thread
        order.append("allocation answered")
        ticket.done()
        ticket.done()  # idempotent: the protocol and the middleware both close it
        await asyncio.wait_for(heavy, 5.0)
        assert gate.light == 0
        return passed[0] - t0
    return order, asyncio.run(scenario())


def test_a_large_body_parse_waits_for_the_open_light_request(monkeypatch):
    """The cause of the validation flood's slow allocations: parses started, one after another,
    while the allocation awaited its build; now none starts until its answer has begun."""
    order, waited = _heavy_turn_order(0.05, max_wait_s=5.0, monkeypatch=monkeypatch)
    assert order == ["allocation", "allocation answered", "parse"]
    assert waited >= 0.05


def test_a_light_flood_delays_a_parse_by_at_most_the_gate_bound(monkeypatch):
    order, waited = _heavy_turn_order(0.3, max_wait_s=0.02, monkeypatch=monkeypatch)
    assert order == ["allocation", "parse", "allocation answered"]  # released by its deadline
    assert waited >= 0.02


def test_a_parse_yields_to_a_light_request_whose_head_arrived_in_the_next_iteration():
    """A parse's turn comes at the second refill after it asked, at the earliest: a light
    request whose bytes arrived while the previous parse held the loop has its head read in
    between (its socket's callback runs after a refill already scheduled in that iteration)."""
    from service import priority
    order: list[str] = []

    async def scenario() -> None:
        gate = priority.PriorityGate(None)
        previous_parse_done = asyncio.Event()

        async def next_parse() -> None:
            await previous_parse_done.wait()
            await gate.wait(heavy=True)
            order.append("parse")
        heavy = asyncio.create_task(next_parse())
        await asyncio.sleep(0)
        previous_parse_done.set()  # the previous parse ends: the next one wakes first ...
        gate._schedule_refill()  # ... and a refill is already due in that iteration
        await asyncio.sleep(0)  # that iteration: the parse asks, the refill runs, then the socket is read
        ticket = priority.LightTicket(gate)
        await asyncio.sleep(0.02)
        order.append("light answered")
        ticket.done()
        await asyncio.wait_for(heavy, 5.0)
    asyncio.run(scenario())
    assert order == ["light answered", "parse"]


def test_light_tickets_follow_the_declared_body_size():
    from service.priority import HEAVY_BODY_BYTES, is_light
    assert is_light([]) and is_light([(b"content-length", str(HEAVY_BODY_BYTES).encode())])
    assert not is_light([(b"content-length", str(HEAVY_BODY_BYTES + 1).encode())])
    assert not is_light([(b"transfer-encoding", b"chunked")])  # size unknown until it has arrived
    assert not is_light([(b"content-length", b"12x")])


def test_validation_error_flood(server, vehicle):
    """60,000 bad entries in a 0.3 MB body, 40,000 unknown members: each a short 422 with the count.

    Parsing such a body holds the event loop; large bodies are parsed one at a time and none
    starts while an event or a light request (the allocation after it, awaiting its rebuild)
    is in flight (``service.bodies.BodySizeLimit``, ``service.priority.LightTicket``), so each
    waits for at most the one parse running when it arrived (:data:`PARSES_WAITED`): the
    allowance is the flood request's own latency, measured alone."""
    bad_rows = json.dumps({"B": [[1.0] * 6] * 6, "umin": [-1.0] * 6, "umax": [1.0] * 6,
                           "V": [["x"] * 6 for _ in range(10_000)]})
    members = json.dumps({"B": [[1.0]], "umin": [-1.0], "umax": [1.0], "v": [0.0],
                          **{f"k{i}": 0 for i in range(40_000)}})
    with httpx.Client(base_url=server.url, timeout=30.0) as c:
        r = c.post("/v1/allocate/batch", content=bad_rows, headers={"content-type": "application/json"})
        assert r.status_code == 422 and len(r.content) < 20_000 and r.json()["error_count"] <= 20, len(r.content)
        r = c.post("/v1/allocate", content=members, headers={"content-type": "application/json"})
        assert r.status_code == 422 and len(r.content) < 20_000, len(r.content)
        alone = []
        for body, path in ((bad_rows, "/v1/allocate/batch"), (members, "/v1/allocate")) * 3:
            t0 = time.perf_counter()
            c.post(path, content=body, headers={"content-type": "application/json"})
            alone.append((time.perf_counter() - t0) * 1e3)
    def flood(stop: Any) -> list[int]:
        sizes = []
        with httpx.Client(base_url=server.url, timeout=60.0) as c:
            while not stop.is_set():
                for body, path in ((bad_rows, "/v1/allocate/batch"), (members, "/v1/allocate")):
                    r = c.post(path, content=body, headers={"content-type": "application/json"})
                    assert r.status_code == 422
                    sizes.append(len(r.content))
        return sizes
    with attack(flood, clients=4) as sizes:
        figures = probe(server, vehicle, 4.0)
    check("validation-error flood (4 clients)", figures, allowance_ms=PARSES_WAITED * max(alone), answers=len(sizes),
          largest_answer=max(sizes), alone_ms=round(max(alone), 1))


# ------------------------------------------------------------------ header floods
def _raw(port: int, data: bytes, source: str = "127.0.0.1") -> bytes:
    """Send ``data`` on a fresh connection, return what the server answers (until it closes)."""
    s = socket.socket()
    s.settimeout(30.0)
    s.bind((source, 0))
    s.connect(("127.0.0.1", port))
    out = b""
    try:
        s.sendall(data)
    except OSError:
        pass  # the server refused and closed before the rest was sent: read its answer
    try:
        while chunk := s.recv(65536):
            out += chunk
    except OSError:
        pass
    finally:
        s.close()
    return out


def test_header_floods_are_refused_before_they_are_buffered(server, vehicle):
    huge = b"GET /v1/health HTTP/1.1\r\nHost: x\r\nX-Pad: " + b"a" * (5 * MiB) + b"\r\n\r\n"
    many = b"GET /v1/health HTTP/1.1\r\nHost: x\r\n" + b"".join(b"X-%d: 1\r\n" % i for i in range(5000)) + b"\r\n"
    t0 = time.perf_counter()
    answer = _raw(server.port, many)
    assert answer.startswith(b"HTTP/1.1 431") and b"problem+json" in answer, answer[:200]
    answer = _raw(server.port, huge)
    assert answer == b"" or answer.startswith(b"HTTP/1.1 431"), answer[:200]  # refused (maybe reset mid-send)
    refused_ms = (time.perf_counter() - t0) * 1e3
    def flood(stop: Any) -> list[int]:
        sent = []
        while not stop.is_set():
            for data in (huge, many):
                sent.append(len(_raw(server.port, data)))
        return sent
    with attack(flood, clients=4) as sent:
        figures = probe(server, vehicle, 4.0)
    check("header flood (4 clients, 5 MiB header / 5,000 fields)", figures, refused_ms=round(refused_ms, 1),
          sent=len(sent))


# ------------------------------------------------------------------ unread answers
def _unread_batch_request(port: int, body: bytes, source: str) -> socket.socket:
    s = socket.socket()
    s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)  # the client reads nothing: keep its buffer small
    s.bind((source, 0))
    s.connect(("127.0.0.1", port))
    s.sendall(b"POST /v1/allocate/batch HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\n"
              b"Content-Length: %d\r\n\r\n" % len(body) + body)
    return s


def test_unread_answers_are_dropped_and_memory_stays_bounded(server, vehicle):
    """Connections that request the largest answers and never read them: each answer's bytes
    are reserved (ALLOC_ANSWER_BYTES_IN_FLIGHT, 503 beyond), the connection is dropped after
    ALLOC_WRITE_TIMEOUT_S, and the service's memory grows by at most that budget."""
    # k = 1, m = 64: a 0.2 MB body asks for a 14 MB answer (the class here is the answer held,
    # not the parse of large bodies, which is the validation flood's)
    m, rows = 64, 8000
    rng = np.random.default_rng(4)
    body = json.dumps({"B": rng.normal(size=(1, m)).tolist(), "umin": [-1.0] * m, "umax": [1.0] * m,
                       "V": rng.normal(size=(rows, 1)).tolist(), "method": "pinv"}).encode()
    with httpx.Client(base_url=server.url, timeout=120.0) as c:  # the answer is large, and admitted
        r = c.post("/v1/allocate/batch", content=body, headers={"content-type": "application/json"})
        assert r.status_code == 200 and len(r.content) > 8 * MiB, (r.status_code, len(r.content))
        # what one such body costs the event loop: its parse and validation (refused after them)
        refused = json.dumps({**json.loads(body), "method": "no-such-method"}).encode()
        alone = []
        for _ in range(3):
            t0 = time.perf_counter()
            assert c.post("/v1/allocate/batch", content=refused,
                          headers={"content-type": "application/json"}).status_code == 422
            alone.append((time.perf_counter() - t0) * 1e3)
    base = server.rss()
    socks = []
    for i in range(40):
        socks.append(_unread_batch_request(server.port, body, f"127.0.0.{2 + i % 8}"))
    t_opened = time.monotonic()
    try:
        # the probe starts once the 40 requests' arrival (a burst of large bodies: parse,
        # validation, the refusals beyond the answer budget; the validation flood's class) has
        # been handled, while their answers are held: health answers as fast as in the floor
        with httpx.Client(base_url=server.url, timeout=30.0) as c:
            while time.monotonic() - t_opened < WRITE_TIMEOUT_S / 2:
                t0 = time.perf_counter()
                c.get("/v1/health")
                if (time.perf_counter() - t0) * 1e3 < max(FLOOR["health"], 20.0):
                    break
                time.sleep(0.05)
        burst_ms = (time.monotonic() - t_opened) * 1e3
        figures = probe(server, vehicle, max(1.5, t_opened + WRITE_TIMEOUT_S - 0.5 - time.monotonic()))
        grown = server.rss() - base
        time.sleep(max(0.0, t_opened + WRITE_TIMEOUT_S + 3.0 - time.monotonic()))
        dropped = 0
        for s in socks:  # after the write deadline every connection is closed by the server
            s.settimeout(10.0)
            try:
                while s.recv(1 << 20):
                    pass
                dropped += 1
            except OSError:
                dropped += 1  # reset: dropped
    finally:
        for s in socks:
            s.close()
    assert dropped == len(socks)
    # the documented bound: the answer budget, plus per connection a socket buffer and a chunk
    bound = ANSWER_BUDGET + len(socks) * 512 * 1024 + 32 * MiB
    assert grown < bound, (grown / MiB, bound / MiB)
    # bodies over 64 KiB are parsed one at a time (test_validation_error_flood)
    check("unread answers (40 connections, 14 MB answers)", figures, allowance_ms=PARSES_WAITED * max(alone),
          rss_growth_mib=round(grown / MiB, 1), bound_mib=round(bound / MiB, 1), parse_ms=round(max(alone), 1),
          burst_handled_ms=round(burst_ms))


# ------------------------------------------------------------ slowloris, reconnecting
def _slowloris(port: int, sources: list[str], per_source: int, stop: Any, opened: Any) -> None:
    """Keep ``per_source`` half-sent requests open from each source address, reopening each one
    as soon as the server closes it (run in a process of its own: its loop would otherwise
    take the probe's GIL in this one)."""
    sel = selectors.DefaultSelector()

    def open_one(source: str) -> None:
        s = socket.socket()
        s.setblocking(False)
        s.bind((source, 0))
        try:
            s.connect(("127.0.0.1", port))
        except BlockingIOError:
            pass
        sel.register(s, selectors.EVENT_WRITE, source)
    for source in sources:
        for _ in range(per_source):
            open_one(source)
    while not stop.is_set():
        for key, mask in sel.select(timeout=0.1):
            s, source = key.fileobj, key.data
            if mask & selectors.EVENT_WRITE:
                try:
                    s.send(b"POST /v1/allocate HTTP/1.1\r\nHost: x\r\nContent-Length: 1000\r\n")  # never finished
                    sel.modify(s, selectors.EVENT_READ, source)
                    opened.value += 1
                    continue
                except OSError:
                    pass
            else:
                try:
                    if s.recv(65536):
                        continue  # an answer (408/503): the close follows
                except OSError:
                    pass
            sel.unregister(s)
            s.close()
            open_one(source)
    for key in list(sel.get_map().values()):
        key.fileobj.close()


@pytest.mark.parametrize("connections", [600, pytest.param(2000, marks=pytest.mark.slow)])
def test_slowloris_with_reconnects_cannot_take_the_events_capacity(server, vehicle, connections):
    """More half-sent requests than the service's connection limit, from 8 other loopback
    addresses, reopened as soon as they are closed: events still get through, every one.

    The probe's connection is open before the attack: the kernel's accept queue is shared by
    everyone connecting, and under a flood of reconnects a new connection can wait for TCP's
    SYN retransmission (1 s and more: measured at 2,000 connections); what the service
    controls is that an open connection is never starved of capacity."""
    sources = [f"127.0.0.{2 + i}" for i in range(8)]
    ctx = multiprocessing.get_context("spawn")
    stop, opened = ctx.Event(), ctx.Value("l", 0)
    client = connected(server)
    attacker = ctx.Process(target=_slowloris, args=(server.port, sources, connections // len(sources), stop, opened),
                           daemon=True)
    attacker.start()
    try:
        deadline = time.monotonic() + 60.0
        while opened.value < connections and time.monotonic() < deadline:
            assert client.get("/v1/health").status_code == 200  # kept open (ALLOC_KEEP_ALIVE_S = 5 s)
            time.sleep(0.5)
        figures = probe(server, vehicle, 4.0, client=client)
        fresh = []  # writers that open a new connection for their event, under the same attack
        for k in range(3):
            t0 = time.perf_counter()
            with httpx.Client(base_url=server.url, timeout=30.0) as c:
                r = c.post(f"/v1/vehicles/{vehicle}/events", json={"effector": "elevon_l", "kind": "jam",
                                                                  "position": float(k)}, headers=H)
            assert r.status_code == 201, r.text
            fresh.append(round((time.perf_counter() - t0) * 1e3, 1))
    finally:
        stop.set()
        attacker.join(timeout=30)
    assert opened.value >= connections
    check(f"slowloris with reconnects ({connections} connections from 8 addresses)", figures, opened=opened.value,
          fresh_connection_event_ms=fresh)
