"""Sweep axes: the failure catalogue reaches the simulator, simulator settings pass through by
name (or are refused before any run), and latency comes from its own single-process pass."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

from benchmarks.compare.failures import KINDS, catalogue_names, make_failure
from benchmarks.compare.sweep import (
    FRAME_PERIOD, STATIC, check_simulator_support, closed_spec, full_sweep, setting_tag,
)


@pytest.mark.parametrize("scenario", ["ice", "harv_latdir"])
def test_catalogue_failures(scenario: str) -> None:
    import importlib

    vehicle = importlib.import_module(f"sim.scenarios.{scenario}").vehicle()
    assert catalogue_names() == [f"{k}{n}" for k in KINDS for n in (1, 2)]
    for name in catalogue_names():
        f = make_failure(scenario, name, 3.0)
        assert f.time == 3.0 and f.A is None and f.B is None and f.delay is None  # effector-only
        assert len({a.index for a in f.actuators}) == int(name[-1])
        a = f.actuators[0]
        i = a.index
        if name.startswith("jam"):
            assert a.kind == "jam" and a.position == 0.5 * vehicle.umax[i]
        elif name.startswith("hardover"):
            assert a.kind == "hardover" and a.position == vehicle.umax[i]
        elif name.startswith("float"):
            assert a.kind == "float"
        elif name.startswith("effectiveness"):
            assert a.kind == "effectiveness" and a.fraction == 0.25
        else:  # the catalogue's limits: reduced position and rate limits (rate_limits rides with it)
            assert a.kind == "limits" and (a.lo, a.hi) == (0.25 * vehicle.umin[i], 0.25 * vehicle.umax[i])
            rate = f.actuators[1]
            assert rate.kind == "rate_limits" and rate.index == i
            assert rate.rate_max == -rate.rate_min == pytest.approx(0.2 * vehicle.rate_max[i])
    with pytest.raises(ValueError, match="catalogue"):
        make_failure(scenario, "jam3", 1.0)


def test_a_catalogue_failure_reaches_the_loop_and_the_told_allocator() -> None:
    import sim.scenarios.ice as ice
    from benchmarks.compare.closedloop import simulate_spec
    from sim.allocation import allocation_problem
    from sim.scenarios import get_scenario

    kw = dict(seed=1, duration=1.0, failure_time=0.5, sim={"pilot_gain": 1.0})
    jam = simulate_spec(closed_spec("ice", "jam1", "pinv", told=False, **kw))
    assert get_scenario("ice").accepts_failure_objects  # handed over directly, no injection
    assert jam.failure == "jam1"
    after = jam.t >= 0.5
    assert np.all(jam.effectors[after, 0] == 15.0)  # elevon_l jammed at hi / 2 from the failure on
    assert not np.any(jam.effectors[~after, 0] == 15.0)
    nominal = simulate_spec(closed_spec("ice", "seed", "pinv", told=False, **dict(kw, failure_time=5.0)))
    assert np.array_equal(nominal.output[~after], jam.output[~after])  # same run until the failure
    told = allocation_problem(ice.vehicle(), make_failure("ice", "jam1", 0.5))
    assert told.umin[0] == told.umax[0] == 15.0


def test_simulator_settings_pass_through_by_name_or_are_refused_before_running() -> None:
    ok = closed_spec("ice", "seed", "pinv", told=True, seed=1, duration=1.0, failure_time=0.5,
                     sim={"pilot_gain": 1.5, "pilot_delay": 0.3})
    assert ok["id"] == "closed/ice/pilot_delay=0.3,pilot_gain=1.5/seed/pinv/told/s01"
    assert setting_tag({}) == "default"
    check_simulator_support([ok])
    bad = dict(ok, sim={"no_such_option": 1})
    with pytest.raises(ValueError, match="'no_such_option': scenario 'ice' does not accept it"):
        check_simulator_support([bad])
    with pytest.raises(ValueError, match="failure 'nope'"):
        check_simulator_support([dict(ok, failure="nope")])

    check_simulator_support([dict(ok, sim={FRAME_PERIOD: 0.01, "pilot": "crossover"})])  # the multi-rate loop


def test_full_sweep_axes() -> None:
    import alloc

    specs = [s for s in full_sweep(seeds=10, frame_rates=(None, 100.0)) if s["kind"] == "closed"]
    ids = [s["id"] for s in specs]
    assert len(ids) == len(set(ids))
    methods = 1 + len(alloc.methods())
    per_cell = (2 * methods - 1) * 10 * 3 * 2  # modes (static blind only) x seeds x pilots x frame rates
    assert len(specs) == per_cell * ((1 + 10) + (2 + 10))  # ICE: seed + catalogue; HARV: 2 + catalogue
    assert {s["sim"].get("pilot", "standin") for s in specs} == {"crossover", "standin"}
    assert {s["sim"].get(FRAME_PERIOD) for s in specs} == {None, 0.01}
    assert not any(s["method"] == STATIC and s["told"] for s in specs)


def test_latency_comes_from_its_own_pass(tmp_path: Path) -> None:
    from benchmarks.compare.report import _latency_section
    from benchmarks.compare.timing import TIMINGS_CSV, measure_latency, write_timings

    rows = measure_latency(["harv_latdir"], ["pinv", "qp"], calls=30, demands=10)
    assert [(r["problem"], r["method"], r["calls"]) for r in rows] == [("harv_latdir", "pinv", 30),
                                                                       ("harv_latdir", "qp", 30)]
    for r in rows:
        assert 0 < r["median_us"] <= r["p99_us"] and r["median_over_floor"] == r["median_us"] / r["floor_median_us"]
    write_timings(tmp_path, rows)
    text = _latency_section(tmp_path, {"cores": 2})
    saved = list(csv.DictReader((tmp_path / TIMINGS_CSV).open()))
    assert f"| qp | {float(saved[1]['median_us']):.3g} / {float(saved[1]['p99_us']):.3g}" in text


def test_recovery_time() -> None:
    from benchmarks.compare.closedloop import recovery_time

    t = np.arange(0, 10.0001, 0.01)
    err = np.full((t.size, 2), 0.1)
    err[(t >= 4) & (t < 6.5), 1] = 1.0  # 10x the pre-failure RMS of channel 1 for 2.5 s after t = 4
    before = np.array([0.1, 0.1])
    assert recovery_time(t, err, 4.0, before) == 3.0  # windows [4,5), [5,6), [6,7) bad; recovered from 7 s
    err[t >= 9.5, 0] = 1.0  # bad again at the end: never recovered
    assert recovery_time(t, err, 4.0, before) == float("inf")
    err[t >= 9.5, 0] = 0.1
    assert recovery_time(t, err, 4.0, before) == 3.0
    err[-1, 0] = 50.0  # the lone end sample t = 10 belongs to the last full window [9, 10] (RMS about 5)
    assert recovery_time(t, err, 4.0, before) == float("inf")
    assert np.isnan(recovery_time(t, err, 0.0, np.array([np.nan, 0.1])))  # no pre-failure interval


def test_seed_length_sweep_axes() -> None:
    """The seed's run lengths (ICE 40 s, failure at 20 s; HARV lat-dir 50 s, failure at 25 s), crossover pilot."""
    import alloc
    from benchmarks.compare.sweep import SAME_AS_DA, SEED_LENGTH_FAILURES, seed_length_sweep

    specs = seed_length_sweep(3)
    methods = len([m for m in alloc.methods() if m not in SAME_AS_DA])
    assert len({s["id"] for s in specs}) == len(specs) == (2 * methods + 1) * 3 * (2 + 3)  # methods x 2 arms + static
    assert {(s["scenario"], s["duration"], s["failure_time"]) for s in specs} == {("ice", 40.0, 20.0),
                                                                               ("harv_latdir", 50.0, 25.0)}
    assert {s["failure"] for s in specs if s["scenario"] == "harv_latdir"} == set(SEED_LENGTH_FAILURES["harv_latdir"])
    assert {setting_tag(s["sim"]) for s in specs} == {"pilot=crossover"}
    assert not {s["method"] for s in specs} & set(SAME_AS_DA)
    check_simulator_support(specs)


