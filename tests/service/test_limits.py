"""The service protects itself: hostile inputs, floods, memory, connections, strict types.

Real uvicorn processes.  Latencies under these attacks are measured by
``benchmarks/bench_service.py`` (no timed assertions here); these tests check the
contracts: 4xx answers naming the cause, no 5xx, the health endpoint answering
throughout, the event path unaffected, and the process's memory under its bound.
"""

from __future__ import annotations

import json
import socket
import threading
import time
from concurrent.futures import ThreadPoolExecutor

import httpx
import numpy as np
import pytest

from alloc.vehicles import ice
from service.process import ServiceProcess

KEY = "limits-key"
H = {"X-API-Key": KEY}
HOSTILE = {"B": [[1e300, 1, 2, 0.5], [1e300, 3, 1, 0.1], [1e300, -1, 2, 3]], "umin": [-1, -1, -1, -1],
           "umax": [1, 1, 1, 1], "Wu": [1e-20, 1, 1, 1], "v": [1, 2, 3]}
MiB = 1024 * 1024


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    proc = ServiceProcess(tmp_path_factory.mktemp("limits"), api_key=KEY,
                          env={"ALLOC_REQUEST_TIMEOUT_S": "1.5", "ALLOC_MAX_CONNECTIONS_PER_CLIENT": "400"}).start(timeout=180.0)
    yield proc
    proc.stop()


def problem_json(r: httpx.Response, status: int) -> dict:
    assert r.status_code == status, r.text
    assert r.headers["content-type"].startswith("application/problem+json")
    return r.json()


def test_hostile_magnitudes_get_422_and_health_keeps_answering(server):
    stop = threading.Event()
    health: list[int] = []

    def poll() -> None:
        with httpx.Client(base_url=server.url, timeout=5.0) as c:
            while not stop.is_set():
                health.append(c.get("/v1/health").status_code)
                time.sleep(0.01)

    def wait_for_polls(n: int) -> None:  # the poller answers before and after the hostile requests
        deadline = time.monotonic() + 10.0
        while len(health) < n and time.monotonic() < deadline:
            time.sleep(0.005)

    t = threading.Thread(target=poll)
    t.start()
    try:
        wait_for_polls(1)
        with httpx.Client(base_url=server.url, timeout=30.0) as c:
            for method in ("pinv", "qp", "wls", "cgi", "da"):
                body = problem_json(c.post("/v1/allocate", json={**HOSTILE, "method": method}), 422)
                pointers = {e["pointer"] for e in body["errors"]}
                assert "/B/0/0" in pointers and "/Wu/0" in pointers, body
            # within the magnitude bound, a tiny (non-zero) weight is refused too
            body = problem_json(c.post("/v1/allocate", json={**HOSTILE, "B": [[1, 1, 2, 0.5], [1, 3, 1, 0.1],
                                                                          [1, -1, 2, 3]]}), 422)
            assert "/Wu/0" in [e["pointer"] for e in body["errors"]]
            assert "at least 1e-09" in body["detail"]
        wait_for_polls(len(health) + 1)
    finally:
        stop.set()
        t.join()
    assert len(health) >= 2 and set(health) == {200}


def test_strict_json_types(server):
    with httpx.Client(base_url=server.url, timeout=30.0) as c:
        vid = c.post("/v1/vehicles", json=ice().to_dict(), headers=H).json()["id"]
        r = c.post(f"/v1/vehicles/{vid}/events", json={"effector": True, "kind": "jam", "position": 1.0}, headers=H)
        assert "/effector" in {e["pointer"] for e in problem_json(r, 422)["errors"]}
        r = c.post(f"/v1/vehicles/{vid}/allocate", json={"v": [0.1, 0.2, 0.0], "u_prev": [0.0] * 11, "dt": True})
        assert "/dt" in {e["pointer"] for e in problem_json(r, 422)["errors"]}
        r = c.post(f"/v1/vehicles/{vid}/allocate", json={"v": [0.1, "0.2", 0.0]})
        assert "/v/1" in {e["pointer"] for e in problem_json(r, 422)["errors"]}
        r = c.post(f"/v1/vehicles/{vid}/allocate", json={"v": [0.1, True, 0.0]})
        assert "/v/1" in {e["pointer"] for e in problem_json(r, 422)["errors"]}
        assert c.post(f"/v1/vehicles/{vid}/events", json={"effector": 0, "kind": "jam", "position": 1},
                      headers=H).status_code == 201  # an integer is a number


