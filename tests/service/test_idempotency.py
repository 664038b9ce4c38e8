"""Idempotent writes: a retried event or vehicle creation (same ``Idempotency-Key``) happens once.

Same key and body -> the first answer, byte for byte (``Idempotent-Replayed: true``); same key,
another body -> 409; the key and its answer are committed in the write's own transaction, so
the promise holds across processes on one database and across a SIGKILL between the commit
and the answer (fault injected with ``ALLOC_FAILPOINT=after-commit``).
"""

from __future__ import annotations

import threading

import httpx
import numpy as np
import pytest
from fastapi.testclient import TestClient

from alloc.vehicles import ice
from service.config import Settings
from service.main import create_app
from service.process import ServiceProcess
from service_backends import BACKENDS, database_url

KEY = "idem-key"
H = {"X-API-Key": KEY}


def settings(tmp_path, url=None) -> Settings:
    return Settings(data_dir=tmp_path, api_key=KEY, warmup=False, database_url=url)


@pytest.fixture(params=BACKENDS)
def url(request, tmp_path):
    return database_url(request.param)


def new_vehicle(c) -> str:
    r = c.post("/v1/vehicles", json=ice().to_dict(), headers=H)
    assert r.status_code == 201, r.text
    return r.json()["id"]


def history(c, vid: str) -> list[dict]:
    return c.get(f"/v1/vehicles/{vid}/events").json()["items"]


def test_retried_event_is_recorded_once_and_answered_the_same(tmp_path, url):
    with TestClient(create_app(settings(tmp_path, url))) as c:
        vid = new_vehicle(c)
        jam = {"effector": "elevon_l", "kind": "jam", "position": 2.0}
        first = c.post(f"/v1/vehicles/{vid}/events", json=jam, headers={**H, "Idempotency-Key": "e-1"})
        again = c.post(f"/v1/vehicles/{vid}/events", json=jam, headers={**H, "Idempotency-Key": "e-1"})
        assert (first.status_code, again.status_code) == (201, 201)
        assert again.content == first.content and again.headers["idempotent-replayed"] == "true"
        assert "idempotent-replayed" not in first.headers
        assert [e["seq"] for e in history(c, vid)] == [1]
        other = c.post(f"/v1/vehicles/{vid}/events", json={**jam, "position": 3.0},
                       headers={**H, "Idempotency-Key": "e-1"})
        assert other.status_code == 409 and other.json()["errors"][0]["loc"] == ["header", "Idempotency-Key"]
        assert [e["seq"] for e in history(c, vid)] == [1]
        # no key: every request is a new write
        for _ in range(2):
            assert c.post(f"/v1/vehicles/{vid}/events", json=jam, headers=H).status_code == 201
        assert [e["seq"] for e in history(c, vid)] == [1, 2, 3]


def test_retried_creation_makes_one_vehicle(tmp_path, url):
    with TestClient(create_app(settings(tmp_path, url))) as c:
        body = {**ice().to_dict(), "name": "once"}
        a = c.post("/v1/vehicles", json=body, headers={**H, "Idempotency-Key": "v-1"})
        b = c.post("/v1/vehicles", json=body, headers={**H, "Idempotency-Key": "v-1"})
        assert a.status_code == b.status_code == 201 and a.content == b.content
        assert a.headers["location"] == b.headers["location"] == f"/v1/vehicles/{a.json()['id']}"
        assert c.get("/v1/vehicles").json()["total"] == 1
        assert c.post("/v1/vehicles", json={**body, "name": "twice"},
                      headers={**H, "Idempotency-Key": "v-1"}).status_code == 409
        assert c.get("/v1/vehicles").json()["total"] == 1


def test_a_key_is_scoped_to_its_endpoint(tmp_path):
    with TestClient(create_app(settings(tmp_path))) as c:
        v1, v2 = new_vehicle(c), new_vehicle(c)
        jam = {"effector": 0, "kind": "jam", "position": 1.0}
        for vid in (v1, v2):
            r = c.post(f"/v1/vehicles/{vid}/events", json=jam, headers={**H, "Idempotency-Key": "shared"})
            assert r.status_code == 201 and "idempotent-replayed" not in r.headers
        assert len(history(c, v1)) == len(history(c, v2)) == 1


@pytest.mark.parametrize("key", ["", "has space", "x" * 256, "tab\there", "\x7f"])
def test_malformed_keys_are_422_naming_the_header(tmp_path, key):
    with TestClient(create_app(settings(tmp_path))) as c:
        vid = new_vehicle(c)
        r = c.post(f"/v1/vehicles/{vid}/events", json={"effector": 0, "kind": "float"},
                   headers={**H, "Idempotency-Key": key})
        assert r.status_code == 422, r.text
        assert r.json()["errors"][0]["loc"] == ["header", "Idempotency-Key"]
        assert history(c, vid) == []