def test_a_short_sweep_row_carries_the_verdict() -> None:
    """A 3 s ICE run (failure at 0.5 s) judged by sim.criteria: the row's verdict columns are the
    summary's verdict, and a broken criterion's metric exceeds its limit."""
    from benchmarks.compare.closedloop import run_closed, verdict_columns
    from sim.criteria import criteria_for

    spec = closed_spec("ice", "seed", STATIC, told=False, seed=1, duration=3.0, failure_time=0.5,
                       sim={"pilot_gain": 1.0})
    row, _, _ = run_closed(spec)
    limits = criteria_for("ice").limits()
    broken = [b for b in row["verdict_broken"].split(";") if b]
    assert row["verdict_pass"] is (not broken)
    for name in broken:
        assert row[name] > limits[name], name
    for name in ("betaw_excursion_after", "position_saturation_after", "rate_saturation_before", "back_in_band_s"):
        assert name in row and row[name] is not None
    # a metric already among the columns is not repeated; an infinite one comes back as inf
    cols = verdict_columns({"pass": False, "broken": ["ps_rms_after", "back_in_band_s"],
                            "metrics": {"ps_rms_after": 9.0, "back_in_band_s": "inf"}}, {"ps_rms_after": 9.0})
    assert cols == {"verdict_pass": False, "verdict_broken": "ps_rms_after;back_in_band_s", "back_in_band_s": float("inf")}
    assert verdict_columns(None, {}) == {"verdict_pass": None, "verdict_broken": None}
