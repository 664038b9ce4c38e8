"""benchmarks/bench_detection.py: the cases it flies, the false-alarm interval and verdict, the
surviving-benefit fraction and the reading of an ``alloc bench detected`` sweep."""

from __future__ import annotations

import math

import numpy as np
import pytest

from benchmarks import bench_detection as bd


def test_detection_cases_are_the_catalogue_and_the_stated_variants():
    assert bd.detection_cases()[:5] == ("jam", "hardover", "float", "effectiveness", "limits")
    loe25 = bd.case_failure("ice", "loe25", 2.5)
    assert [(a.index, a.kind, a.params) for a in loe25.actuators] == [(0, "effectiveness", {"fraction": 0.75})]
    rate = bd.case_failure("harv_latdir", "rate_limits", 2.0)
    assert [a.kind for a in rate.actuators] == ["rate_limits"] and rate.time == 2.0
    assert bd.case_kind("loe50") == "effectiveness" and bd.case_kind("jam") == "jam"


def test_poisson_interval_and_verdict():
    # exact (Garwood) 95 % limits: 0 events [0, 3.689], 5 events [1.623, 11.668]
    assert bd.poisson_interval(0) == pytest.approx((0.0, 3.6889), abs=1e-4)
    assert bd.poisson_interval(5) == pytest.approx((1.6235, 11.6683), abs=1e-4)
    assert bd.false_verdict(0.5, 0.9) == "met"
    assert bd.false_verdict(0.5, 2.0).startswith("not shown")
    assert bd.false_verdict(1.5, 3.0) == "NOT met"


def test_surviving_fraction_mean_and_median():
    blind, told = np.array([4.0, 6.0, 5.0]), np.array([2.0, 2.0, 2.0])
    detected = np.array([2.5, 2.5, math.inf])
    assert math.isnan(bd.surviving_fraction(blind, told, detected))
    assert bd.surviving_fraction(blind, told, detected, np.median) == pytest.approx((5 - 2.5) / 3)
    assert math.isnan(bd.surviving_fraction(told, blind, detected))  # told no better: undefined


def test_sweep_rows_read_a_detected_sweep(tmp_path):
    header = "scenario,setting,failure,method,health,seed,diverged,ps_rms_before,ps_rms_after\n"
    rows = ["ice,frame_period=0.01,jam1,qp,blind,1,False,0.5,2.0", "ice,frame_period=0.01,jam1,qp,told,1,False,0.5,1.0",
            "ice,frame_period=0.01,jam1,qp,detected,1,True,0.5,nan"]
    path = tmp_path / "closed_ice.csv"
    path.write_text(header + "\n".join(rows) + "\n")
    got = bd.sweep_rows(path)
    assert [(r["kind"], r["health"], r["seed"], r["diverged"], r["frame_period"]) for r in got] == [
        ("jam", "blind", 1, False, 0.01), ("jam", "told", 1, False, 0.01), ("jam", "detected", 1, True, 0.01)]
    assert bd.score(got[1], got[0]) == pytest.approx(2.0) and bd.score(got[2], got[0]) == math.inf


def test_the_detected_sweep_flies_its_static_baseline_and_scores_a_finite_share():
    """Every (failure, seed) of ``alloc bench detected`` has the ``static`` blind run its scores are
    relative to, so the report's ``detected_share`` is a number; flown on a shortened single jam."""
    from benchmarks.compare.closedloop import run_closed
    from benchmarks.compare.summaries import closed_scores, detected_share
    from benchmarks.compare.sweep import STATIC, detected_sweep

    specs = detected_sweep(2)
    assert len(specs) == 2 * 2 * (1 + 2 * 3)  # failures x seeds x (static + two methods' three arms)
    for failure in ("jam1", "hardover1"):
        for seed in (1, 2):
            cell = [s for s in specs if s["failure"] == failure and s["seed"] == seed]
            assert [(s["method"], s["health"]) for s in cell if s["method"] == STATIC] == [(STATIC, "blind")]
            assert len({(s["duration"], s["failure_time"], str(s["sim"])) for s in cell}) == 1
    tiny = [{**s, "duration": 3.0, "failure_time": 1.0} for s in detected_sweep(1)
            if s["failure"] == "jam1" and s["method"] in (STATIC, "qp")]
    rows = closed_scores([run_closed(s)[0] for s in tiny])
    assert all(math.isfinite(r["score"]) for r in rows)
    (share,) = detected_share(rows, resamples=50)
    by = {r["health"]: r["score"] for r in rows if r["method"] == "qp"}
    assert by["blind"] > by["told"]  # told helps on this jam, so the share is defined
    assert share["share"] == pytest.approx((by["blind"] - by["detected"]) / (by["blind"] - by["told"]))
    assert math.isfinite(share["share"]) and share["seeds"] == 1


def test_the_report_keeps_excited_runs_apart(tmp_path):
    """Rows flown with ``--excitation`` get their own table, never pooled with the plain ones."""
    import json

    def row(seed, excitation, delay):
        det = {"effector": "elevon_l", "kind": "jam", "time": 3.0 + delay, "delay": delay}
        return {"key": f"ice/jam/1/{seed}/{excitation}", "scenario": "ice", "case": "jam", "kind": "jam",
                "noise_scale": 1.0, "failed": ["elevon_l"], "detections": [det], "excitation": excitation,
                "wall": 1.0}

    rows = [row(0, 0.0, 0.1), row(1, 0.0, 0.1), row(0, 2.0, 0.9), row(1, 2.0, 0.9)]
    (tmp_path / "delays.jsonl").write_text("\n".join(json.dumps(r) for r in rows) + "\n")
    text = bd.report(tmp_path, markdown=True)
    plain, excited = text.split("with null-space excitation 2 deg")
    assert "| ice | jam | x1 | 2 | 2 | 2 | 2 | 0 | 0 | 0.10 | 0.10 |" in plain
    assert "| ice | jam | x1 | 2 | 2 | 2 | 2 | 0 | 0 | 0.90 | 0.90 |" in excited


def test_the_evidence_trace_reads_the_detector_and_changes_nothing():
    """A traced ``delays`` run detects what the untraced one does; its evidence sums to one and
    names the failed effector's jam once the jam is detected."""
    from benchmarks import detection_evidence as de

    traced = de.fly_traced("ice", "jam", 1.0, 0)
    tf = bd.delay_failure_time(0, "ice", "jam")
    plain = bd._fly("ice", "jam", health="detected", method="qp", seed=100, failure_time=tf, duration=tf + 3.0,
                    frame_period=0.01)
    assert traced["detections"] == plain["detections"] and traced["detections"]
    alarmed = [p for p in traced["trace"] if p["alarmed"]]
    assert alarmed and all(p["t"] >= -0.05 for p in alarmed)  # no alarm before the jam
    decided = traced["detections"][0]["time"] - tf
    last = [p for p in alarmed if p["t"] <= decided + 1e-9][-1]
    top = last["evidence"][0]
    assert (top[0], top[1]) == ("elevon_l", "jam") and top[2] >= 0.95
    assert sum(p for _, _, p in last["evidence"]) <= 1.0 + 1e-9
    assert de.at_deadline(traced)["delay"] == traced["detections"][0]["delay"]
