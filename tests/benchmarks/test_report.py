"""The comparison report computes its numbers from the CSVs (synthetic rows with known answers),
and every figure's data (``X.csv`` next to ``X.png``) is the table printed next to it."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np
import pytest

from benchmarks.compare.report import (
    cell_summaries, closed_scores, coverage_agreement, make_report, parse_markdown_table, told_blind,
)
from benchmarks.compare.stats import bootstrap_median, paired_ratio, rank_with_ties, spearman
from benchmarks.compare.sweep import STATIC, closed_spec, open_spec, quick_sweep

CHANNELS = ("alphaw", "ps", "betaw")
SETTING = {"pilot_gain": 1.0}
SEEDS = range(1, 11)
#: method -> (told factor, blind factor) on the static design's post-failure RMS
FACTORS = {"da_facet": (0.5, 0.8), "qp": (0.52, 0.8), "cgi": (1.0, 1.0), "pinv": (2.0, 1.5)}
COVERAGE = {"da_facet": 1.0, "qp": 0.95, "cgi": 0.8, "pinv": 0.5}
FAILURES = ("seed", "jam1")


def _write(path: Path, rows: list[dict]) -> None:
    with path.open("w", newline="") as fh:
        w = csv.DictWriter(fh, list(rows[0]), lineterminator="\n")
        w.writeheader()
        w.writerows(rows)


def _closed_row(spec: dict, rms_after: float, diverged: bool = False) -> dict:
    row = {"id": spec["id"], "scenario": spec["scenario"], "setting": "pilot_gain=1", "failure": spec["failure"],
           "method": spec["method"], "told": spec["told"], "seed": spec["seed"], "duration": spec["duration"],
           "failure_time": spec["failure_time"], "noise": True, "diverged": diverged, "simulated": spec["duration"]}
    for c in CHANNELS:
        row.update({f"{c}_rms_before": 0.1, f"{c}_rms_after": rms_after, f"{c}_max_before": 0.2,
                    f"{c}_max_after": 2 * rms_after})
    row.update(recover_s=1.0, effort_after=0.2, unattainable_after=0.0, fallback_after="",
               time_in_position_saturation=1.0, time_in_rate_saturation=0.0)
    return row


@pytest.fixture()
def sweep(tmp_path: Path) -> list[dict]:
    """Synthetic CSVs: static's post-failure RMS varies with the seed; each method is a fixed
    factor of it (``FACTORS``), told runs times a seeded 5 % jitter; coverage orders the told methods."""
    rng = np.random.default_rng(7)
    kw = dict(duration=2.0, failure_time=1.0, sim=SETTING)
    specs, closed = [], []
    for f in FAILURES:
        for s in SEEDS:
            base = 1.0 + 0.5 * rng.random()
            spec = closed_spec("ice", f, STATIC, told=False, seed=s, **kw)
            specs.append(spec)
            closed.append(_closed_row(spec, base))
            for m, (ft, fb) in FACTORS.items():
                jitter = 1.0 + 0.05 * rng.standard_normal()
                if m == "cgi":  # told half 10 % better, half 10 % worse: told/blind undecided
                    jitter = 0.9 + 0.2 * (s % 2)
                for told, factor in ((True, ft), (False, fb)):
                    spec = closed_spec("ice", f, m, told=told, seed=s, **kw)
                    specs.append(spec)
                    closed.append(_closed_row(spec, base * factor * (jitter if told else 1.0)))
    opened = []
    for m, cov in COVERAGE.items():
        s = open_spec("ice", m, samples=10, demands=5, steps=5)
        specs.append(s)
        opened.append({"id": s["id"], "problem": "ice", "method": m, "coverage": cov, "coverage_lo": cov,
                       "coverage_hi": cov, "coverage_estimator": "polytope", "unatt_err_mean": 1 - cov,
                       "unatt_err_max": 1.0, "unatt_angle_mean": 0.0, "effort_mean": 1.0, "rate_violation_max": 0.0,
                       "traj_err_mean": 0.1, "fallbacks": 0, "calls": 10})
    _write(tmp_path / "closed_ice.csv", closed)
    _write(tmp_path / "open.csv", opened)
    return specs


def _loaded(tmp_path: Path, specs: list[dict]) -> tuple[list[dict], list[dict]]:
    from benchmarks.compare.report import load_rows

    tables = load_rows(tmp_path, specs)
    return closed_scores(tables["closed_ice"]), tables["open"]


# ----------------------------------------------------------------------------- statistics
def test_bootstrap_median_interval_holds_the_true_median_at_its_level() -> None:
    rng = np.random.default_rng(0)
    hits = 0
    for _ in range(300):
        x = rng.normal(3.0, 1.0, 15)
        est, lo, hi = bootstrap_median(x, n_boot=500, seed=int(rng.integers(1 << 30)))
        assert est == np.median(x) and lo <= est <= hi
        assert lo in x and hi in x  # order statistics: no interpolation
        hits += lo <= 3.0 <= hi
    assert 0.88 <= hits / 300 <= 0.995  # nominal 95 %, percentile bootstrap of a median with n = 15


def test_bootstrap_keeps_inf_and_drops_nan() -> None:
    est, lo, hi = bootstrap_median([1.0, 2.0, math.inf, math.inf, math.inf, math.nan])
    assert (est, hi) == (math.inf, math.inf) and lo in (1.0, 2.0, math.inf)
    assert bootstrap_median([2.0, 2.0, 2.0]) == (2.0, 2.0, 2.0)
    assert all(math.isnan(v) for v in bootstrap_median([math.nan]))


def test_paired_ratio() -> None:
    blind = np.array([1.0, 2.0, 3.0, 4.0, 5.0])
    assert paired_ratio(0.5 * blind, blind) == (0.5, 0.5, 0.5)  # exactly half in every pair
    assert paired_ratio([1.0, 1.0], [math.inf, math.inf])[0] == 0.0  # told survives, blind diverges
    with pytest.raises(ValueError, match="paired"):
        paired_ratio([1.0], [1.0, 2.0])


def test_rank_with_ties() -> None:
    ranks = rank_with_ties({"a": (0.5, 0.45, 0.55), "b": (0.52, 0.5, 0.6), "c": (2.0, 1.8, 2.2),
                            "d": (math.inf, math.inf, math.inf), "e": (math.nan, math.nan, math.nan)})
    assert ranks == {"a": 1, "b": 1, "c": 3, "d": 4, "e": 5}
    # diverged in most runs (median inf) but some survived (interval reaching down to the best):
    # ranked after every finite median, never tied for first (found in the ICE sweep: pinv_scale
    # told, jam1, stand-in pilot at gain 2, was listed at rank 1 with median inf)
    ranks = rank_with_ties({"a": (0.5, 0.45, 0.55), "b": (0.52, 0.5, 0.6), "f": (math.inf, 0.4, math.inf),
                            "d": (math.inf, math.inf, math.inf)})
    assert ranks == {"a": 1, "b": 1, "f": 3, "d": 3}  # both inf: they overlap, so they share


def test_spearman() -> None:
    assert spearman([1, 2, 3, 4], [8, 6, 4, 2])[:1] == (-1.0,)
    rho, p, n = spearman([1, 2, 3, 4, 5], [1, 2, math.inf, 3, math.nan])
    assert n == 4 and rho == pytest.approx(0.8)
    assert math.isnan(spearman([1, 2], [1, 2])[0])


# ----------------------------------------------------------------------------- report numbers
def test_scores_cells_and_ranking(tmp_path: Path, sweep: list[dict]) -> None:
    rows, _ = _loaded(tmp_path, sweep)
    pinv_blind = [r for r in rows if r["method"] == "pinv" and not r["told"]]
    assert all(r["score"] == pytest.approx(1.5) for r in pinv_blind)
    cells = cell_summaries(rows)
    look = {(c["failure"], c["method"], c["mode"]): c for c in cells}
    c = look[("seed", "da_facet", "told")]
    scores = [r["score"] for r in rows if (r["failure"], r["method"], r["told"]) == ("seed", "da_facet", True)]
    assert c["score"] == np.median(scores) and c["score_lo"] <= c["score"] <= c["score_hi"]
    assert c["runs"] == 10 and c["diverged"] == 0
    # da_facet told (0.5) and qp told (0.52) overlap: shared rank 1; then the 0.8s, then cgi, static, pinv
    ranks = {(m, mode): look[("seed", m, mode)]["rank"] for (f, m, mode) in look if f == "seed"}
    assert ranks[("da_facet", "told")] == ranks[("qp", "told")] == 1
    assert ranks[("qp", "blind")] == ranks[("da_facet", "blind")] == 3
    assert ranks[("pinv", "told")] == max(ranks.values())


def test_told_blind_and_coverage_agreement(tmp_path: Path, sweep: list[dict]) -> None:
    rows, open_rows = _loaded(tmp_path, sweep)
    ratios = {(r["failure"], r["method"]): r for r in told_blind(rows)}
    r = ratios[("seed", "pinv")]
    assert r["ratio"] == pytest.approx(2.0 / 1.5, rel=0.03) and r["verdict"] == "hurts" and r["pairs"] == 10
    assert ratios[("seed", "da_facet")]["verdict"] == "helps"
    cgi = ratios[("seed", "cgi")]
    assert (cgi["ratio"], cgi["ratio_lo"], cgi["ratio_hi"], cgi["verdict"]) == \
        (pytest.approx(1.0), pytest.approx(0.9), pytest.approx(1.1), "undecided")
    agree = {(a["failure"], a["mode"]): a for a in coverage_agreement(cell_summaries(rows), open_rows)}
    assert agree[("seed", "told")]["rho"] == pytest.approx(-1.0)  # more coverage, less error, exactly
    assert agree[("seed", "told")]["methods"] == 4


def test_diverged_runs_rank_last_and_a_diverged_static_leaves_no_score(tmp_path: Path, sweep: list[dict]) -> None:
    rows = list(csv.DictReader((tmp_path / "closed_ice.csv").open()))
    for r in rows:
        if r["method"] == "da_facet" and r["told"] == "True" and r["failure"] == "jam1":
            r["diverged"] = "True"
        if r["method"] == STATIC and r["seed"] == "1" and r["failure"] == "seed":
            r["diverged"] = "True"
    _write(tmp_path / "closed_ice.csv", rows)
    scored, _ = _loaded(tmp_path, sweep)
    cells = {(c["failure"], c["method"], c["mode"]): c for c in cell_summaries(scored)}
    jam = cells[("jam1", "da_facet", "told")]
    assert jam["score"] == math.inf and jam["diverged"] == 10
    assert jam["rank"] == max(c["rank"] for k, c in cells.items() if k[0] == "jam1")
    assert cells[("seed", "qp", "told")]["unscored"] == 1 and cells[("seed", "qp", "told")]["runs"] == 10


# ----------------------------------------------------------------------------- figures = tables
def _csv(path: Path) -> list[dict]:
    return list(csv.DictReader(path.open()))


def _fmt3(x: str) -> str:
    v = float(x)
    return "inf" if math.isinf(v) else f"{v:.3g}"


def test_heatmap_and_forest_data_are_the_tables_next_to_them(tmp_path: Path, sweep: list[dict]) -> None:
    text = make_report(tmp_path, sweep, {"sweep": "test", "command": "alloc bench test"}).read_text()
    assert "Command: `alloc bench test`" in text
    heat = _csv(tmp_path / "heatmap_ice_pilot_gain_1.csv")
    table = {(r["method"], r["allocator"]): r for r in parse_markdown_table(text, "method")}
    assert len(heat) == 2 * (1 + 2 * len(FACTORS))
    for d in heat:
        assert table[(d["method"], d["mode"])][d["failure"]] == \
            f"{_fmt3(d['score'])} [{_fmt3(d['score_lo'])}, {_fmt3(d['score_hi'])}]"
    forest = _csv(tmp_path / "forest_ice_pilot_gain_1.csv")
    ratio_table = {r["method (told / blind)"]: r for r in parse_markdown_table(text, "method (told / blind)")}
    assert len(forest) == 2 * len(FACTORS)
    for d in forest:
        assert ratio_table[d["method"]][d["failure"]] == \
            f"{_fmt3(d['ratio'])} [{_fmt3(d['ratio_lo'])}, {_fmt3(d['ratio_hi'])}]"
    for png in ("heatmap_ice_pilot_gain_1.png", "forest_ice_pilot_gain_1.png", "coverage.png"):
        assert (tmp_path / png).stat().st_size > 1000


def test_quick_sweep_shape() -> None:
    specs = quick_sweep()
    ids = [s["id"] for s in specs]
    assert len(set(ids)) == len(ids)
    assert not any(s["method"] == STATIC and s.get("told") for s in specs)  # a fixed matrix cannot be told
    kinds = [s["kind"] for s in specs]
    assert kinds == sorted(kinds)  # closed (long) runs are submitted first
    closed = [s for s in specs if s["kind"] == "closed"]
    import alloc

    assert {s["method"] for s in closed} == {STATIC, *alloc.methods()}
    assert any(s["history"] for s in closed)


def test_settings_pooled_and_verdicts_per_setting(tmp_path: Path) -> None:
    """Two simulator settings in which different methods win: the pooled section scores each run
    against ``static`` in its own setting, pairs told/blind within a setting and seed, and its
    verdict table names each setting's winner."""
    from benchmarks.compare.report import (
        ALL_SETTINGS, cell_summaries, closed_scores, load_rows, pooled_rows, told_blind, verdicts_by_setting,
    )

    winners = {"pilot_gain=1": "qp", "pilot_gain=2": "pinv"}
    rng = np.random.default_rng(3)
    specs, closed = [], []
    for sim, tag in (({"pilot_gain": 1.0}, "pilot_gain=1"), ({"pilot_gain": 2.0}, "pilot_gain=2")):
        static_rms = 1.0 if tag == "pilot_gain=1" else 3.0  # scores are relative to static in the same setting
        for s in SEEDS:
            for m in (STATIC, "qp", "pinv"):
                for told in ((False,) if m == STATIC else (True, False)):
                    spec = closed_spec("ice", "jam1", m, told=told, seed=s, duration=2.0, failure_time=1.0, sim=sim)
                    factor = 1.0 if m == STATIC else (0.5 if m == winners[tag] else 0.9)
                    factor *= (0.8 if told else 1.0) * (1 + 0.01 * rng.standard_normal())
                    row = _closed_row(spec, static_rms * factor)
                    row["setting"] = tag
                    specs.append(spec)
                    closed.append(row)
    _write(tmp_path / "closed_ice.csv", closed)
    rows = closed_scores(load_rows(tmp_path, specs)["closed_ice"])
    pooled = pooled_rows(rows)
    assert {r["setting"] for r in pooled} == {ALL_SETTINGS}
    assert len({(r["seed"]) for r in pooled}) == 2 * len(SEEDS)
    assert [r["score"] for r in pooled] == [r["score"] for r in rows]
    verdicts = verdicts_by_setting(cell_summaries(rows), ["jam1"])
    assert verdicts == [{"failure": "jam1", "pilot_gain=1": "qp told", "pilot_gain=2": "pinv told"}]
    from benchmarks.compare.report import verdict_stability
    assert verdict_stability(cell_summaries(rows), ["jam1"]) == [
        {"failure": "jam1", "settings": 2, "always": "-", "sometimes": "pinv told (1); qp told (1)"}]
    ratios = told_blind(pooled)
    assert {r["pairs"] for r in ratios} == {2 * len(SEEDS)}
    assert all(r["verdict"] == "helps" and abs(r["ratio"] - 0.8) < 0.02 for r in ratios)
    cells = {(c["method"], c["mode"]): c for c in cell_summaries(pooled)}
    assert cells[("qp", "told")]["runs"] == 2 * len(SEEDS)
    assert 0.4 < cells[("qp", "told")]["score"] < 0.72  # 0.4 in one setting, 0.72 in the other: the median between

    import json
    (tmp_path / "run.json").write_text(json.dumps({"sweep": "t", "command": "t", "date": "t", "cores": 2,
                                                   "load_avg_1min": 0, "platform": "t", "python": "t", "numpy": "t",
                                                   "engine": "t", "runs": len(specs), "ran": len(specs), "skipped": 0,
                                                   "wall_s": 1, "latency_pass_s": None}))
    text = make_report(tmp_path, specs).read_text()
    assert "ICE, all 2 simulator settings pooled" in text
    section = text.split("all 2 simulator settings pooled")[1]
    stable = parse_markdown_table(section, "failure")
    assert stable[0] == {"failure": "jam1", "rank 1 in every setting": "-",
                         "rank 1 in some settings": "pinv told (1); qp told (1)"}
    table = parse_markdown_table(section.split("<summary>")[1], "failure")
    assert table[0] == {"failure": "jam1", "pilot_gain=1": "qp told", "pilot_gain=2": "pinv told"}
    saved = list(csv.DictReader((tmp_path / "heatmap_ice_all_settings.csv").open()))
    qp_told = next(r for r in saved if (r["method"], r["mode"]) == ("qp", "told"))
    assert math.isclose(float(qp_told["score"]), cells[("qp", "told")]["score"])


