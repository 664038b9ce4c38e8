"""Walk-through "Add a failure kind" (docs/ARCHITECTURE.md), performed end to end.

The new kind, ``damage`` (battle damage: part of the control power *and* of the travel lost),
is ONE row of the specification table in :mod:`alloc.health`, registered here with
:func:`alloc.health.register_failure_kind`.  Nothing else is written anywhere: the library's
health and failure grammar, the simulator's actuators (told and untold runs), ``alloc sim``,
the service's event schema and the sweep's catalogue all read the table.
"""

from __future__ import annotations

import sys

import numpy as np
import pytest
from fastapi.testclient import TestClient

import alloc
from alloc import health, vehicles
from alloc.health import Default, Effect, FailureEvent, FailureKindError, KindSpec, Told

#: the one table entry this walk-through adds
DAMAGE = KindSpec(
    "damage", "battle damage: part of the control power and of the travel lost",
    params={"fraction": None, "lo": None, "hi": None},
    effects=(Effect.SCALE, Effect.LIMITS),
    told=(Told.EFFECTIVENESS, Told.LIMITS),
    example={"fraction": 0.5, "lo": -0.5, "hi": 0.5},
)
KEY = "k3y"
FAILURE_TIME = 0.5


@pytest.fixture
def damage():
    """``damage`` registered for one test; the table as it was afterwards."""
    saved = dict(health._TABLE)
    kind = health.register_failure_kind(DAMAGE)
    yield kind
    health._TABLE.clear()
    health._TABLE.update(saved)


def test_the_kind_is_one_row_of_the_table(damage):
    assert damage == "damage" and damage in list(health.FailureKind) and health.FailureKind("damage") is damage
    assert health.FAILURE_KINDS["damage"].effects == (Effect.SCALE, Effect.LIMITS)
    with pytest.raises(FailureKindError, match="already registered"):
        health.register_failure_kind(DAMAGE)


def test_the_table_is_restored_after_the_walkthrough():
    assert "damage" not in health.FAILURE_KINDS
    with pytest.raises(alloc.ProblemError, match="^kind: unknown failure kind 'damage'"):
        FailureEvent("elevon_l", "damage", fraction=0.5, lo=-1.0, hi=1.0)


def test_the_library_tells_it(damage):
    nominal = vehicles.problem("ice")
    name, after = health.apply_event(nominal, {}, FailureEvent("elevon_l", "damage", fraction=0.25, lo=-7.5, hi=7.5))
    assert name == "elevon_l" and after["elevon_l"] == health.EffectorHealth(effectiveness=0.25, limits=(-7.5, 7.5))
    told = nominal.with_health(after)
    np.testing.assert_array_equal(told.B[:, 0], 0.25 * nominal.B[:, 0])
    assert (told.umin[0], told.umax[0]) == (-7.5, 7.5)
    r = alloc.allocate(told, [1.0, 5.0, 0.1], "qp")
    assert np.isfinite(r.u).all() and -7.5 <= r.u[0] <= 7.5
    # its parameters are checked by their ranges in the table, naming the field
    with pytest.raises(alloc.ProblemError, match=r"^lo: damage lo -40 of 'elevon_l' outside its nominal limits"):
        health.apply_event(nominal, {}, FailureEvent("elevon_l", "damage", fraction=0.5, lo=-40.0, hi=7.5))
    with pytest.raises(alloc.ProblemError, match=r"^fraction: required for a 'damage' failure"):
        FailureEvent("elevon_l", "damage", lo=-1.0, hi=1.0)


def _fly(failure, told: bool):
    from sim.scenarios import get_scenario

    return get_scenario("ice")(failure=failure, method="qp", duration=1.0, seed=1, allocator_knows_failure=told,
                               failure_time=FAILURE_TIME)