def _raw(server: ServiceProcess, data: bytes, timeout: float = 10.0) -> bytes:
    with socket.create_connection(("127.0.0.1", server.port), timeout=timeout) as s:
        s.sendall(data)
        chunks = []
        while True:
            try:
                chunk = s.recv(65536)
            except TimeoutError:
                break
            if not chunk:
                break
            chunks.append(chunk)
        return b"".join(chunks)


def test_framing_errors_are_problem_json(server):
    for request in (b"POST /v1/allocate HTTP/1.1\r\nHost: x\r\nContent-Length: abc\r\n\r\n{}",
                    b"GARBAGE\r\n\r\n",
                    b"POST /v1/allocate HTTP/1.1\r\nHost: x\r\nContent-Length: 2\r\nContent-Length: 3\r\n\r\n{}"):
        reply = _raw(server, request)
        head, _, body = reply.partition(b"\r\n\r\n")
        assert head.startswith(b"HTTP/1.1 400"), reply
        assert b"content-type: application/problem+json" in head.lower()
        assert json.loads(body)["status"] == 400


def test_half_sent_requests_are_closed(server):
    """A request whose headers or body never finish is answered 408 and closed (ALLOC_REQUEST_TIMEOUT_S = 1.5)."""
    socks = []
    for i in range(200):
        s = socket.create_connection(("127.0.0.1", server.port), timeout=10.0)
        s.sendall(b"POST /v1/allocate HTTP/1.1\r\nHost: x\r\n" if i % 2 else
                  b"POST /v1/allocate HTTP/1.1\r\nHost: x\r\nContent-Length: 100\r\n\r\n{\"B\"")
        socks.append(s)
    t0 = time.monotonic()
    closed = 0
    for s in socks:
        data = b""
        while True:
            chunk = s.recv(65536)
            if not chunk:
                break
            data += chunk
        assert data.startswith(b"HTTP/1.1 408") and b"problem+json" in data, data
        closed += 1
        s.close()
    assert closed == 200 and time.monotonic() - t0 < 30.0
    assert httpx.get(f"{server.url}/v1/health").status_code == 200


def test_empty_api_key_refuses_to_start(tmp_path):
    with pytest.raises(RuntimeError, match="empty"):
        ServiceProcess(tmp_path / "data", api_key="").start(timeout=120.0)


def test_padded_api_key_refuses_to_start_with_a_clear_message(tmp_path):
    with pytest.raises(RuntimeError, match="surrounding whitespace") as info:
        ServiceProcess(tmp_path / "data", api_key=" k ").start(timeout=120.0)
    assert " k " not in str(info.value).split("surrounding whitespace")[1]  # the key is not echoed
    assert "Traceback" not in str(info.value)


@pytest.mark.parametrize(("content", "accepted"), [("s3cret\n", "s3cret"), ("s3cret", "s3cret"),
                                                   ("s3cret\r\n", "s3cret"), (" s3cret\n", None),
                                                   ("s3cret\n\n", None), ("\n", None), ("", None)])
def test_api_key_file(tmp_path, content, accepted):
    from pydantic import ValidationError

    from service.config import Settings
    path = tmp_path / "key"
    path.write_text(content, newline="")
    if accepted is None:
        with pytest.raises(ValidationError, match="empty|whitespace"):
            Settings(api_key_file=path)
    else:
        assert Settings(api_key_file=path).api_key == accepted
    with pytest.raises(ValidationError, match="one way"):
        Settings(api_key_file=path, api_key="other")


