"""Telemetry time, duplicate keys, races with events and the schema's word (issue 39).

* Times are checked against the configured ``sample_time`` (``service/telemetry.py``): inside a
  batch a step is half a ``sample_time`` to one window, a batch reaching into time already
  received is refused naming ``t/i``, and a gap or a time never received starts a new segment
  (recorded in the answer).  A seeded generator of hostile times (far future, NaN, negative,
  non-monotonic, huge gaps, duplicates, subnormal steps, replays, ...) checks that each gets a
  4xx naming ``t`` or is accepted, and that a real jam flown afterwards is still detected: the
  issue's bar, since one far-future sample used to refuse every later batch for good.
* ``PUT ... {"reset": true}`` restarts the detector with the same settings.
* A key given twice is refused naming it, over HTTP and the WebSocket.
* Batches racing events on the same vehicle all get 200 and lose no detection (13 of 20 got
  409 before).
* A 405 lists in ``Allow`` every method the OpenAPI document gives the path.
"""

from __future__ import annotations

import json
import threading
from collections import Counter

import numpy as np
import pytest
from fastapi.testclient import TestClient

from service.config import Settings
from service.main import create_app
from service.telemetry import KEPT_SEGMENTS

from test_telemetry import H, KEY, SMALL, SMALL_SETTINGS, _snapshot, post, small_vehicle

DT = SMALL_SETTINGS["sample_time"]
WINDOW = SMALL_SETTINGS["window"]  # 4 samples: the longest step inside a batch, the gap that starts a segment
#: a jam flown after a hostile batch is decided within this many seconds of its onset (the
#: existing telemetry tests' stated delay)
DELAY_S = 0.5
#: the real stream's samples before the jam: the buffers refill after a new segment (4 samples)
JAM_AFTER = 10


@pytest.fixture()
def client(tmp_path):
    with TestClient(create_app(Settings(data_dir=tmp_path, warmup=False, api_key=KEY))) as c:
        yield c


def flight(rng: np.random.Generator, t: np.ndarray, jam_from: float | None = None, position: float = 5.0):
    """Commands and measured responses of SMALL at times ``t``; effector ``a`` held at
    ``position`` from ``jam_from``; noise 0.05, as configured."""
    B = np.array(SMALL["B"])
    U = rng.uniform(-10, 10, (len(t), 4))
    actual = U.copy()
    if jam_from is not None:
        actual[t >= jam_from - 1e-9, 0] = position
    return U, actual @ B.T + rng.normal(0, 0.05, (len(t), 3))


def body_of(t, U, Y) -> dict:
    return {"t": [float(x) for x in t], "u": np.asarray(U).tolist(), "y": np.asarray(Y).tolist()}


# ------------------------------------------------------------------------ hostile times
#: the classes of hostile times; each case is one batch sent after the real stream's last sample
CLASSES = ("far_future", "far_future_inside", "nan", "infinity", "beyond_1e9", "negative_batch", "negative_inside",
           "back_inside", "duplicate_inside", "subnormal_step", "tiny_step", "huge_gap_inside", "replay",
           "overlap_last", "too_soon", "gap_batch", "string_time", "unseen_before")