def test_told_and_untold_simulator_runs_honour_it(damage, monkeypatch):
    import sim.engine
    from benchmarks.compare.failures import catalogue_names, catalogue_texts, make_failure
    from sim.allocation import allocation_problem
    from sim.blocks import ActuatorFailure
    from sim.model import Failure
    from sim.scenarios import ice

    # the sweep's catalogue has it (parameters set by its effects' severities: 25 %, a quarter range),
    # written in the failure grammar on the effector ICE names for it
    assert catalogue_names()[-2:] == ["damage1", "damage2"]
    assert catalogue_texts("ice")["damage1"] == "damage:elevon_l@0.25:-7.5:7.5"
    failure = make_failure("ice", "damage1", FAILURE_TIME)
    assert failure.actuators == (ActuatorFailure(0, "damage", fraction=0.25, lo=-7.5, hi=7.5),)
    # the same failure written with two built-in kinds: the simulator must fly both the same, bit for bit
    pair = Failure("pair", FAILURE_TIME, "effectiveness and limits of elevon_l", actuators=(
        ActuatorFailure(0, "effectiveness", fraction=0.25), ActuatorFailure(0, "limits", lo=-7.5, hi=7.5)))

    told_problems = []
    build = sim.engine.build_allocator

    def spy(vehicle, method, options, *, failure=None, **kw):
        if failure is not None:
            told_problems.append(allocation_problem(vehicle, failure))
        return build(vehicle, method, options, failure=failure, **kw)

    monkeypatch.setattr(sim.engine, "build_allocator", spy)
    runs = {(name, told): _fly(f, told) for name, f in (("damage", failure), ("pair", pair)) for told in (True, False)}
    told_damage, told_pair = told_problems  # only told runs tell: one problem each
    assert (told_damage.umin[0], told_damage.umax[0]) == (-7.5, 7.5)
    np.testing.assert_array_equal(told_damage.B[:, 0], 0.25 * ice.vehicle().B_alloc[:, 0])
    np.testing.assert_array_equal(told_damage.B, told_pair.B)

    t = runs["damage", True].t
    after = t >= FAILURE_TIME
    for told in (True, False):
        run, same = runs["damage", told], runs["pair", told]
        assert not run.diverged
        # the actuator executes the row's LIMITS effect, told or not
        assert np.abs(run.effectors[after, 0]).max() <= 7.5
        for signal in ("output", "effectors", "unallocated"):
            np.testing.assert_array_equal(getattr(run, signal), getattr(same, signal), err_msg=signal)
    told_run, blind = runs["damage", True], runs["damage", False]
    np.testing.assert_array_equal(told_run.output[~after], blind.output[~after])  # the same until the failure
    assert not np.array_equal(told_run.output[after], blind.output[after])  # telling it changes the flight
    assert not np.array_equal(told_run.effectors[after], blind.effectors[after])


def test_the_grammar_reads_and_writes_it(damage):
    from alloc.failure_grammar import EffectorFailure, failure_kinds, format_failure, parse_failure

    assert "damage" in failure_kinds()
    text = "damage:elevon_l@0.25:-7.5:7.5"
    parsed = parse_failure(text, vehicles.problem("ice").names)
    assert parsed == (EffectorFailure("damage", "elevon_l", {"fraction": 0.25, "lo": -7.5, "hi": 7.5}),)
    assert format_failure(parsed) == text
    with pytest.raises(alloc.ProblemError, match=r"^failure: 'damage:elevon_l@0.25': lo is required"):
        parse_failure("damage:elevon_l@0.25")


def test_alloc_sim_flies_it(damage, tmp_path):
    """``alloc sim ice --failure damage1`` (the catalogue name) and the text it stands for: one flight."""
    import json

    from typer.testing import CliRunner

    from alloc.cli import app
    from sim.scenarios import get_scenario

    runner = CliRunner()
    args = ["--failure-time", str(FAILURE_TIME), "--duration", "1", "--method", "qp", "--told"]
    by_name = runner.invoke(app, ["sim", "ice", "--failure", "damage1", *args], prog_name="alloc")
    by_text = runner.invoke(app, ["sim", "ice", "--failure", "damage:elevon_l@0.25:-7.5:7.5", *args],
                            prog_name="alloc")
    assert by_name.exit_code == 0 and by_text.exit_code == 0, (by_name.output[-800:], by_text.output[-800:])
    named, texted = json.loads(by_name.stdout), json.loads(by_text.stdout)
    assert named["failure"] == "damage1" and not named["diverged"] and named["failure_time"] == FAILURE_TIME
    for summary in (named, texted):  # the one difference: the name the run was given
        summary.pop("failure"), summary["settings"].pop("failure")
    assert named == texted
    listed = runner.invoke(app, ["sim", "--list"], prog_name="alloc")
    assert "--failure damage1: catalogue, damage:elevon_l@0.25:-7.5:7.5" in listed.stdout
    run = get_scenario("ice")(failure="damage1", failure_time=FAILURE_TIME, duration=1.0, method="qp", seed=0)
    assert np.abs(run.effectors[run.t >= FAILURE_TIME, 0]).max() <= 7.5