def test_da_family_written_once_when_all_four_agree() -> None:
    from benchmarks.compare.summaries import _short

    four = [f"{m} told" for m in ("da", "da_bisect", "da_facet", "da_table")]
    assert _short([*four, "qp told"]) == "da* told, qp told"
    assert _short([*four[:3], "qp told"]) == "da told, da_bisect told, da_facet told, qp told"  # not all four


def test_baseline_fate_and_engineering_verdicts_beside_the_scores(tmp_path: Path, sweep: list[dict]) -> None:
    """Rows with verdicts: static diverges in 2 of 10 seed-failure runs (at 1.5 and 1.25 s) and breaks
    ps_rms_after in all; told qp breaks back_in_band_s in 3 of its 10; the others pass."""
    from benchmarks.compare.summaries import baseline_fate, broken_counts

    rows = list(csv.DictReader((tmp_path / "closed_ice.csv").open()))
    for r in rows:
        broken = []
        if r["method"] == STATIC:
            broken = ["ps_rms_after"]
            if r["failure"] == "seed" and r["seed"] in ("1", "2"):
                r["diverged"], r["simulated"] = "True", {"1": "1.5", "2": "1.25"}[r["seed"]]
                broken = ["diverged", "ps_rms_after"]
        elif r["method"] == "qp" and r["told"] == "True" and int(r["seed"]) <= 3:
            broken = ["back_in_band_s"]
        r["verdict_pass"], r["verdict_broken"] = str(not broken), ";".join(broken)
    _write(tmp_path / "closed_ice.csv", rows)
    scored, _ = _loaded(tmp_path, sweep)
    fates = {f["failure"]: f for f in baseline_fate(scored)}
    assert (fates["seed"]["runs"], fates["seed"]["diverged"], fates["seed"]["diverged_at"]) == (10, 2, "1.25, 1.50")
    assert fates["seed"]["passed"] == 0 and fates["seed"]["broken"] == "ps_rms_after (10), diverged (2)"
    assert fates["jam1"]["diverged"] == 0 and fates["jam1"]["diverged_at"] == "-"
    cells = {(c["failure"], c["method"], c["mode"]): c for c in cell_summaries(scored)}
    assert cells[("seed", "qp", "told")]["passed"] == 7 and cells[("seed", "qp", "told")]["broken"] == "back_in_band_s (3)"
    assert cells[("seed", STATIC, "blind")]["diverged_at"] == pytest.approx(1.375)
    assert broken_counts([]) == "-"
    text = make_report(tmp_path, sweep, {"sweep": "test"}).read_text()
    assert ("Baseline `static` (every score's denominator): diverged in 2 of 10 runs (at t = 1.25, 1.50 s; failure at "
            "1 s, runs of 2 s); met every engineering criterion in 0 of 10 (broken: ps_rms_after (10), diverged (2)).") in text
    met = {(r["method"], r["allocator"]): r for r in parse_markdown_table(text.split("Runs that met every")[1], "method")}
    assert met[("qp", "told")]["seed"] == "7 of 10" and met[(STATIC, "blind")]["jam1"] == "0 of 10"
    saved = {r["failure"]: r for r in _csv(tmp_path / "baseline_ice_pilot_gain_1.csv")}
    assert saved["seed"]["diverged_at"] == "1.25, 1.50" and saved["jam1"]["passed"] == "0"
    assert "met every engineering criterion in 0 of 20" in text  # the headline
