"""Telemetry takes the priority gate's fast path (issue 23: once a failure is published, every
allocation accounts for it promptly, whatever other clients do).

A telemetry batch that turns into a detection is how a *silent* failure is published, so it
is priority like an event, but only with a light body (``service.priority._is_write``: a key
holder cannot hold the loop with 4 MiB parses on the fast path either).  The classification
is checked on every route of the application (enumerated, so a new route cannot be left
unclassified) by a seeded generator of methods, paths, keys and bodies; the WebSocket's
per-message hold of the gate on the ASGI level; and the promise itself on a real server: a
silent jam posted in a telemetry batch (HTTP and WebSocket) while a validation-error flood
runs changes the health and the next allocation holds it, within the attack suite's
same-run-floor bound (``test_attacks``).
"""

from __future__ import annotations

import asyncio
import json
import re
import string
import time
from typing import Any

import httpx
import numpy as np
import pytest
from fastapi.routing import iter_route_contexts
from fastapi.testclient import TestClient

from service.config import Settings
from service.deps import require_api_key
from service.main import create_app
from service.priority import HEAVY_BODY_BYTES, PriorityGate, PriorityMiddleware
from service.process import ServiceProcess
from test_attacks import FLOOR_FACTOR, PARSES_WAITED, TARGETS_MS, attack, p99, slack
from test_telemetry import SMALL, SMALL_SETTINGS, small_flight

KEY = "telemetry-priority-key"
H = {"X-API-Key": KEY}

#: what must be priority, written from the issue's promise (not read from service.priority):
#: the writes that publish or decide a failure (event, telemetry batch, proposal decisions) or
#: add or remove a vehicle; ``light`` ones only with a body of at most HEAVY_BODY_BYTES
PRIORITY = {
    ("POST", "/v1/vehicles"): "light",
    ("DELETE", "/v1/vehicles/{vehicle_id}"): "light",
    ("POST", "/v1/vehicles/{vehicle_id}/events"): "light",
    ("POST", "/v1/vehicles/{vehicle_id}/telemetry"): "light",
    ("POST", "/v1/vehicles/{vehicle_id}/proposals/{pid}/accept"): "light",
    ("POST", "/v1/vehicles/{vehicle_id}/proposals/{pid}/reject"): "light",
}
#: WebSockets whose light messages are priority
STREAMS = {"/v1/vehicles/{vehicle_id}/telemetry/ws"}
#: key-guarded writes that are deliberately not priority (they publish no failure)
GUARDED_NOT_PRIORITY = {("PUT", "/v1/vehicles/{vehicle_id}/telemetry")}
METHODS = ["GET", "HEAD", "POST", "PUT", "PATCH", "DELETE", "OPTIONS"]


def _needs_key(dependant: Any) -> bool:
    return any(d.call is require_api_key or _needs_key(d) for d in dependant.dependencies)


@pytest.fixture(scope="module")
def routes(tmp_path_factory) -> list[dict[str, Any]]:
    """Every route of the application, in dispatch order: kind, methods, path format and
    pattern, whether it needs the API key."""
    app = create_app(Settings(data_dir=tmp_path_factory.mktemp("routes"), warmup=False))
    out = []
    for route in iter_route_contexts(app.routes):
        dependant = getattr(route, "dependant", None)
        out.append({"kind": type(route.original_route).__name__, "methods": frozenset(route.methods or ()),
                    "format": route.path_format, "regex": route.path_regex,
                    "guarded": dependant is not None and _needs_key(dependant)})
    return out


def _dispatched(routes: list[dict[str, Any]], method: str, path: str) -> str | None:
    """The path format of the HTTP route the application runs for ``method path`` (the oracle),
    or ``None`` (404, 405)."""
    for route in routes:
        if route["kind"] != "APIWebSocketRoute" and route["regex"].match(path) and method in route["methods"]:
            return route["format"]
    return None


