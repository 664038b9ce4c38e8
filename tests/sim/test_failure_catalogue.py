"""One failure grammar in the simulator: ``alloc sim`` flies what the sweep flies.

``alloc sim ice --failure jam1`` was refused ("known: ['seed', 'none']") while the comparison
sweep flew ``jam1``.  Now a scenario resolves its own failures, the catalogue's names
(:mod:`sim.failure_catalogue`, each a text of :mod:`alloc.failure_grammar` on effectors the
scenario names) and any grammar text on its effectors.  The sweep's catalogue is checked here
against the rule it was written with (effector *indices* hard-coded in the benchmarks:
``ice`` 0 and 7, ``harv_latdir`` 1 and 2) -- the same actuator failures, bit for bit.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

import alloc
from alloc.cli import app
from alloc.failure_grammar import parse_failure
from alloc.health import FailureKind
from benchmarks.compare.failures import (
    CATALOGUE_SCENARIOS,
    FAILED_EFFECTORS,
    SEVERITY,
    catalogue_names,
    catalogue_texts,
    failed_effectors,
    make_failure,
)
from sim.blocks import ActuatorFailure
from sim.scenarios import get_scenario

ROOT = Path(__file__).resolve().parents[2]
runner = CliRunner()

#: the catalogue's failed effectors as the benchmarks hard-coded them before they were named
OLD_INDICES = {"ice": (0, 7), "harv_latdir": (1, 2)}


def _old_rule(scenario: str, name: str) -> tuple[ActuatorFailure, ...]:
    """The actuator failures of catalogue ``name`` by the rule as it was: indices, severities, riders."""
    vehicle = importlib_scenario(scenario).vehicle()
    kind, n = name[:-1], int(name[-1])
    out = []
    for i in OLD_INDICES[scenario][:n]:
        for k in (kind, *(["rate_limits"] if kind == "limits" else [])):
            params: dict[str, float] = {}
            for effect in FailureKind(k).spec.effects:
                params.update(SEVERITY[effect](vehicle.umin[i], vehicle.umax[i], vehicle.rate_max[i]))
            out.append(ActuatorFailure(i, k, **params))
    return tuple(out)


def importlib_scenario(name: str):
    import importlib

    return importlib.import_module(f"sim.scenarios.{name}").SCENARIO


@pytest.mark.parametrize("scenario", CATALOGUE_SCENARIOS)
def test_every_catalogue_entry_resolves_on_every_sweep_scenario(scenario):
    run = get_scenario(scenario)
    texts = catalogue_texts(scenario)
    assert list(texts) == catalogue_names() == list(run.catalogue())
    names = importlib_scenario(scenario).vehicle().effector_names
    assert tuple(names[i] for i in OLD_INDICES[scenario]) == failed_effectors(scenario)
    assert FAILED_EFFECTORS[scenario] == OLD_INDICES[scenario]
    for name, text in texts.items():
        run.check_failure(name)  # what alloc sim asks
        run.check_failure(text)  # the text it stands for is taken as itself
        # the text names the failed effectors by name, first one, then both
        assert {f.effector for f in parse_failure(text)} == set(failed_effectors(scenario)[: int(name[-1])])
        failure = make_failure(scenario, name, 3.0)
        assert failure.name == name and failure.time == 3.0
        assert failure.actuators == _old_rule(scenario, name), name
        # bit for bit: the parameters are the floats the old rule computed
        for new, old in zip(failure.actuators, _old_rule(scenario, name), strict=True):
            assert [np.float64(v).tobytes() for v in new.params.values()] == \
                [np.float64(old.params[k]).tobytes() for k in new.params]
        same = importlib_scenario(scenario).resolve_failure(text, 3.0)
        assert same.actuators == failure.actuators and same.A is None and same.delay is None


def test_a_legacy_name_flies_as_todays_under_its_own_name():
    old, new = make_failure("ice", "loe1", 2.0), make_failure("ice", "effectiveness1", 2.0)
    assert old.name == "loe1" and old.actuators == new.actuators


def test_named_composite_failures_keep_working():
    ice, harv = importlib_scenario("ice"), importlib_scenario("harv_latdir")
    seed = ice.resolve_failure("seed", None)
    assert seed.time == 20.0 and seed.delay == 0.05 and seed.A is not None  # the seed's, plant included
    assert harv.resolve_failure("failure1", None).time == 25.0
    assert harv.resolve_failure("failure2", None).time == 0.0
    # a catalogue or grammar failure without a time: the scenario's seed failure time
    assert ice.resolve_failure("jam1", None).time == 20.0
    assert harv.resolve_failure("float:rudder", None).time == 25.0


@pytest.mark.parametrize("scenario, text, effector, kind", [
    ("ice", "jam:lef_r@-5+float:yaw_tv", "lef_r", "jam"),
    ("harv_lon", "hardover:ptv@-3", "ptv", "hardover"),
    ("harv_latdir", "bandwidth:roll_tv@10", "roll_tv", "bandwidth"),
])
def test_any_grammar_text_on_the_scenarios_effectors_is_taken(scenario, text, effector, kind):
    sc = importlib_scenario(scenario)
    failure = sc.resolve_failure(text, 1.0)
    names = sc.vehicle().effector_names
    assert failure.actuators[0].index == names.index(effector) and failure.actuators[0].kind == kind


@pytest.mark.parametrize("scenario, failure, says", [
    ("ice", "jam3", "catalogue: jam1, jam2"),
    ("ice", "jam:de3@5", "unknown effector 'de3'; effectors: elevon_l"),
    ("ice", "jam:elevon_l@45", "outside its nominal limits [-30, 30]"),
    ("ice", "rate_limits:elevon_l@-20:10", "symmetric"),
    ("harv_lon", "jam1", "harv_lon names no catalogue effectors"),
    ("pendulum", "jam1", "its own failures only"),
    ("f16", "float:elevator", "its own failures only"),
])
def test_cli_refuses_naming_the_failure_and_what_is_taken(scenario, failure, says):
    res = runner.invoke(app, ["sim", scenario, "--failure", failure, "--duration", "0.2"], prog_name="alloc")
    assert res.exit_code == 2, res.output
    line, = res.stderr.strip().splitlines()  # one line, naming the option
    assert "--failure" in line and f"unknown failure {failure!r} for {scenario}" in line and says in line, line


def test_list_shows_the_catalogue_and_the_grammar():
    res = runner.invoke(app, ["sim", "--list"], prog_name="alloc")
    assert res.exit_code == 0
    assert "--failure jam1: catalogue, jam:elevon_l@15" in res.stdout
    assert "--failure jam2: catalogue, jam:aileron@13.75+jam:rudder@15" in res.stdout
    assert "--failure <kind>:<effector>[@<value>" in res.stdout


def test_alloc_sim_flies_a_catalogue_name_and_applies_it(tmp_path):
    """The bar, shortened: the failure early so a short run flies past it (the full run is the slow test)."""
    out = tmp_path / "r.json"
    res = runner.invoke(app, ["sim", "ice", "--failure", "jam1", "--failure-time", "0.5", "--duration", "1.5",
                              "--method", "qp", "--json", str(out)], prog_name="alloc")
    assert res.exit_code == 0, res.output
    summary = json.loads(out.read_text())
    assert summary["failure"] == "jam1" and summary["failure_time"] == 0.5 and not summary["diverged"]
    run = get_scenario("ice")(failure="jam1", failure_time=0.5, duration=1.5, method="qp", seed=0)
    elevon = run.effectors[:, run.effector_names.index("elevon_l")]
    # jam1 on ICE is jam:elevon_l@15: held at 15 deg from the instant of failure, free before it
    assert np.all(elevon[run.t >= 0.5] == 15.0) and np.all(np.abs(elevon[run.t < 0.5]) < 10.0)
    assert run.summary() == summary


@pytest.mark.slow
def test_the_bar_alloc_sim_ice_failure_jam1_duration_25(tmp_path):
    """``alloc sim ice --failure jam1 --duration 25`` flies: bounded, the jam injected at the seed's 20 s."""
    out = tmp_path / "r.json"
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    res = subprocess.run([sys.executable, "-m", "alloc.cli", "sim", "ice", "--failure", "jam1", "--duration", "25",
                          "--json", str(out)], cwd=ROOT, env=env, capture_output=True, text=True, timeout=600,
                         check=False)
    assert res.returncode == 0, res.stderr[-2000:]
    summary = json.loads(out.read_text())
    assert summary["failure"] == "jam1" and summary["failure_time"] == 20.0 and not summary["diverged"]
    assert summary["duration"] == 25.0
    for channel in summary["channels"].values():
        assert np.isfinite(channel["rms_after"]) and channel["max_after"] < 10.0  # deg, deg/s: no departure


@pytest.mark.slow
def test_committed_catalogue_rows_reproduce():
    """Committed sweep rows (benchmarks/reference/full) of each catalogue name re-run the same."""
    from benchmarks.compare.reproduce import load_reference, reproduce

    specs, _ = load_reference()
    ids = []
    for scenario in CATALOGUE_SCENARIOS:
        for name in ("jam2", "limits2", "loe1", "hardover1", "float2"):
            ids.append(next(i for i, s in sorted(specs.items()) if s["scenario"] == scenario
                            and s["failure"] == name and s["method"] == "qp" and s["told"]))
    results = reproduce(ids)
    assert [r.verdict for r in results if r.verdict == "differs"] == [], [(r.id, r.discrete_diffs) for r in results]


def test_a_hostile_failure_never_reaches_the_loop():
    for bad in ("", " ", "jam:elevon_l@nan", "jam:elevon_l@" + "9" * 5000, "☃:elevon_l", None, 5):
        with pytest.raises(alloc.AllocError) as info:
            importlib_scenario("ice").check_failure(bad)
        assert info.value.field == "failure"