def test_no_key_on_the_command_line(tmp_path):
    """``--api-key`` is gone (argv is world-readable in /proc/<pid>/cmdline); the file form works."""
    import inspect

    from service import cli
    assert "api_key" not in inspect.signature(cli.serve_command).parameters
    (tmp_path / "key").write_text("from-file\n")
    proc = ServiceProcess(tmp_path / "data", env={"ALLOC_API_KEY_FILE": str(tmp_path / "key")}).start(timeout=120.0)
    try:
        cmdline = open(f"/proc/{proc.proc.pid}/cmdline", "rb").read()
        assert b"from-file" not in cmdline
        with httpx.Client(base_url=proc.url, timeout=30.0) as c:
            assert c.post("/v1/vehicles", json=ice().to_dict()).status_code == 401
            assert c.post("/v1/vehicles", json=ice().to_dict(), headers={"X-API-Key": "from-file"}).status_code == 201
    finally:
        proc.stop()


def test_build_cost_refused_before_it_starts(server):
    rng = np.random.default_rng(1)
    B = rng.normal(size=(3, 64)).tolist()
    body = {"B": B, "umin": [-1.0] * 64, "umax": [1.0] * 64, "v": [0.1, 0.1, 0.1], "method": "da_table",
            "options": {"resolution": 256}}
    with httpx.Client(base_url=server.url, timeout=30.0) as c:
        t0 = time.monotonic()
        out = problem_json(c.post("/v1/allocate", json=body), 422)
        assert time.monotonic() - t0 < 5.0  # refused, not built (the build takes about a minute)
        assert out["errors"][0]["pointer"] == "/options/resolution"
        assert "predicted build time" in out["detail"] and "budget" in out["detail"]


def test_option_flood_does_not_block_events(server):
    """100 unauthenticated allocations with distinct options while events are recorded:
    every event commits, nothing answers 5xx (the flood gets 200, 422 or 429)."""
    with httpx.Client(base_url=server.url, timeout=60.0) as c:
        vid = c.post("/v1/vehicles", json=ice().to_dict(), headers=H).json()["id"]
    flood_status: list[int] = []

    def flood(i: int) -> None:
        with httpx.Client(base_url=server.url, timeout=120.0) as c:
            r = c.post(f"/v1/vehicles/{vid}/allocate", json={"v": [0.1, 0.2, 0.0], "method": "da_table",
                                                             "options": {"resolution": 8 + i}})
            flood_status.append(r.status_code)
    with ThreadPoolExecutor(16) as pool:
        futures = [pool.submit(flood, i) for i in range(100)]
        with httpx.Client(base_url=server.url, timeout=60.0) as c:
            for k in range(10):
                r = c.post(f"/v1/vehicles/{vid}/events", json={"effector": "elevon_l", "kind": "jam",
                                                                "position": float(k)}, headers=H)
                assert r.status_code == 201
                body = c.post(f"/v1/vehicles/{vid}/allocate", json={"v": [0.1, 0.2, 0.0]}).json()
                assert body["health_version"] == k + 1 and body["u"][0] == float(k)
        for f in futures:
            f.result()
    assert set(flood_status) <= {200, 422, 429} and 200 in flood_status, flood_status