def _stream_dispatched(routes: list[dict[str, Any]], path: str) -> str | None:
    for route in routes:
        if route["kind"] == "APIWebSocketRoute" and route["regex"].match(path):
            return route["format"]
    return None


def _segment(rng: np.random.Generator) -> str:
    alphabet = string.ascii_letters + string.digits + "_-"
    return "".join(rng.choice(list(alphabet), size=int(rng.integers(1, 65))))


def _concrete(path_format: str, rng: np.random.Generator) -> str:
    return re.sub(r"\{[^}]+\}", lambda _: _segment(rng), path_format)


def _key_headers(rng: np.random.Generator) -> tuple[list[tuple[bytes, bytes]], bool]:
    """Headers carrying (or not) the key, and whether they carry the right one where the
    service reads it (the first ``x-api-key`` field)."""
    key = KEY.encode()
    case = int(rng.integers(0, 8))
    if case == 0:
        return [], False
    if case == 1:
        return [(b"x-api-key", key)], True
    if case == 2:  # wrong: another key, a prefix, an extension, a case change
        wrong = [b"other", key[:-1], key + b"x", key.upper(), b""][int(rng.integers(0, 5))]
        return [(b"x-api-key", wrong)], False
    if case == 3:  # the right key in the wrong header
        name = [b"authorization", b"x-api-token", b"api-key", b"x-apikey", b"cookie"][int(rng.integers(0, 5))]
        return [(name, key)], False
    if case == 4:  # the first x-api-key is what counts (as in the routes' check)
        return [(b"x-api-key", b"wrong"), (b"x-api-key", key)], False
    if case == 5:
        return [(b"x-api-key", key), (b"x-api-key", b"wrong")], True
    if case == 6:  # among other headers
        return [(b"host", b"x"), (b"content-type", b"application/json"), (b"x-api-key", key)], True
    return [(b"authorization", b"Bearer " + key)], False


def _body_headers(rng: np.random.Generator) -> tuple[list[tuple[bytes, bytes]], bool]:
    """Body framing headers and whether the body is light (declared, at most HEAVY_BODY_BYTES)."""
    case = int(rng.integers(0, 6))
    if case == 0:
        return [], True
    if case == 1:
        n = int(rng.integers(0, HEAVY_BODY_BYTES + 1))
        return [(b"content-length", str(n).encode())], True
    if case == 2:
        return [(b"content-length", str(HEAVY_BODY_BYTES).encode())], True
    if case == 3:
        n = int(rng.integers(HEAVY_BODY_BYTES + 1, 8 * HEAVY_BODY_BYTES))
        return [(b"content-length", str(n).encode())], False
    if case == 4:
        return [(b"transfer-encoding", b"chunked")], False  # size unknown until it has arrived
    return [(b"content-length", b"12x")], False


def _mutated(path: str, rng: np.random.Generator) -> str:
    """A path next to a route's: not that route."""
    case = int(rng.integers(0, 4))
    if case == 0:
        return path + "/"
    if case == 1:
        return path + "/" + _segment(rng)
    if case == 2:
        return "/v2" + path[3:] if path.startswith("/v1") else "/x" + path
    return path.rsplit("/", 1)[0] + "/" + _segment(rng) if path.count("/") > 2 else path + "x"


def test_every_route_is_classified(routes):
    """The expected table names existing routes only, every priority route needs the key, and
    every key-guarded route is either priority or deliberately not."""
    http = {(method, r["format"]) for r in routes for method in r["methods"]}
    guarded = {(method, r["format"]) for r in routes if r["guarded"] for method in r["methods"]}
    sockets = {r["format"] for r in routes if r["kind"] == "APIWebSocketRoute"}
    assert set(PRIORITY) <= http, set(PRIORITY) - http
    assert STREAMS <= sockets, STREAMS - sockets
    assert set(PRIORITY) <= guarded, set(PRIORITY) - guarded  # the fast path is for key holders only
    assert guarded == set(PRIORITY) | GUARDED_NOT_PRIORITY, guarded ^ (set(PRIORITY) | GUARDED_NOT_PRIORITY)
    assert len(http) >= 25 and len(sockets) == 1  # the enumeration saw the included routers