def test_concurrent_retries_write_once(tmp_path, url):
    """Eight clients send the same keyed event at once: one event, eight identical answers."""
    with TestClient(create_app(settings(tmp_path, url))) as c:
        vid = new_vehicle(c)
        answers: list[httpx.Response] = []
        start = threading.Barrier(8)

        def send() -> None:
            start.wait()
            answers.append(c.post(f"/v1/vehicles/{vid}/events", json={"effector": 1, "kind": "float"},
                                  headers={**H, "Idempotency-Key": "race"}))
        threads = [threading.Thread(target=send) for _ in range(8)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        assert [r.status_code for r in answers] == [201] * 8
        assert len({r.content for r in answers}) == 1
        assert sum("idempotent-replayed" not in r.headers for r in answers) == 1
        assert [e["seq"] for e in history(c, vid)] == [1]


def test_seeded_hostile_retries_match_a_model(tmp_path):
    """Random (key, body) sequences from small pools: every key's first body is written once and
    replayed byte for byte; another body with a used key is 409; the history is exactly the keys."""
    rng = np.random.default_rng(23)
    with TestClient(create_app(settings(tmp_path))) as c:
        vid = new_vehicle(c)
        bodies = [{"effector": int(j), "kind": "jam", "position": float(p)}
                  for j, p in zip(rng.integers(0, 11, 6), rng.uniform(-5, 5, 6))]
        first: dict[str, tuple[int, bytes]] = {}
        for step in range(60):
            key, b = f"k{rng.integers(0, 12)}", int(rng.integers(0, len(bodies)))
            r = c.post(f"/v1/vehicles/{vid}/events", json=bodies[b], headers={**H, "Idempotency-Key": key})
            if key not in first:
                assert r.status_code == 201, (step, r.text)
                first[key] = (b, r.content)
            elif first[key][0] == b:
                assert r.status_code == 201 and r.content == first[key][1], step
            else:
                assert r.status_code == 409, (step, r.text)
        assert len(history(c, vid)) == len(first)


def test_key_holds_across_processes_on_one_database(tmp_path):
    """A key written through one process is replayed by another (workers, replicas, a restart)."""
    with TestClient(create_app(settings(tmp_path))) as a, TestClient(create_app(settings(tmp_path))) as b:
        vid = new_vehicle(a)
        jam = {"effector": 2, "kind": "jam", "position": 0.5}
        ra = a.post(f"/v1/vehicles/{vid}/events", json=jam, headers={**H, "Idempotency-Key": "across"})
        rb = b.post(f"/v1/vehicles/{vid}/events", json=jam, headers={**H, "Idempotency-Key": "across"})
        assert ra.status_code == rb.status_code == 201 and ra.content == rb.content
        assert rb.headers["idempotent-replayed"] == "true" and len(history(b, vid)) == 1


def test_retry_after_sigkill_between_commit_and_answer(tmp_path):
    """The server commits the keyed event and is SIGKILLed before answering; the client's retry
    to the restarted server gets the original answer and the event is recorded once."""
    data = tmp_path / "data"
    with ServiceProcess(data, api_key=KEY, env={"ALLOC_WARMUP": "false"}) as server:
        with httpx.Client(base_url=server.url, timeout=30.0) as c:
            vid = new_vehicle(c)
    jam = {"effector": "elevon_l", "kind": "jam", "position": 4.0}
    crashing = ServiceProcess(data, api_key=KEY, env={"ALLOC_WARMUP": "false", "ALLOC_FAILPOINT": "after-commit"})
    with crashing:
        with httpx.Client(base_url=crashing.url, timeout=30.0) as c, pytest.raises(httpx.TransportError):
            c.post(f"/v1/vehicles/{vid}/events", json=jam, headers={**H, "Idempotency-Key": "after-kill"})
        crashing.proc.wait(timeout=10)
        assert crashing.proc.returncode == -9  # killed after the commit, before any answer
    with ServiceProcess(data, api_key=KEY, env={"ALLOC_WARMUP": "false"}) as server:
        with httpx.Client(base_url=server.url, timeout=30.0) as c:
            r = c.post(f"/v1/vehicles/{vid}/events", json=jam, headers={**H, "Idempotency-Key": "after-kill"})
            assert r.status_code == 201 and r.headers["idempotent-replayed"] == "true"
            assert r.json()["event"]["seq"] == 1 and r.json()["health"]["effectors"][0]["status"] == "jammed"
            assert [e["seq"] for e in history(c, vid)] == [1]
            r = c.post(f"/v1/vehicles/{vid}/events", json={**jam, "position": 5.0},
                       headers={**H, "Idempotency-Key": "after-kill"})
            assert r.status_code == 409