def test_inline_memory_attack_stays_bounded(server):
    """Distinct inline da_facet problems at k = 6, m = 20 (~60-70 MiB each when built): not
    kept, so the RSS of the service and its build process together stays under start +
    cache budget (128 MiB) + one build in flight (~100 MiB)."""
    rng = np.random.default_rng(9)
    with httpx.Client(base_url=server.url, timeout=120.0) as c:  # the build process started and warm
        assert c.post("/v1/allocate", json={**ice().to_dict(), "v": [0.1, 0.2, 0.0], "method": "da_facet"}
                      ).status_code == 200
    base = server.rss()
    with httpx.Client(base_url=server.url, timeout=120.0) as c:
        for _ in range(6):
            body = {"B": rng.normal(size=(6, 20)).tolist(), "umin": [-1.0] * 20, "umax": [1.0] * 20,
                    "v": [0.1] * 6, "method": "da_facet"}
            assert c.post("/v1/allocate", json=body).status_code in (200, 429)
    grown = server.rss() - base
    assert grown < 128 * MiB + 100 * MiB, grown / MiB


def test_docs_are_offline(server):
    with httpx.Client(base_url=server.url, timeout=30.0) as c:
        for page in ("/docs", "/redoc"):
            html = c.get(page).text
            assert "http://" not in html and "https://" not in html.replace("https://github", ""), page
            import re
            refs = re.findall(r'(?:src|href)="([^"]+)"', html) + re.findall(r"url: '([^']+)'", html)
            assert refs, html
            for ref in refs:
                assert ref.startswith("/"), ref
                assert c.get(ref).status_code == 200, ref


# ------------------------------------------------------- request bodies (service.bodies)
def _run_bodies(requests: list[tuple[int, bool, bool]], total: int, reserved: int, limit: int):
    """Drive :class:`service.bodies.BodySizeLimit` with ``requests`` (size, priority, chunked), all
    held by the application at once until every one has arrived; returns each one's status,
    the largest budget held and the budget's state at the end."""
    import asyncio

    from service.bodies import BodyBudget, BodySizeLimit
    from service.priority import SCOPE_KEY

    budget = BodyBudget(total, reserved)
    peak = {"all": 0, "open": 0}
    release = asyncio.Event()
    arrived: list[int] = []

    async def app(scope, receive, send):
        body = (await receive())["body"]
        arrived.append(len(body))
        peak["all"] = max(peak["all"], budget.held)
        await release.wait()  # the application holds the body (as a slow route would)
        await send({"type": "http.response.start", "status": 200, "headers": []})
        await send({"type": "http.response.body", "body": b"ok"})

    middleware = BodySizeLimit(app, limit, budget)

    async def one(size: int, priority: bool, chunked: bool) -> tuple[int, dict]:
        headers = [] if chunked else [(b"content-length", str(size).encode())]
        scope = {"type": "http", "method": "POST", "path": "/v1/allocate", "headers": headers, SCOPE_KEY: priority}
        pieces = [b"x" * min(65536, size - i) for i in range(0, size, 65536)] or [b""]
        messages = [{"type": "http.request", "body": p, "more_body": i < len(pieces) - 1} for i, p in enumerate(pieces)]
        out: dict = {}

        async def receive():
            await asyncio.sleep(0)
            return messages.pop(0) if messages else {"type": "http.disconnect"}

        async def send(message):
            if message["type"] == "http.response.start":
                out["status"] = message["status"]
                out["headers"] = dict(message["headers"])
            else:
                out.setdefault("body", b"")
                out["body"] += message.get("body", b"")
        await middleware(scope, receive, send)
        return out["status"], out

    async def main():
        tasks = [asyncio.create_task(one(*r)) for r in requests]
        for _ in range(200):  # everything admitted has reached the application, the rest refused
            await asyncio.sleep(0)
        release.set()
        return await asyncio.gather(*tasks)
    results = asyncio.run(main())
    return results, peak, budget