@pytest.mark.parametrize("configured", [True, False], ids=["key", "no-key"])
def test_priority_of_every_route_method_key_and_body(routes, configured):
    """A seeded generator over every route, every method, key placements and body framings, on
    the route's paths and on neighbouring ones: priority exactly when the application would run
    an expected write, with a light body and the right key (any key, or none, when the service
    has no key); a WebSocket's messages exactly on the telemetry stream, with the key."""
    gate = PriorityGate(KEY if configured else None)
    rng = np.random.default_rng(23)
    formats = sorted({r["format"] for r in routes})
    claimed: set[tuple[str, str]] = set()
    for fmt in formats:
        for method in METHODS:
            for _ in range(12):
                keys, right = _key_headers(rng)
                framing, light = _body_headers(rng)
                headers = [*keys, *framing] if rng.random() < 0.5 else [*framing, *keys]
                path = _concrete(fmt, rng)
                for candidate in (path, _mutated(path, rng)):
                    target = _dispatched(routes, method, candidate)
                    expected = (method, target) in PRIORITY and light and (right or not configured)
                    assert gate.claims(method, candidate, headers) is expected, (method, candidate, target, headers)
                    if expected:
                        claimed.add((method, target))
                    stream = _stream_dispatched(routes, candidate) in STREAMS and (right or not configured)
                    assert gate.claims_stream(candidate, headers) is stream, (candidate, headers)
    assert len(claimed) >= 4  # the generator reached priority routes (and every one below)
    for method, fmt in PRIORITY:
        path = _concrete(fmt, rng)
        assert gate.claims(method, path, [(b"x-api-key", KEY.encode()), (b"content-length", b"120")])
        assert not gate.claims(method, path, [(b"x-api-key", KEY.encode()), (b"transfer-encoding", b"chunked")])
        assert gate.claims(method, path, [(b"x-api-key", b"wrong")]) is not configured
    # the WebSocket's handshake (GET, upgrade) never claims the gate: only its messages do
    assert not gate.claims("GET", "/v1/vehicles/v1/telemetry/ws", [(b"x-api-key", KEY.encode())])


def test_a_light_batch_is_what_a_stream_posts():
    """HEAVY_BODY_BYTES in samples (service.priority._is_write): about 180 at m = 11, k = 6."""
    rng = np.random.default_rng(5)
    n = 200
    body = json.dumps({"t": (10.0 + np.cumsum(rng.uniform(0.09, 0.11, n))).tolist(),
                       "u": rng.uniform(-25, 25, (n, 11)).tolist(), "y": rng.normal(0, 3, (n, 6)).tolist()})
    per_sample = len(body) / n
    assert 150 <= HEAVY_BODY_BYTES / per_sample <= 220, HEAVY_BODY_BYTES / per_sample


