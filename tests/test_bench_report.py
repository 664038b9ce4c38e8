"""The comparison report computes its numbers from the CSVs: scores, rankings, Spearman."""

from __future__ import annotations

import csv
from pathlib import Path

import pytest

from benchmarks.compare.report import make_report
from benchmarks.compare.sweep import STATIC, closed_spec, open_spec, quick_sweep

METHODS = ("pinv", "qp", "da_facet", "cgi")
CHANNELS = ("alphaw", "ps", "betaw")


def _write(path: Path, rows: list[dict]) -> None:
    with path.open("w", newline="") as fh:
        w = csv.DictWriter(fh, list(rows[0]), lineterminator="\n")
        w.writeheader()
        w.writerows(rows)


def _closed_row(spec: dict, rms_after: float, diverged: bool = False) -> dict:
    row = {k: spec[k] for k in ("id", "scenario", "failure", "method", "told", "seed", "duration",
                                "failure_time", "noise")}
    row.update(diverged=diverged, simulated=spec["duration"])
    for c in CHANNELS:
        row.update({f"{c}_rms_before": 0.1, f"{c}_rms_after": rms_after, f"{c}_max_before": 0.2,
                    f"{c}_max_after": 2 * rms_after})
    row.update(time_in_position_saturation=1.0, time_in_rate_saturation=0.0)
    return row


def _open_row(spec: dict, coverage: float, err: float) -> dict:
    return {"id": spec["id"], "problem": spec["problem"], "method": spec["method"], "coverage": coverage,
            "coverage_lo": coverage, "coverage_hi": coverage, "coverage_estimator": "polytope",
            "unatt_err_mean": err, "unatt_err_max": 2 * err, "unatt_angle_mean": 0.0, "effort_mean": 1.0,
            "rate_violation_max": 0.0, "traj_err_mean": err, "fallbacks": 0, "calls": 10}


@pytest.fixture()
def sweep(tmp_path: Path) -> list[dict]:
    """Synthetic CSVs: told, the closed-loop order follows coverage exactly; blind, the reverse."""
    kw = dict(seed=1, duration=2.0, failure_time=1.0)
    specs = [closed_spec("ice", "seed", STATIC, told=False, **kw)]
    closed = [_closed_row(specs[0], 2.0)]
    for i, m in enumerate(METHODS):  # told: score (i + 1) / 4, the coverage order; blind: reversed
        for told, rms in ((True, 0.5 * (i + 1)), (False, 0.5 * (len(METHODS) - i))):
            s = closed_spec("ice", "seed", m, told=told, **kw)
            specs.append(s)
            closed.append(_closed_row(s, rms))
    opened = []
    for i, m in enumerate(METHODS):
        s = open_spec("ice", m, samples=10, demands=5, steps=5, latency_calls=5)
        specs.append(s)
        opened.append(_open_row(s, coverage=1.0 - 0.2 * i, err=float(i + 1)))
    _write(tmp_path / "closed_ice.csv", closed)
    _write(tmp_path / "open.csv", opened)
    _write(tmp_path / "open_timings.csv", [{"id": r["id"], "latency_median_us": 5.0, "latency_p99_us": 9.0}
                                           for r in opened])
    return specs


def test_report_numbers_come_from_the_csvs(tmp_path: Path, sweep: list[dict]) -> None:
    meta = {"sweep": "test", "command": "alloc bench test", "date": "today", "cores": 2}
    text = make_report(tmp_path, sweep, meta, history=False).read_text()
    assert "Command: `alloc bench test`" in text
    # score = mean over channels of rms_after / static's rms_after (2.0): pinv told 0.5 / 2
    assert "allocator told** (score: post-failure RMS / the seed's static distribution, 1 = as good as the " \
           "seed; 2 s runs, failure at 1 s): pinv (0.25), qp (0.5), da_facet (0.75)." in text
    assert "allocator blind** (score: post-failure RMS / the seed's static distribution, 1 = as good as the " \
           "seed; 2 s runs, failure at 1 s): cgi (0.25), da_facet (0.5), qp (0.75)." in text
    assert "coverage rho = 1 told, -1 blind" in text
    assert "telling the allocator lowers the score for 2 of 4 methods (pinv, qp)" in text
    for png in ("coverage.png", "latency.png", "errors_ice_seed.png"):
        assert (tmp_path / png).stat().st_size > 1000


def test_a_diverged_run_ranks_last(tmp_path: Path, sweep: list[dict]) -> None:
    rows = list(csv.DictReader((tmp_path / "closed_ice.csv").open()))
    for r in rows:
        if r["method"] == "pinv" and r["told"] == "True":
            r["diverged"] = "True"
    _write(tmp_path / "closed_ice.csv", rows)
    text = make_report(tmp_path, sweep, {}, history=False).read_text()
    assert "1 = as good as the seed; 2 s runs, failure at 1 s): qp (0.5), da_facet (0.75), cgi (1)." in text
    assert "| 9 | pinv | told | diverged |" in text
    assert "Diverged ICE runs: 1 of 9." in text


def test_quick_sweep_shape() -> None:
    specs = quick_sweep()
    ids = [s["id"] for s in specs]
    assert len(set(ids)) == len(ids)
    assert not any(s["method"] == STATIC and s.get("told") for s in specs)  # a fixed matrix cannot be told
    kinds = [s["kind"] for s in specs]
    assert kinds == sorted(kinds)  # closed (long) runs are submitted first
