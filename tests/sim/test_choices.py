"""The verdict-driving choices table (sim.choices) and its generated docs page."""

from __future__ import annotations

from dataclasses import fields
from pathlib import Path

import numpy as np
import pytest

from benchmarks import bench_sensitivity

from sim.choices import render_markdown, verdict_choices
from sim.settings import SETTING, RunSettings

PAGE = Path(__file__).resolve().parents[2] / "docs" / "verdict-choices.md"


def test_every_verdict_setting_is_listed_and_only_those():
    listed = {c.name.removeprefix("setting ") for c in verdict_choices() if c.name.startswith("setting ")}
    flagged = {f.name for f in fields(RunSettings) if f.metadata[SETTING].verdict}
    assert listed == flagged
    assert "seed" not in listed and "record_every" not in listed  # bookkeeping is not a verdict choice


def test_every_choice_names_value_source_and_place():
    choices = verdict_choices()
    assert len({c.name for c in choices}) == len(choices)
    for c in choices:
        assert c.value and c.where and c.source
        assert c.source.startswith(("seed", "ours")), c


def test_the_project_s_own_choices_are_marked_ours():
    by_name = {c.name: c for c in verdict_choices()}
    for name in ("setting preferred", "setting anti_windup", "setting boundary_layer", "setting rate_window",
                 "setting rate_horizon", "Fig 4-81 bank-angle steps", "daisy groups (ICE)",
                 "divergence bound ICE", "stand-in pilot gain"):
        assert by_name[name].source.startswith("ours"), name
    assert "20 deg at 1 s" in by_name["Fig 4-81 bank-angle steps"].value


def test_docs_page_is_generated_from_the_committed_sweep():
    assert PAGE.read_text() == bench_sensitivity.choices_page(), \
        "regenerate: python -m benchmarks.bench_sensitivity page --out benchmarks/reference/sensitivity-2026-12-02b"


def test_every_swept_factor_is_a_row_of_the_choices_table():
    names = {c.name for c in verdict_choices()}
    swept = {v.factor for v in bench_sensitivity.factors()} - {"default"} | {"setting frame_period"}
    assert swept <= names, swept - names
    flipped = {r["factor"] for r in bench_sensitivity.read_flips(bench_sensitivity.REFERENCE / "flips.csv")}
    assert flipped <= swept
    # every factor the committed sweep flew is in the page; the rest say "not swept"
    page = PAGE.read_text()
    for name in swept - flipped:
        assert f"| {name} |" in page and "not swept" in page


def test_flips_column_without_a_sweep_is_absent():
    page = render_markdown()
    assert "| flips |" not in page and "| flips |" in render_markdown({"setting preferred": "0 of 16"})


def _row(factor, level, scenario, case, method, diverged, rms, base="2000 Hz"):
    return {"factor": factor, "level": level, "base": base, "scenario": scenario, "case": case, "method": method,
            "diverged": str(diverged), "t_end": "12.5" if diverged else "40.0", "rms_ps": f"{rms:g}"}


@pytest.mark.parametrize("seed", range(20))
def test_flips_counts_each_changed_verdict_against_the_default(seed):
    """Seeded random verdicts: the flip count equals a direct count, and the best method is the least ps RMS."""
    rng = np.random.default_rng(seed)
    methods = bench_sensitivity.METHODS
    keys = [(s, c, m) for s in ("ice", "harv_latdir") for c in ("failed", "nominal") for m in methods]
    base = {k: (bool(rng.random() < 0.4), float(rng.uniform(0.1, 9.0))) for k in keys}
    moved = {k: (d if rng.random() < 0.7 else not d, float(rng.uniform(0.1, 9.0))) for k, (d, _) in base.items()}
    rows = [_row("default", "default", *k, *v) for k, v in base.items()]
    rows += [_row("setting preferred", "zero", *k, *v) for k, v in moved.items()]
    (out,) = bench_sensitivity.flips(rows)
    assert out["runs"] == len(keys)
    assert out["flips"] == sum(base[k][0] != moved[k][0] for k in keys)
    for s, c in {(s, c) for s, c, _ in keys}:
        def best(table):
            bounded = [(table[(s, c, m)][1], m) for m in methods if not table[(s, c, m)][0]]
            return min(bounded)[1] if bounded else "none"
        changed = best(base) != best(moved)
        assert (f"{s} {c}: {best(base)} -> {best(moved)}" in out["best_flips"]) == changed


def test_flips_by_choice_sums_the_levels():
    rows = [{"factor": "x", "level": "a", "base": "2000 Hz", "runs": "16", "flips": "2", "best_flips": ""},
            {"factor": "x", "level": "b", "base": "100 Hz", "runs": "16", "flips": "0", "best_flips": "ice failed"}]
    assert bench_sensitivity.flips_by_choice(rows) == {"x": "2 of 32 verdicts flip (a: 2, b at 100 Hz: 0 + best)"}


def test_the_pilot_table_reads_each_crossover_wc_level_back_and_counts_its_flips():
    """The committed pilot re-run: a crossover_wc level's row shows the crossover it states, and its flips
    are the verdicts that differ from the default's, counted here from runs*.csv directly."""
    rows = bench_sensitivity.all_runs(bench_sensitivity.REFERENCE_PILOT)
    section = bench_sensitivity.pilot_section(bench_sensitivity.REFERENCE_PILOT)
    assert section in PAGE.read_text()
    default = {(r["scenario"], r["case"], r["method"]): r["diverged"] for r in rows
               if (r["factor"], r["base"]) == ("default", "2000 Hz")}
    levels = [v for v in bench_sensitivity.factors() if v.factor == "crossover_wc pilot crossover frequency"]
    assert levels
    for v in levels:
        wc = float(v.level.removesuffix(" rad/s"))
        for scenario in v.scenarios:
            mine = [r for r in rows if (r["factor"], r["level"], r["scenario"]) == (v.factor, v.level, scenario)]
            assert len(mine) == 8, (v.level, scenario)  # failed and nominal, four methods
            flips = sum(default[(scenario, r["case"], r["method"])] != r["diverged"] for r in mine)
            line = next(x for x in section.splitlines() if x.startswith(f"| {v.factor} = {v.level} | {scenario} |"))
            cells = [c.strip() for c in line.strip("|").split("|")]
            assert float(cells[2]) == pytest.approx(wc, abs=5e-3)
            assert cells[-1] == f"{flips} of 8"