def test_body_budget_refuses_beyond_it_and_keeps_the_writers_share():
    MB = 1_000_000
    # 10 unauthenticated 1 MB bodies against a 6 MB budget with 2 MB kept for writers: 4 admitted
    results, peak, budget = _run_bodies([(MB, False, False)] * 10 + [(MB, True, False)] * 2, 6 * MB, 2 * MB, 2 * MB)
    statuses = [s for s, _ in results]
    assert statuses[:10].count(200) == 4 and statuses[:10].count(503) == 6, statuses
    assert statuses[10:] == [200, 200]  # the writers' share was there for them
    refusal = results[4][1]
    assert refusal["headers"][b"content-type"] == b"application/problem+json"
    assert refusal["headers"][b"retry-after"] == b"1"
    assert json.loads(refusal["body"])["limit"] == "ALLOC_BODY_BYTES_IN_FLIGHT"
    assert peak["all"] == 6 * MB and budget.held == 0 and budget.refused == 6


@pytest.mark.parametrize("seed", range(20))
def test_body_budget_hostile_mixes(seed):
    """Seeded mixes of sizes (empty to over the limit), declared and chunked bodies, writers and
    others: the budget is never exceeded, others never take the writers' share, every request
    is answered 200, 413 or 503, and nothing stays reserved."""
    rng = np.random.default_rng(seed)
    total, reserved, limit = int(rng.integers(1, 8)) * MiB, 0, 0
    reserved = int(rng.integers(0, total // 2 + 1))
    limit = int(rng.integers(1, total - reserved + 1))
    n = int(rng.integers(1, 40))
    requests = [(int(rng.choice([0, 1, rng.integers(1, limit + 1), limit, limit + 1 + rng.integers(0, 1000)])),
                 bool(rng.random() < 0.3), bool(rng.random() < 0.4)) for _ in range(n)]
    results, peak, budget = _run_bodies(requests, total, reserved, limit)
    admitted_others = sum(size for (size, prio, _), (status, _) in zip(requests, results) if status == 200 and not prio)
    admitted = sum(size for (size, _, _), (status, _) in zip(requests, results) if status == 200)
    for (size, _, chunked), (status, _) in zip(requests, results):
        assert status in (200, 413, 503)
        if size <= limit:
            assert status != 413, (size, limit)
        else:  # a declared size is refused for it first; a chunked one when either limit is reached
            assert status == 413 or (chunked and status == 503), (size, limit, status)
    assert peak["all"] <= total and admitted <= total and admitted_others <= total - reserved
    assert budget.held == 0


@pytest.mark.parametrize("seed", range(10))
def test_json_bodies_parse_as_the_standard_library_does(seed):
    """service.bodies.parse_json (pydantic-core) against json.loads on seeded documents: the same
    values, floats bit for bit (extreme exponents, subnormals, long mantissas), and broken
    documents raise JSONDecodeError (FastAPI's 422) at a position inside the document."""
    from service.bodies import parse_json

    rng = np.random.default_rng(seed)
    floats = np.concatenate([rng.normal(size=200), rng.normal(size=50) * 10.0 ** rng.integers(-320, 308, size=50),
                             [5e-324, -0.0, 1.7976931348623157e308, 2.2250738585072014e-308]])
    formats = ["%r", "%.17g", "%.25e", "%.3f"]
    doc = ("{" + ", ".join(f'"k{i}": [' + ", ".join(formats[(i + j) % 4] % float(x) for j, x in enumerate(floats[i::7])) + "]"
                           for i in range(7)) + ', "s": "a\\u00e9\\n\\"b", "n": [1, -2, 123456789012345678901234567890]}')
    mine, theirs = parse_json(doc.encode()), json.loads(doc)
    assert mine == theirs
    for key in (f"k{i}" for i in range(7)):
        assert np.array_equal(np.array(mine[key]).view(np.int64), np.array(theirs[key]).view(np.int64))
    broken = doc.encode()
    cut = int(rng.integers(1, len(broken) - 1))
    for bad in (broken[:cut], broken[:cut] + b",,}" + broken[cut:], b"[" * 5000, b"\xff"):
        with pytest.raises(json.JSONDecodeError) as info:
            parse_json(bad)
        assert 0 <= info.value.pos <= len(bad)
