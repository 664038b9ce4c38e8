"""Do no harm in the service's telemetry: the model setting (learnt or exact), the detector's
withdrawals of its own detections (probation) as durable health events under policy auto and as
withdrawn proposals under confirm, and every detection saying how sure (confidence) and how much
better (improvement), both in [0, 1].

A false detection is fabricated the way a wrong isolation would leave it: the vehicle's stored
detector state is given a standing jam of effector ``a`` (through the library's own state:
``FailureDetector._emit``) and the vehicle's health that jam, as if the service had applied it;
then healthy telemetry follows."""

from __future__ import annotations

import math
import threading

import numpy as np
import pytest
from fastapi.testclient import TestClient
from sqlalchemy import insert, update

from alloc.estimation import Detection, FailureDetector
from alloc.health import FailureEvent, FailureKind
from service.config import Settings
from service.db import ProposalRow, TelemetryRow
from service.main import create_app
from service.telemetry import DetectorSettings, detection_out

from test_telemetry import H, KEY, SMALL, SMALL_SETTINGS, post, small_flight, small_vehicle

LN100 = math.log(100.0)


@pytest.fixture()
def app(tmp_path):
    return create_app(Settings(data_dir=tmp_path, warmup=False, api_key=KEY))


@pytest.fixture()
def client(app):
    with TestClient(app) as c:
        yield c


def healthy(seed: int, t0: float, n: int):
    rng = np.random.default_rng(seed)
    B = np.array(SMALL["B"])
    t = t0 + np.arange(n) * 0.1
    U = rng.uniform(-10, 10, (n, 4))
    return t, U, U @ B.T + rng.normal(0, 0.05, (n, 3))


def fabricate_false_jam(app, client, vid: str, policy: str) -> float:
    """30 healthy samples through the service, then a false jam of ``a`` at +8 standing in the
    stored detector (and, under auto, in the vehicle's health via a posted event; under
    confirm, as a pending proposal).  Returns the detection's time."""
    t, U, Y = healthy(1, 0.1, 30)
    assert post(client, vid, t, U, Y).status_code == 200
    store = app.state.store
    vehicle = store.get(vid)
    with store._sessions() as s:
        row = s.get(TelemetryRow, vid)
        state, config = dict(row.state), row.config
    segments = state.pop("segments")
    det = FailureDetector.from_dict(vehicle.nominal, state)
    false = Detection(event=FailureEvent("a", FailureKind.JAM, position=8.0), time=det.last_time,
                      onset=det.last_time - 0.3, statistic=30.0, threshold=20.0, confidence=0.99,
                      effector_confidence=0.99, kind_confidence=1.0, parameter=8.0, parameter_std=0.1, samples=4,
                      improvement=0.9)
    det._emit(false)
    version = vehicle.version
    if policy == "auto":
        r = client.post(f"/v1/vehicles/{vid}/events", json={"effector": "a", "kind": "jam", "position": 8.0}, headers=H)
        assert r.status_code == 201, r.text
        version = r.json()["health_version"] if "health_version" in r.json() else version + 1
    with store._sessions() as s:
        s.execute(update(TelemetryRow).where(TelemetryRow.vehicle_id == vid)
                  .values(state={**det.to_dict(), "segments": segments}, synced_version=version,
                          revision=TelemetryRow.revision + 1))
        if policy == "confirm":
            out = detection_out(false)
            s.execute(insert(ProposalRow).values(vehicle_id=vid, status="pending", effector="a", kind="jam",
                                                 params=out["params"], detection=out, health_version=version,
                                                 event_seq=None))
        s.commit()
    assert DetectorSettings.from_record(config).probation == 2.0
    return false.time


def test_put_model_settings_appear_in_get(client):
    vid = small_vehicle(client, model="learnt", model_uncertainty=0.5, probation=1.0)
    s = client.get(f"/v1/vehicles/{vid}/telemetry", headers=H).json()["settings"]
    assert (s["model"], s["model_uncertainty"], s["probation"]) == ("learnt", 0.5, 1.0)
    vid = small_vehicle(client)
    s = client.get(f"/v1/vehicles/{vid}/telemetry", headers=H).json()["settings"]
    assert (s["model"], s["model_uncertainty"], s["probation"]) == ("exact", 0.2, 2.0)  # the defaults


@pytest.mark.parametrize("field, value", [("model", "guessed"), ("model", None), ("model_uncertainty", 10.5),
                                          ("model_uncertainty", -0.1), ("model_uncertainty", "0.2"),
                                          ("probation", -1.0), ("probation", 4000.0), ("probation", True)])
def test_bad_model_settings_are_refused_naming_the_field(client, field, value):
    vid = client.post("/v1/vehicles", json=SMALL, headers=H).json()["id"]
    r = client.put(f"/v1/vehicles/{vid}/telemetry", json={**SMALL_SETTINGS, field: value}, headers=H)
    assert r.status_code == 422 and r.headers["content-type"].startswith("application/problem+json")
    assert any(e["pointer"] == f"/{field}" for e in r.json()["errors"]), r.text
    assert client.get(f"/v1/vehicles/{vid}/telemetry").status_code == 409  # nothing was configured


@pytest.mark.parametrize("model", ["exact", "learnt"])
def test_a_real_jam_says_how_sure_and_how_much_better(client, model):
    vid = small_vehicle(client, model=model)
    t, U, Y = small_flight(3, n=80)
    answers = [post(client, vid, t[i:i + 10], U[i:i + 10], Y[i:i + 10]).json() for i in range(0, 80, 10)]
    found = [d for a in answers for d in a["detections"]]
    assert [(d["effector"], d["kind"]) for d in found][:1] == [("a", "jam")], found
    for d in found:
        assert 0.0 <= d["confidence"] <= 1.0 and 0.0 <= d["improvement"] <= 1.0
    assert found[0]["improvement"] > 0.9  # a jam at 5 with commands over +-10: most of the residual is the jam
    assert [w for a in answers for w in a["withdrawals"]] == []  # a real jam stands
    assert client.get(f"/v1/vehicles/{vid}/health").json()["effectors"][0]["status"] == "jammed"