# --------------------------------------------------------------- the WebSocket's hold
def _run_stream(messages: list[dict[str, Any]], headers: list[tuple[bytes, bytes]],
                fail_at: int | None = None, stalled: bool = False) -> tuple[list[int], PriorityGate]:
    """A stub WebSocket route behind the middleware: for each message it receives, the number of
    priority requests in flight while it handles it, and while its answer is being sent;
    ``fail_at``: the route raises there; ``stalled``: the client reads no answer (a send
    never completes; the connection is dropped after the last message's)."""
    gate = PriorityGate(KEY)
    seen: list[int] = []
    sending: list[int] = []

    async def route(scope: Any, receive: Any, send: Any) -> None:
        assert (await receive())["type"] == "websocket.connect"
        await send({"type": "websocket.accept"})
        while True:
            message = await receive()
            if message["type"] == "websocket.disconnect":
                return
            seen.append(gate.active)
            if len(seen) - 1 == fail_at:
                raise RuntimeError("the route failed")
            await asyncio.sleep(0)
            await send({"type": "websocket.send", "text": "{}"})

    async def scenario() -> None:
        inbox = [{"type": "websocket.connect"}, *messages, {"type": "websocket.disconnect", "code": 1000}]

        async def receive() -> dict[str, Any]:
            return inbox.pop(0)

        async def send(message: dict[str, Any]) -> None:
            if message["type"] == "websocket.send":
                sending.append(gate.active)
                if stalled:
                    await asyncio.wait_for(asyncio.Event().wait(), 0.05)  # dropped: the send fails
        scope = {"type": "websocket", "path": "/v1/vehicles/v/telemetry/ws", "headers": headers}
        try:
            await PriorityMiddleware(route, gate)(scope, receive, send)
        except (TimeoutError, RuntimeError):
            pass  # the failure propagates as it would to the server
    asyncio.run(scenario())
    assert sending == [0] * len(sending)  # an answer being sent holds nobody back
    return seen, gate


def test_a_streams_light_messages_hold_the_gate_until_answered():
    light = {"type": "websocket.receive", "text": "x" * HEAVY_BODY_BYTES}
    heavy = {"type": "websocket.receive", "text": "x" * (HEAVY_BODY_BYTES + 1)}
    wide = {"type": "websocket.receive", "text": "\u00e9" * 100}  # not ASCII: its size is not its length
    raw = {"type": "websocket.receive", "bytes": b"x" * 100}
    key = [(b"x-api-key", KEY.encode())]
    seen, gate = _run_stream([light, heavy, light, wide, raw, light], key)
    assert seen == [1, 0, 1, 0, 1, 1] and gate.active == 0
    seen, gate = _run_stream([light, light], [(b"x-api-key", b"wrong")])
    assert seen == [0, 0] and gate.active == 0
    seen, gate = _run_stream([light, light, light], key, fail_at=1)  # the route fails mid-message
    assert seen == [1, 1] and gate.active == 0
    seen, gate = _run_stream([light, light], key, stalled=True)  # the client reads nothing
    assert seen == [1] and gate.active == 0


def test_a_real_stream_leaves_the_gate_open(tmp_path):
    """The telemetry WebSocket of the application, with the key: every message answered, and
    afterwards no priority request is left in flight (the gate would close for nobody)."""
    app = create_app(Settings(data_dir=tmp_path, warmup=False, api_key=KEY))
    t, U, Y = small_flight(3)
    with TestClient(app) as c:
        vid = c.post("/v1/vehicles", json=SMALL, headers=H).json()["id"]
        assert c.put(f"/v1/vehicles/{vid}/telemetry", json={**SMALL_SETTINGS, "policy": "auto"},
                     headers=H).status_code == 200
        with c.websocket_connect(f"/v1/vehicles/{vid}/telemetry/ws", headers=H) as ws:
            answers = []
            for i in range(0, len(t), 20):
                ws.send_text(json.dumps({"t": t[i:i + 20].tolist(), "u": U[i:i + 20].tolist(),
                                         "y": Y[i:i + 20].tolist()}))
                answers.append(json.loads(ws.receive_text()))
        assert [a["health_version"] for a in answers] == [0, 1, 1]  # the jam at 3 s, in the second batch
        assert app.state.gate.active == 0 and app.state.gate.light == 0
        waited = app.state.gate.waited
        assert c.get("/v1/health").status_code == 200 and app.state.gate.waited == waited  # not held


# ------------------------------------------------------------------ a real server
@pytest.fixture(scope="module")
def server(tmp_path_factory):
    proc = ServiceProcess(tmp_path_factory.mktemp("telemetry-priority"), api_key=KEY,
                          env={"ALLOC_REQUEST_TIMEOUT_S": "3"}).start(timeout=300.0)
    proc.build_processes(timeout=300.0)  # warm-up done: it does not compete with the floor
    yield proc
    proc.stop()