@pytest.fixture
def service_app(damage, tmp_path, monkeypatch):
    """The service started after the kind is registered (as a plugin kind registers on import,
    before the service starts): its modules are imported afresh, the originals put back after."""
    for name in [m for m in sys.modules if m == "service" or m.startswith("service.")]:
        monkeypatch.delitem(sys.modules, name)
    from service.config import Settings
    from service.main import create_app

    return create_app(Settings(data_dir=tmp_path, api_key=KEY, warmup=False))


def test_a_service_event_honours_it(service_app):
    nominal = vehicles.problem("ice")
    headers = {"X-API-Key": KEY}
    with TestClient(service_app) as client:
        r = client.post("/v1/vehicles", json={**nominal.to_dict(), "name": "ice"}, headers=headers)
        assert r.status_code == 201, r.text
        vid = r.json()["id"]
        event = {"effector": "elevon_l", "kind": "damage", "fraction": 0.25, "lo": -7.5, "hi": 7.5}
        r = client.post(f"/v1/vehicles/{vid}/events", json=event, headers=headers)
        assert r.status_code == 201, r.text
        body = r.json()
        assert body["event"]["kind"] == "damage" and body["event"]["params"] == {"fraction": 0.25, "lo": -7.5, "hi": 7.5}
        elevon = body["health"]["effectors"][0]
        assert (elevon["status"], elevon["effectiveness"], elevon["limits"]) == ("degraded", 0.25, [-7.5, 7.5])
        effective = body["health"]["effective"]
        assert (effective["umin"][0], effective["umax"][0]) == (-7.5, 7.5)
        np.testing.assert_allclose(np.array(effective["B"])[:, 0], 0.25 * nominal.B[:, 0], rtol=0, atol=0)
        r = client.post(f"/v1/vehicles/{vid}/allocate", json={"v": [1.0, 5.0, 0.1], "method": "qp"})
        assert r.status_code == 200, r.text
        assert -7.5 <= r.json()["u"][0] <= 7.5
        # the schema is the row's: a missing parameter and an out-of-range one are 422 naming the field
        for bad, pointer in (({**event, "fraction": 1.5}, "/fraction"), ({**event, "lo": -40.0}, "/lo"),
                             ({k: v for k, v in event.items() if k != "hi"}, "/hi")):
            r = client.post(f"/v1/vehicles/{vid}/events", json=bad, headers=headers)
            assert r.status_code == 422, r.text
            assert pointer in [e["pointer"] for e in r.json()["errors"]], r.json()
        # the same failure as text, and each recorded event written back in the grammar
        r = client.post(f"/v1/vehicles/{vid}/events", json={"failure": "damage:elevon_r@0.5:-10:10"},
                        headers=headers)
        assert r.status_code == 201, r.text
        assert r.json()["event"]["params"] == {"fraction": 0.5, "lo": -10.0, "hi": 10.0}
        assert [e["failure"] for e in client.get(f"/v1/vehicles/{vid}/events").json()["items"]] == [
            "damage:elevon_l@0.25:-7.5:7.5", "damage:elevon_r@0.5:-10:10"]
        schemas = client.get("/openapi.json").json()["components"]["schemas"]
        assert set(schemas["DamageEvent"]["required"]) == {"effector", "kind", "fraction", "lo", "hi"}


@pytest.mark.parametrize("change, gap", [
    ({"effects": ()}, "no actuator effect"),
    ({"told": ()}, "no told rule"),
    ({"params": {"fraction": None, "lo": None}}, r"read \['hi'\], which are not among its params"),
    ({"params": {"fraction": None, "lo": None, "hi": None, "position": None}}, r"\['position'\] read by none"),
    ({"example": {"fraction": 0.5}}, "its example must give every required parameter"),
    ({"effects": (Effect.SCALE, Effect.LIMITS, Effect.BANDWIDTH),
      "params": {"fraction": None, "lo": None, "hi": None}}, "read \\['wn'\\]"),
    ({"params": {"fraction": None, "lo": Default.AT_FAILURE, "hi": None}}, "instant of failure is a default only"),
    ({"name": "Damage!"}, "a name is"),
])
def test_an_incomplete_row_fails_at_registration(change, gap):
    from dataclasses import replace

    with pytest.raises(FailureKindError, match=gap):
        health.register_failure_kind(replace(DAMAGE, **change))
    assert "damage" not in health.FAILURE_KINDS