def hostile_times(seed: int, t_last: float, t_first: float) -> tuple[str, str]:
    """One hostile batch's JSON (its ``t`` hostile, ``u`` and ``y`` well formed) and its class,
    for a vehicle whose samples so far run from ``t_first`` to ``t_last``."""
    rng = np.random.default_rng(seed)
    cls = CLASSES[seed % len(CLASSES)] if seed < len(CLASSES) else CLASSES[int(rng.integers(len(CLASSES)))]
    n = int(rng.integers(1, 6))
    t = t_last + DT * np.arange(1, n + 1)
    token = None
    i = int(rng.integers(1, max(n, 2)))
    if cls == "far_future":  # milliseconds sent as seconds, and worse: up to the 1e9 cap
        t = t_last + 10.0 ** rng.uniform(2, 8.9) + DT * np.arange(n)
    elif cls == "far_future_inside":
        t = t_last + DT * np.arange(1, max(n, 2) + 1)
        t[i:] += 10.0 ** rng.uniform(1, 8)
    elif cls in ("nan", "infinity"):
        token = "NaN" if cls == "nan" else ["Infinity", "-Infinity"][int(rng.integers(2))]
    elif cls == "beyond_1e9":
        t = t + 10.0 ** rng.uniform(9.1, 300)
    elif cls == "negative_batch":  # a whole batch in negative time, never received
        t = -10.0 ** rng.uniform(0, 8) + DT * np.arange(n)
    elif cls == "negative_inside":
        t = t_last + DT * np.arange(1, max(n, 2) + 1)
        t[i] = -abs(t[i]) - rng.uniform(0, 1e6)
    elif cls == "back_inside":  # non-monotonic
        t = t_last + DT * np.arange(1, max(n, 2) + 1)
        t[i] = t[i - 1] - rng.uniform(0, 5)
    elif cls == "duplicate_inside":
        t = t_last + DT * np.arange(1, max(n, 2) + 1)
        t[i] = t[i - 1]
    elif cls == "subnormal_step":
        t = t_last + DT * np.arange(1, max(n, 2) + 1)
        t[i] = np.nextafter(t[i - 1], np.inf) if rng.random() < 0.5 else t[i - 1] + 5e-324 * rng.integers(1, 9)
    elif cls == "tiny_step":  # a stream faster than configured
        t = t_last + DT * np.arange(1, max(n, 2) + 1)
        t[i] = t[i - 1] + DT * rng.uniform(1e-6, 0.49)
    elif cls == "huge_gap_inside":
        t = t_last + DT * np.arange(1, max(n, 2) + 1)
        t[i:] += WINDOW * rng.uniform(1.01, 1e6)
    elif cls == "replay":  # a batch of the last 2 s received, again (a client's retry)
        start = rng.uniform(max(t_first, t_last - 2.0), max(t_first, t_last - n * DT))
        t = start + DT * np.arange(n)
    elif cls == "overlap_last":
        t = t_last - DT * rng.integers(0, 3) + DT * np.arange(n)
    elif cls == "too_soon":  # less than half a sample time after the last one
        t = t_last + DT * rng.uniform(0, 0.49) + DT * np.arange(n)
    elif cls == "gap_batch":  # a gap longer than the window: a new segment
        t = t_last + WINDOW * rng.uniform(1.01, 100) + DT * np.arange(n)
    elif cls == "unseen_before":  # before everything received (a clock restarted)
        t = t_first - rng.uniform(1, 1e5) - DT * np.arange(n)[::-1]
    U, Y = flight(rng, np.asarray(t, dtype=float))
    body = body_of(t, U, Y)
    if cls == "string_time":
        body["t"][int(rng.integers(n))] = ["1.5", True, None, [1.0]][int(rng.integers(4))]
    raw = json.dumps(body)
    if token is not None:
        raw = raw.replace(json.dumps(body["t"][i % n]), token, 1)
    return raw, cls


def _telemetry_state(client, vid):
    return client.get(f"/v1/vehicles/{vid}/telemetry").json()


