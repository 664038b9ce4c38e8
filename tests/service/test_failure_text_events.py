"""Service events in the library's failure grammar: ``{"failure": "jam:elevon_l@5"}`` is the same
event as its fields, every recorded event carries its text, and bad text is a 422 naming ``failure``."""

from __future__ import annotations

import numpy as np
import pytest
from fastapi.testclient import TestClient

from alloc import vehicles
from alloc.failure_grammar import parse_failure

KEY = "k3y"
H = {"X-API-Key": KEY}


@pytest.fixture
def client(tmp_path):
    from service.config import Settings
    from service.main import create_app

    with TestClient(create_app(Settings(data_dir=tmp_path, api_key=KEY, warmup=False))) as c:
        yield c


def _vehicle(client) -> str:
    r = client.post("/v1/vehicles", json={**vehicles.problem("ice").to_dict(), "name": "ice"}, headers=H)
    assert r.status_code == 201, r.text
    return r.json()["id"]


def test_text_and_fields_record_the_same_event(client):
    by_text, by_fields = _vehicle(client), _vehicle(client)
    pairs = [
        ({"failure": "jam:elevon_l@-5", "note": "hydraulics"},
         {"effector": "elevon_l", "kind": "jam", "position": -5.0, "note": "hydraulics"}),
        ({"failure": "hardover:lef_l"}, {"effector": "lef_l", "kind": "hardover"}),
        ({"failure": "limits:pitch_tv@-5:5"}, {"effector": "pitch_tv", "kind": "limits", "lo": -5.0, "hi": 5.0}),
        ({"failure": "effectiveness:yaw_tv@0.5"}, {"effector": "yaw_tv", "kind": "effectiveness", "fraction": 0.5}),
        ({"failure": "repair:elevon_l"}, {"effector": "elevon_l", "kind": "repair"}),
    ]
    for text, fields in pairs:
        a = client.post(f"/v1/vehicles/{by_text}/events", json=text, headers=H)
        b = client.post(f"/v1/vehicles/{by_fields}/events", json=fields, headers=H)
        assert a.status_code == b.status_code == 201, (a.text, b.text)
        ea, eb = a.json()["event"], b.json()["event"]
        assert {k: ea[k] for k in ("effector", "kind", "params", "note", "failure")} == \
            {k: eb[k] for k in ("effector", "kind", "params", "note", "failure")}
        assert a.json()["health"]["effectors"] == b.json()["health"]["effectors"]
    texts = [e["failure"] for e in client.get(f"/v1/vehicles/{by_fields}/events").json()["items"]]
    # the hard-over records the stop it ran to; every text reads back as its event
    assert texts == ["jam:elevon_l@-5", "hardover:lef_l@40", "limits:pitch_tv@-5:5", "effectiveness:yaw_tv@0.5",
                     "repair:elevon_l"]
    for text in texts:
        parse_failure(text, vehicles.problem("ice").names)
    u = client.post(f"/v1/vehicles/{by_text}/allocate", json={"v": [1.0, 5.0, 0.1], "method": "qp"}).json()["u"]
    assert np.isfinite(u).all() and u[7] == 40.0  # lef_l at its hard-over stop


@pytest.mark.parametrize("body, pointer, says", [
    ({"failure": "jam:elevon_l@nan"}, None, "failure: 'jam:elevon_l@nan': position 'nan' is not a finite number"),
    ({"failure": "warp:elevon_l"}, None, "unknown kind 'warp'"),
    ({"failure": ""}, None, "failure: empty"),
    ({"failure": 5}, None, "failure: expected text"),
    ({"failure": "jam:elevon_l@" + "9" * 5000}, None, "at most 4096"),
    ({"failure": "float:elevon_l+float:lef_l"}, None, "an event is one"),
    ({"failure": "bandwidth:elevon_l@3"}, None, "simulator only"),
    ({"failure": "float:elevon_l", "kind": "float"}, None, "not both"),
    ({"failure": "jam:de3@1"}, "/effector", "unknown name 'de3'"),
    ({"failure": "jam:elevon_l@45"}, "/position", "outside its nominal limits"),
])
def test_bad_text_is_a_422_naming_the_field(client, body, pointer, says):
    vid = _vehicle(client)
    r = client.post(f"/v1/vehicles/{vid}/events", json=body, headers=H)
    assert r.status_code == 422, r.text
    errors = r.json()["errors"]
    assert any(e["pointer"] == pointer and says in e["reason"] for e in errors), errors
    assert client.get(f"/v1/vehicles/{vid}/events").json()["items"] == []  # nothing recorded


def test_seeded_hostile_text_never_records_or_5xx(client):
    vid = _vehicle(client)
    rng = np.random.default_rng(7)
    alphabet = list("jamfloteivsrhdw_:@+.-0123456789eE \t\n\x00☃é٣")
    for _ in range(150):
        text = "".join(alphabet[int(i)] for i in rng.integers(len(alphabet), size=int(rng.integers(0, 30))))
        r = client.post(f"/v1/vehicles/{vid}/events", json={"failure": text}, headers=H)
        assert r.status_code in (201, 422), (text, r.text)
        if r.status_code == 201:  # a valid text by chance: it is recorded as written
            assert r.json()["event"]["failure"] is not None