def _jam_round(c: httpx.Client, base: str, seed: int, websocket: bool) -> dict[str, float]:
    """A vehicle whose effector ``a`` jams silently at 3 s: the samples before it, then the batch
    holding the jam (timed), then the first allocation after it (timed)."""
    from websockets.sync.client import connect

    vid = c.post("/v1/vehicles", json=SMALL, headers=H).json()["id"]
    assert c.put(f"/v1/vehicles/{vid}/telemetry", json={**SMALL_SETTINGS, "policy": "auto"},
                 headers=H).status_code == 200
    t, U, Y = small_flight(seed)
    cut = int(np.searchsorted(t, 3.0 - 1e-9))
    before = {"t": t[:cut].tolist(), "u": U[:cut].tolist(), "y": Y[:cut].tolist()}
    jam = json.dumps({"t": t[cut:].tolist(), "u": U[cut:].tolist(), "y": Y[cut:].tolist()})
    assert len(jam) <= HEAVY_BODY_BYTES  # a light batch: priority
    if websocket:
        with connect(base.replace("http://", "ws://") + f"/v1/vehicles/{vid}/telemetry/ws",
                     additional_headers=H) as ws:
            ws.send(json.dumps(before))
            assert json.loads(ws.recv())["health_version"] == 0
            t0 = time.perf_counter()
            ws.send(jam)
            answer = json.loads(ws.recv())
            t1 = time.perf_counter()
    else:
        r = c.post(f"/v1/vehicles/{vid}/telemetry", json=before, headers=H)
        assert r.status_code == 200 and r.json()["health_version"] == 0, r.text
        t0 = time.perf_counter()
        r = c.post(f"/v1/vehicles/{vid}/telemetry", content=jam, headers={**H, "content-type": "application/json"})
        t1 = time.perf_counter()
        assert r.status_code == 200, r.text
        # the fast path: it never waited at the gate (a request that does has a "gate" phase)
        assert "app;dur=" in r.headers["server-timing"] and "gate;" not in r.headers["server-timing"]
        answer = r.json()
    (d,) = answer["detections"]
    assert (d["effector"], d["kind"], d["applied"]) == ("a", "jam", True) and answer["health_version"] == 1
    a = c.post(f"/v1/vehicles/{vid}/allocate", json={"v": [10.0, 4.0, 1.0], "method": "qp"})
    t2 = time.perf_counter()
    assert a.status_code == 200 and a.json()["health_version"] == 1, a.text
    assert a.json()["u"][0] == d["params"]["position"]  # the allocation holds the jam at its estimate
    return {"batch": (t1 - t0) * 1e3, "allocation": (t2 - t1) * 1e3}


def _rounds(server, seeds: range) -> dict[str, list[float]]:
    out: dict[str, list[float]] = {"batch": [], "allocation": []}
    with httpx.Client(base_url=server.url, timeout=30.0) as c:
        for seed in seeds:
            for websocket in (False, True):
                for kind, ms in _jam_round(c, server.url, seed, websocket).items():
                    out[kind].append(ms)
    return out


#: the flood's bodies (test_attacks.test_validation_error_flood's class): 60,000 bad
#: entries in a 0.3 MB batch body, and 40,000 unknown members
BAD_ROWS = json.dumps({"B": [[1.0] * 6] * 6, "umin": [-1.0] * 6, "umax": [1.0] * 6,
                       "V": [["x"] * 6 for _ in range(10_000)]})
MEMBERS = json.dumps({"B": [[1.0]], "umin": [-1.0], "umax": [1.0], "v": [0.0],
                      **{f"k{i}": 0 for i in range(40_000)}})
FLOOD = ((BAD_ROWS, "/v1/allocate/batch"), (MEMBERS, "/v1/allocate"))
#: the flights (small_flight seeds) of the floor and of the attack, one new vehicle each, HTTP and WebSocket
SEEDS = range(3)