def run_hostile_times(client, seeds) -> dict[str, Counter]:
    """Each seed: a hostile batch, then the real stream goes on with a jam of ``a`` that must be
    decided within :data:`DELAY_S` (and is repaired for the next seed).  Returns the outcomes
    per class."""
    vid = small_vehicle(client, policy="auto")
    rng = np.random.default_rng(12345)
    outcomes: dict[str, Counter] = {}
    # a real start: 2 s of healthy samples
    t = np.arange(1, 21) * DT
    U, Y = flight(rng, t)
    assert post(client, vid, t, U, Y).status_code == 200
    t_first, t_last = float(t[0]), float(t[-1])
    for seed in seeds:
        raw, cls = hostile_times(seed, t_last, t_first)
        before = _snapshot(client, vid)
        r = client.post(f"/v1/vehicles/{vid}/telemetry", content=raw.encode(),
                        headers={**H, "Content-Type": "application/json"})
        outcome = outcomes.setdefault(cls, Counter())
        if r.status_code == 200:
            answer = r.json()
            outcome[f"accepted ({answer['segment'] or 'continued'})"] += 1
            assert answer["detections"] == [], (seed, cls, answer)  # a healthy flight: nothing to find
        else:
            assert 400 <= r.status_code < 500, (seed, cls, r.status_code, r.text[:300])
            problem = r.json()
            named = [e["pointer"] or "" for e in problem["errors"]] + [problem["detail"]]
            assert any(x.startswith("/t") or x.startswith("t") for x in named), (seed, cls, problem)
            assert _snapshot(client, vid) == before, (seed, cls)  # a refused batch changes nothing
            outcome[f"{r.status_code}"] += 1
        # the real stream goes on where it was (its clock never saw the hostile batch): 3 s in
        # batches of 5 samples, a jam of ``a`` from its 10th sample; never poisoned
        t = t_last + DT * np.arange(1, 31)
        onset = float(t[JAM_AFTER])
        position = float(rng.uniform(-20, 20))
        U, Y = flight(rng, t, jam_from=onset, position=position)
        found = []
        for k in range(0, len(t), 5):
            r = post(client, vid, t[k:k + 5], U[k:k + 5], Y[k:k + 5])
            assert r.status_code == 200, (seed, cls, r.text[:600])
            found += r.json()["detections"]
        assert [(d["effector"], d["kind"]) for d in found] == [("a", "jam")], (seed, cls, found)
        assert 0.0 <= found[0]["time"] - onset <= DELAY_S, (seed, cls, found[0]["time"], onset)
        estimate, std = found[0]["params"]["position"], found[0]["evidence"]["parameter_std"]
        # 5 of its standard deviations: over the slow run's 1,000 jams, 4 were exceeded once (seed
        # 1899, 4.15 std, after a refused batch: an estimate's tail, not the hostile time)
        assert abs(estimate - position) <= max(5 * std, 0.05), (seed, cls, estimate, std, position)
        assert client.post(f"/v1/vehicles/{vid}/events", json={"effector": "a", "kind": "repair"},
                           headers=H).status_code == 201
        t_last = float(t[-1])
    return outcomes


def _report(outcomes: dict[str, Counter]) -> str:
    return "\n".join(f"  {cls:<18} {dict(sorted(c.items()))}" for cls, c in sorted(outcomes.items()))


def test_hostile_times_get_a_4xx_naming_t_or_are_accepted_and_a_later_jam_is_detected(client):
    outcomes = run_hostile_times(client, range(len(CLASSES) + 6))
    print("\nhostile times (default run):\n" + _report(outcomes))
    assert set(outcomes) == set(CLASSES)
    # the classes whose fate is fixed: refused ones never accepted, segment starts never refused
    for cls in ("nan", "infinity", "beyond_1e9", "string_time", "negative_inside", "back_inside",
                "duplicate_inside", "subnormal_step", "tiny_step", "huge_gap_inside", "far_future_inside",
                "replay", "overlap_last", "too_soon"):
        assert not any(k.startswith("accepted") for k in outcomes[cls]), (cls, outcomes[cls])
    for cls, why in (("far_future", "gap"), ("gap_batch", "gap"), ("negative_batch", "unseen_time"),
                     ("unseen_before", "unseen_time")):
        assert set(outcomes[cls]) == {f"accepted ({why})"}, (cls, outcomes[cls])


@pytest.mark.slow
def test_hostile_times_many_seeds(client):
    outcomes = run_hostile_times(client, range(1000, 2000))
    print("\nhostile times (slow run, 1,000 seeds):\n" + _report(outcomes))
    assert sum(sum(c.values()) for c in outcomes.values()) == 1000