def test_auto_withdrawal_is_a_durable_event_restoring_the_health_before(app, client):
    vid = small_vehicle(client)
    t_det = fabricate_false_jam(app, client, vid, "auto")
    assert client.get(f"/v1/vehicles/{vid}/health").json()["effectors"][0]["status"] == "jammed"
    t, U, Y = healthy(2, t_det + 0.1, 30)
    answers = [post(client, vid, t[i:i + 5], U[i:i + 5], Y[i:i + 5]).json() for i in range(0, 30, 5)]
    ws = [w for a in answers for w in a["withdrawals"]]
    assert len(ws) == 1, answers
    w = ws[0]
    assert (w["effector"], w["kind"], w["detection_time"], w["applied"]) == ("a", "jam", t_det, True)
    assert w["reason"] == "evidence favours the health before the detection"
    assert w["statistic"] >= 2 * LN100 and t_det < w["time"] <= t_det + 2.0 + 1e-9
    assert w["event_seq"] == 2 and w["proposal_id"] is None
    health = client.get(f"/v1/vehicles/{vid}/health").json()
    assert health["health_version"] == 2 and health["effectors"][0]["status"] == "healthy"
    events = client.get(f"/v1/vehicles/{vid}/events").json()["items"]
    assert [(e["seq"], e["kind"]) for e in events] == [(1, "jam"), (2, "repair")]
    assert "withdrawn" in events[1]["note"] and "evidence favours" in events[1]["note"]
    got = client.get(f"/v1/vehicles/{vid}/telemetry").json()["withdrawals"]
    assert [(g["effector"], g["time"], g["statistic"]) for g in got] == [("a", w["time"], w["statistic"])]
    # durable: a new application on the same database sees the same
    again = create_app(Settings(data_dir=app.state.settings.data_dir, warmup=False, api_key=KEY))
    with TestClient(again) as c2:
        assert c2.get(f"/v1/vehicles/{vid}/health").json()["health_version"] == 2
        assert len(c2.get(f"/v1/vehicles/{vid}/telemetry").json()["withdrawals"]) == 1


def test_confirm_withdrawal_marks_the_pending_proposal_withdrawn(app, client):
    vid = small_vehicle(client, policy="confirm")
    t_det = fabricate_false_jam(app, client, vid, "confirm")
    (prop,) = client.get(f"/v1/vehicles/{vid}/proposals", params={"status": "pending"}).json()["items"]
    t, U, Y = healthy(2, t_det + 0.1, 30)
    answers = [post(client, vid, t[i:i + 5], U[i:i + 5], Y[i:i + 5]).json() for i in range(0, 30, 5)]
    ws = [w for a in answers for w in a["withdrawals"]]
    assert [(w["effector"], w["applied"], w["event_seq"], w["proposal_id"]) for w in ws] == [("a", False, None,
                                                                                            prop["id"])]
    (p,) = client.get(f"/v1/vehicles/{vid}/proposals", params={"status": "withdrawn"}).json()["items"]
    assert p["id"] == prop["id"] and p["decided_at"] is not None
    assert client.post(f"/v1/vehicles/{vid}/proposals/{p['id']}/accept", headers=H).status_code == 409
    health = client.get(f"/v1/vehicles/{vid}/health").json()
    assert health["health_version"] == 0 and health["effectors"][0]["status"] == "healthy"


def test_batches_and_events_interleaving_keep_one_event_sequence(app, client):
    """Two clients: one streams the healthy telemetry that withdraws the false jam, the other
    posts events on effector d meanwhile.  The event sequence is 1, 2, ... without gaps or
    repeats, the withdrawal's repair is in it once, and the health is the events replayed."""
    vid = small_vehicle(client)
    t_det = fabricate_false_jam(app, client, vid, "auto")
    t, U, Y = healthy(2, t_det + 0.1, 40)
    statuses: list[int] = []

    def events() -> None:
        for i in range(12):
            # reduced limits the commands (within +-10) never reach: the model of the data stays
            # right (a wrong one would leave the health before unfit, and nothing withdrawn)
            body = {"effector": "d", "kind": "limits", "lo": -24.0 + 0.1 * i, "hi": 24.0 - 0.1 * i}
            statuses.append(client.post(f"/v1/vehicles/{vid}/events", json=body, headers=H).status_code)

    other = threading.Thread(target=events)
    other.start()
    answers = [post(client, vid, t[i:i + 2], U[i:i + 2], Y[i:i + 2]) for i in range(0, 40, 2)]
    other.join()
    assert all(r.status_code == 200 for r in answers) and statuses == [201] * 12
    ws = [w for r in answers for w in r.json()["withdrawals"]]
    assert [w["effector"] for w in ws] == ["a"]
    items = client.get(f"/v1/vehicles/{vid}/events").json()["items"]
    assert [e["seq"] for e in items] == list(range(1, len(items) + 1))
    assert [e["kind"] for e in items if e["effector"] == "a"] == ["jam", "repair"]
    assert next(e["seq"] for e in items if e["kind"] == "repair") == ws[0]["event_seq"]
    health = client.get(f"/v1/vehicles/{vid}/health").json()
    assert health["health_version"] == len(items) == 14
    a, d = health["effectors"][0], health["effectors"][3]
    assert a["status"] == "healthy" and d["limits"] == pytest.approx([-24.0 + 1.1, 24.0 - 1.1])