@pytest.mark.slow  # a server of its own and two phases: 10-40 s (the attack suite's module has the default run's)
def test_a_silent_jam_in_a_telemetry_batch_is_held_during_a_validation_flood(server):
    """Same-run floor (test_attacks): the jam batch's answer and the first allocation after
    it, over HTTP and the WebSocket, p99 under the larger of the target scaled by the load and
    FLOOR_FACTOR x the floor, plus the one flood parse a priority request may wait for."""
    floor = _rounds(server, SEEDS)
    with httpx.Client(base_url=server.url, timeout=30.0) as c:
        alone = []
        for body, path in FLOOD * 2:
            t0 = time.perf_counter()
            assert c.post(path, content=body, headers={"content-type": "application/json"}).status_code == 422
            alone.append((time.perf_counter() - t0) * 1e3)

    def flood(stop: Any) -> list[int]:
        statuses = []
        with httpx.Client(base_url=server.url, timeout=60.0) as c:
            while not stop.is_set():
                for body, path in FLOOD:
                    statuses.append(c.post(path, content=body, headers={"content-type": "application/json"}
                                           ).status_code)
        return statuses
    with attack(flood, clients=4) as statuses:
        figures = _rounds(server, SEEDS)  # the floor's flights: the same detector work (it varies with the data)
    assert statuses and set(statuses) == {422}, set(statuses)
    s, allowance = slack(), PARSES_WAITED * max(alone)
    print(f"\ntelemetry jam under a validation flood ({len(statuses)} flood requests): "
          + ", ".join(f"{k} p50 {np.median(v):.1f} ms p99 {p99(v):.1f} ms (floor p99 {p99(floor[k]):.1f} ms)"
                      for k, v in figures.items()) + f"; flood request alone {max(alone):.1f} ms, slack {s:.1f}")
    for kind, target in (("batch", TARGETS_MS["event"]), ("allocation", TARGETS_MS["allocation"])):
        bound = max(target * s, FLOOR_FACTOR * p99(floor[kind])) + allowance
        assert p99(figures[kind]) < bound, (kind, figures[kind], bound)


@pytest.mark.slow  # a server of its own: 5-12 s
def test_websockets_do_not_keep_their_clients_connection_slots(tmp_path):
    """A WebSocket leaves the HTTP protocol at its upgrade: its per-client slot is released then,
    or a ground station reconnecting its stream ALLOC_MAX_CONNECTIONS_PER_CLIENT times would
    have every later connection (its events included) refused with 503."""
    from websockets.exceptions import InvalidStatus
    from websockets.sync.client import connect

    limit = 4
    proc = ServiceProcess(tmp_path, api_key=KEY, env={"ALLOC_MAX_CONNECTIONS_PER_CLIENT": str(limit),
                                                      "ALLOC_WARMUP": "false"}).start(timeout=300.0)
    try:
        with httpx.Client(base_url=proc.url, timeout=30.0) as c:
            vid = c.post("/v1/vehicles", json=SMALL, headers=H).json()["id"]
        url = proc.url.replace("http://", "ws://") + f"/v1/vehicles/{vid}/telemetry/ws"
        for _ in range(2 * limit):  # accepted streams, and refused ones, each on a new connection
            with connect(url, additional_headers=H, open_timeout=30.0):
                pass
            with pytest.raises(InvalidStatus) as refused:
                connect(url, additional_headers={"X-API-Key": "wrong"}, open_timeout=30.0)
            assert refused.value.response.status_code == 401
        for k in range(limit + 1):  # fresh connections: each needs a slot
            with httpx.Client(base_url=proc.url, timeout=30.0) as c:
                r = c.post(f"/v1/vehicles/{vid}/events", json={"effector": "a", "kind": "jam", "position": float(k)},
                           headers=H)
            assert r.status_code == 201, r.text
    finally:
        proc.stop()