# ------------------------------------------------------------------------ segments, reset
def test_far_future_sample_no_longer_poisons_the_detector(client):
    """The issue's scenario: one sample 1.7e8 s ahead (milliseconds sent as seconds), then
    the real stream with a jam.  Before: every later batch 422 'out of order', the jam never
    detected.  Now: the far-future batch starts a segment, the real stream another (time never
    received), and the jam is decided as on a clean detector."""
    vid = small_vehicle(client)
    rng = np.random.default_rng(7)
    t = np.arange(1, 21) * DT
    U, Y = flight(rng, t)
    first = post(client, vid, t, U, Y).json()
    assert first["segment"] == "first" and first["segments"] == 1
    U1, Y1 = flight(rng, np.array([2.1e3 * 1e5]))
    far = post(client, vid, [2.1e8], U1, Y1).json()
    assert far["segment"] == "gap" and far["last_time"] == 2.1e8
    t = 2.0 + DT * np.arange(1, 31)
    U, Y = flight(rng, t, jam_from=float(t[JAM_AFTER]))
    answers = [post(client, vid, t[k:k + 5], U[k:k + 5], Y[k:k + 5]) for k in range(0, 30, 5)]
    assert [r.status_code for r in answers] == [200] * 6
    assert answers[0].json()["segment"] == "unseen_time" and answers[1].json()["segment"] is None
    (d,) = [d for r in answers for d in r.json()["detections"]]
    assert (d["effector"], d["kind"]) == ("a", "jam") and 0 <= d["time"] - t[JAM_AFTER] <= DELAY_S
    state = _telemetry_state(client, vid)
    assert state["segments"] == 3 and state["health_version"] == 1 and state["samples"] == 20 + 1 + 30


def test_a_repeat_is_refused_naming_the_sample_and_a_gap_starts_a_segment(client):
    vid = small_vehicle(client)
    rng = np.random.default_rng(8)
    t = np.arange(1, 11) * DT
    U, Y = flight(rng, t)
    assert post(client, vid, t, U, Y).status_code == 200
    before = _snapshot(client, vid)
    # a retried batch, and one that starts before and runs into what was received
    for times, index in ((t[3:6], 0), (np.arange(-2, 3) * DT, 3)):
        r = post(client, vid, times, U[:len(times)], Y[:len(times)])
        assert r.status_code == 422 and r.json()["errors"][0]["pointer"] == f"/t/{index}", r.text
        assert "already received" in r.json()["detail"]
    assert _snapshot(client, vid) == before
    # a gap of more than one window (0.4 s) starts a segment; within it, the segment goes on
    for gap, segment in ((WINDOW, None), (WINDOW + DT, "gap")):
        start = _telemetry_state(client, vid)["last_time"] + gap
        r = post(client, vid, [start, start + DT], U[:2], Y[:2])
        assert r.status_code == 200 and r.json()["segment"] == segment, (gap, r.text)
    # inside a batch a gap is refused, naming the sample after it
    start = _telemetry_state(client, vid)["last_time"] + DT
    r = post(client, vid, [start, start + DT, start + DT + WINDOW * 1.5], U[:3], Y[:3])
    assert r.status_code == 422 and r.json()["errors"][0]["pointer"] == "/t/2" and "one window" in r.text


def test_kept_segments_are_bounded_and_time_before_the_last_forgets_what_came_after(client):
    """The state remembers the last KEPT_SEGMENTS segments' times, no more; a segment starting
    before the last sample (the clock went back) forgets the time received after its start."""
    from service.db import TelemetryRow

    def kept():
        with client.app.state.store._sessions() as s:
            return s.get(TelemetryRow, vid).state["segments"]["kept"]
    vid = small_vehicle(client)
    rng = np.random.default_rng(9)
    U, Y = flight(rng, np.zeros(1))
    starts = [10.0 * (i + 1) for i in range(KEPT_SEGMENTS + 1)]
    for s in starts:
        assert post(client, vid, [s], U, Y).json()["segment"] in ("first", "gap")
    for s in starts[-KEPT_SEGMENTS:]:  # remembered: a repeat
        assert post(client, vid, [s], U, Y).status_code == 422
    assert kept() == [[s, s] for s in starts[1:]]
    r = post(client, vid, [starts[0]], U, Y)  # forgotten: new time, before the last sample
    assert r.status_code == 200 and r.json()["segment"] == "unseen_time" and r.json()["segments"] == len(starts) + 1
    assert kept() == [[starts[0], starts[0]]]
    r = post(client, vid, [starts[-1]], U, Y)  # after a clock gone back, that time is new again
    assert r.status_code == 200 and r.json()["segment"] == "gap"


def test_put_reset_restarts_the_detector_with_the_same_settings(client):
    vid = small_vehicle(client)
    rng = np.random.default_rng(10)
    t = np.arange(1, 11) * DT
    U, Y = flight(rng, t)
    assert post(client, vid, t, U, Y).status_code == 200
    url = f"/v1/vehicles/{vid}/telemetry"
    # the same settings (a policy change alone) keep the state, as documented
    same = client.put(url, json={**SMALL_SETTINGS, "policy": "confirm"}, headers=H).json()
    assert same["samples"] == 10 and same["segments"] == 1
    reset = client.put(url, json={**SMALL_SETTINGS, "policy": "confirm", "reset": True}, headers=H).json()
    assert reset["samples"] == 0 and reset["segments"] == 0 and reset["last_time"] is None
    assert reset["revision"] == same["revision"] + 1 and "reset" not in reset["settings"]
    # the same times are new to the new detector
    r = post(client, vid, t, U, Y)
    assert r.status_code == 200 and r.json()["segment"] == "first"
    assert client.put(url, json={**SMALL_SETTINGS, "reset": "yes"}, headers=H).status_code == 422


# ------------------------------------------------------------------------ duplicate keys
def test_a_key_given_twice_is_refused_naming_it_over_http_and_the_websocket(client):
    vid = small_vehicle(client)
    before = _snapshot(client, vid)
    raws = {"/t": '{"t": [1.0], "u": [[0, 0, 0, 0]], "y": [[0, 0, 0]], "t": [2.0]}',
            "/u": '{"u": [[1, 1, 1, 1]], "t": [1.0], "u": [[0, 0, 0, 0]], "y": [[0, 0, 0]]}'}
    for pointer, raw in raws.items():
        r = client.post(f"/v1/vehicles/{vid}/telemetry", content=raw, headers={**H, "Content-Type": "application/json"})
        assert r.status_code == 422 and r.json()["errors"][0]["pointer"] == pointer, r.text
    with client.websocket_connect(f"/v1/vehicles/{vid}/telemetry/ws", headers=H) as ws:
        for pointer, raw in raws.items():
            ws.send_text(raw)
            answer = json.loads(ws.receive_text())
            assert answer["status"] == 422 and answer["errors"][0]["pointer"] == pointer, answer
    assert _snapshot(client, vid) == before
    # every JSON body: an event's kind given twice, a nested key in a vehicle; a colon in a string is no key
    r = client.post(f"/v1/vehicles/{vid}/events", content='{"effector": "a", "kind": "jam", "position": 1, '
                    '"kind": "repair"}', headers={**H, "Content-Type": "application/json"})
    assert r.status_code == 422 and r.json()["errors"][0]["pointer"] == "/kind"
    r = client.post(f"/v1/vehicles/{vid}/events", json={"effector": "a", "kind": "jam", "position": 1.0,
                                                        "note": "k: v, \"x\": 1"}, headers=H)
    assert r.status_code == 201, r.text
    r = client.post("/v1/allocate", content=json.dumps({**{k: SMALL[k] for k in ("B", "umin", "umax")},
                                                        "v": [1.0, 0.0, 0.0]})[:-1] + ', "options": {"a": 1, "a": 2}}',
                    headers={"Content-Type": "application/json"})
    assert r.status_code == 422 and r.json()["errors"][0]["pointer"] == "/options/a", r.text


# ------------------------------------------------------------------------ races with events
def test_batches_racing_events_all_succeed_and_the_jam_is_detected(client):
    """The issue's client: 20 batches, no retries, while two threads post events on the same
    vehicle (effectiveness of ``d`` set and repaired).  Every batch 200, the jam applied."""
    vid = small_vehicle(client)
    rng = np.random.default_rng(11)
    t = np.arange(1, 401) * DT
    onset = float(t[150])
    U, Y = flight(rng, t, jam_from=onset)
    stop = threading.Event()
    posted = Counter()

    def events():
        i = 0
        while not stop.is_set():
            body = {"effector": "d", "kind": "effectiveness", "fraction": 0.5} if i % 2 == 0 else \
                {"effector": "d", "kind": "repair"}
            posted[client.post(f"/v1/vehicles/{vid}/events", json=body, headers=H).status_code] += 1
            i += 1
    threads = [threading.Thread(target=events) for _ in range(2)]
    for th in threads:
        th.start()
    try:
        answers = [post(client, vid, t[k:k + 20], U[k:k + 20], Y[k:k + 20]) for k in range(0, 400, 20)]
    finally:
        stop.set()
        for th in threads:
            th.join()
    statuses = Counter(r.status_code for r in answers)
    print(f"\nbatches racing {sum(posted.values())} events: {dict(statuses)}")
    assert statuses == {200: 20} and set(posted) == {201} and sum(posted.values()) >= 20
    found = [(d["effector"], d["kind"]) for r in answers for d in r.json()["detections"]]
    assert ("a", "jam") in found
    state = _telemetry_state(client, vid)
    assert state["samples"] == 400
    seqs = [e["seq"] for e in client.get(f"/v1/vehicles/{vid}/events").json()["items"]]
    assert seqs == list(range(1, len(seqs) + 1))  # one history, contiguous


def test_a_detection_meeting_an_event_at_every_run_is_recorded_after_it(client, monkeypatch):
    """Deterministic race: an event commits during every run of the batch that decides a jam.
    After the bounded runs the detection is recorded after the events (no 409, nothing lost)."""
    import service.telemetry_store as telemetry_store
    from service.schemas import EventIn
    from pydantic import TypeAdapter

    vid = small_vehicle(client)
    rng = np.random.default_rng(12)
    t = np.arange(1, 41) * DT
    U, Y = flight(rng, t, jam_from=float(t[20]))
    assert post(client, vid, t[:20], U[:20], Y[:20]).status_code == 200
    real = telemetry_store.run_batch
    runs = []
    store = client.app.state.store
    # nominal limits: the health version moves, the model does not (nothing else to detect)
    event = TypeAdapter(EventIn).validate_python({"effector": "d", "kind": "limits", "lo": -25.0, "hi": 25.0})

    def racing(*args):
        runs.append(1)
        out = real(*args)
        store.record_event(vid, event)  # commits while the batch is "running"
        return out
    monkeypatch.setattr(telemetry_store, "run_batch", racing)
    r = post(client, vid, t[20:], U[20:], Y[20:])
    assert r.status_code == 200, r.text
    (d,) = r.json()["detections"]
    assert (d["effector"], d["kind"], d["applied"]) == ("a", "jam", True)
    assert len(runs) == telemetry_store._MAX_RUNS and d["event_seq"] == len(runs) + 1
    kinds = [(e["seq"], e["kind"]) for e in client.get(f"/v1/vehicles/{vid}/events").json()["items"]]
    assert kinds == [(1, "limits"), (2, "limits"), (3, "limits"), (4, "jam")]


# ------------------------------------------------------------------------ 405
def test_405_allow_lists_every_method_of_the_path(client):
    paths = client.get("/openapi.json").json()["paths"]
    checked = 0
    for template, operations in paths.items():
        path = template.replace("{vehicle_id}", "abc").replace("{pid}", "1").replace("{name}", "qp")
        declared = {m.upper() for m in operations}
        for method in {"GET", "POST", "PUT", "DELETE", "PATCH"} - declared:
            r = client.request(method, path)
            assert r.status_code == 405, (method, path, r.status_code)
            assert set(r.headers["allow"].split(", ")) == declared, (method, path, r.headers["allow"])
            checked += 1
    assert checked > 40
