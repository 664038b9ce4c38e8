"""Markdown report and figures from a sweep folder's CSVs (every number and every figure comes from them).

Closed-loop score
    For each run, the post-failure RMS tracking error of each channel divided by that of the
    seed's static distribution (``static``, blind) in the same scenario, simulator setting,
    failure and noise seed, averaged over the channels: 1 = as good as the seed's design,
    0.5 = half its error.  A diverged run scores ``inf``; a run whose ``static`` partner
    diverged has no score (``nan``, counted apart).

Per cell (scenario x setting x failure x method x told/blind)
    the median score over noise seeds with a percentile-bootstrap 95 % interval, and the
    medians of the other per-run measures (time to recover, effort, unattainable and fallback
    fractions, time at a position limit).  Ranking per failure: 1 + the number of entries whose
    interval lies entirely below (better than) the entry's own; overlapping intervals share a rank.

Told / blind
    ``median(score told) / median(score blind)`` over the same noise seeds, with a paired
    bootstrap 95 % interval: < 1 with the interval below 1 means telling the allocator of the
    failed effectors helps; an interval straddling 1 means this sweep cannot tell.

Open-loop / closed-loop agreement
    Spearman rank correlation, over the registry methods, between AMS coverage on the scenario's
    own allocation problem (higher is better) and the closed-loop median score (lower is
    better), per failure and told/blind; a *negative* rho means more coverage, lower error
    (Bordignon and Durham's conclusion, which the seed's section 1.3.4.9 reports and questions:
    open-loop measures need not carry over to the closed loop).

Engineering verdict (rows that carry one)
    Each run judged by its scenario's pass/fail criteria (:mod:`sim.criteria`: tracking-error
    RMS and peak per channel, sideslip excursion, effector position- and rate-saturation share,
    time back inside the nominal band, divergence; nominal limits before the failure, failed-state
    limits after).  Per cell: the runs that met every criterion, and the criteria broken (runs).
    The fate of ``static``, every score's denominator, is given beside each score: how many of
    its runs diverged and when, and which criteria they broke.

Every figure ``X.png`` is written with ``X.csv``, the exact numbers it draws, taken from the
same summaries as the table printed next to it; time histories are drawn from the runs stored
in ``histories/`` by the sweep (never re-simulated).

The numbers are computed in :mod:`benchmarks.compare.summaries`, the figures drawn in
:mod:`benchmarks.compare.figures` and the cells formatted by :mod:`benchmarks.compare.tables`;
this module lays out the sections of ``report.md``.
"""


from __future__ import annotations

import csv
import json
import math
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from scipy.stats import rankdata

from .figures import HISTORY_DECIMATE, _method_order, _plot_coverage, _plot_forest, _plot_heatmap, _plot_history
from .figures import _subplots  # noqa: F401  (tests/sim/test_plot_backend.py draws through it from here)
from .runner import history_path
from .summaries import (ALL_SETTINGS, RANDOM, _channels, _groups, _mode, _open_pivot, _typed, baseline_fate,
                        cell_summaries, closed_scores, coverage_agreement, detected_share, has_verdicts, load_rows,
                        pooled_rows, told_blind, verdict_stability, verdicts_by_setting)
from .sweep import STATIC, Spec
from .tables import Row, _ci, _fmt, _pct, _slug, _table, _write_csv, parse_markdown_table
from .timing import TIMINGS_CSV

#: the summaries and the table parser are re-exported: a reader of the report finds them here
__all__ = ["make_report", "load_rows", "closed_scores", "cell_summaries", "told_blind", "detected_share", "coverage_agreement",
           "parse_markdown_table", "pooled_rows", "verdicts_by_setting", "verdict_stability", "ALL_SETTINGS",
           "HISTORY_DECIMATE"]

TITLES = {"ice": "ICE", "harv_latdir": "F-18/HARV lat-dir"}


#: fewer noise seeds than this per cell: the report says its intervals are indicative only
FEW_SEEDS = 10


# ----------------------------------------------------------------------------- closed-loop sections
def _failure_description(scenario: str, failure: str) -> str:
    from .failures import CATALOGUE_SCENARIOS, canonical_name, failed_effectors, is_catalogue

    if is_catalogue(failure):
        # the effectors by the names the scenario gives its catalogue (sim.failure_catalogue)
        who = ", ".join(failed_effectors(scenario)[: int(failure[-1])]) if scenario in CATALOGUE_SCENARIOS else "?"
        return f"{canonical_name(failure)[:-1]} of {who} (catalogue, effector only; see benchmarks/compare/failures.py)"
    try:
        from sim.scenarios import get_scenario

        return get_scenario(scenario).failures.get(failure, failure)
    except (KeyError, ImportError):
        return failure


def _failure_order(failures: Sequence[str]) -> list[str]:
    from .failures import canonical_name, catalogue_names

    cat = catalogue_names()
    place = {f: cat.index(canonical_name(f)) for f in failures if canonical_name(f) in cat}  # loe1 as effectiveness1
    return sorted(failures, key=lambda f: (f in place, place.get(f, 0), f))


def _heatmap_table(cells: Sequence[Row], failures: Sequence[str]) -> str:
    methods = _method_order(cells)
    look = {(c["method"], c["mode"], c["failure"]): c for c in cells}
    body = []
    for m in methods:
        for mode in ("blind", "told"):
            if not any((m, mode, f) in look for f in failures):
                continue
            body.append([m, mode] + [(_ci(look[(m, mode, f)]["score"], look[(m, mode, f)]["score_lo"],
                                          look[(m, mode, f)]["score_hi"]) if (m, mode, f) in look else "-")
                                     for f in failures])
    return _table(["method", "allocator", *failures], body)


def _ranking_table(cells: Sequence[Row], channels: Sequence[str]) -> str:
    verdicts = bool(cells) and "passed" in cells[0]
    headers = ["rank", "method", "allocator", "median score [95 % CI]", "runs", "diverged", "unscored",
               *[f"{c} RMS after" for c in channels], "recover (s)", "effort", "unattainable", "fallback",
               "pos. sat. (s)", *(["criteria met (runs)", "broken (runs)"] if verdicts else [])]
    body = [[c["rank"], c["method"], c["mode"], _ci(c["score"], c["score_lo"], c["score_hi"]), c["runs"],
             c["diverged"], c["unscored"], *[_fmt(c[f"{ch}_rms_after"]) for ch in channels], _fmt(c["recover_s"]),
             _fmt(c["effort_after"]), _fmt(c["unattainable_after"]), _fmt(c["fallback_after"]),
             _fmt(c["saturation_s"]), *([f"{c['passed']} of {c['runs']}", c["broken"]] if verdicts else [])]
            for c in cells]
    return _table(headers, body)


def _fate_line(fate: Row) -> str:
    """One sentence: what happened to ``static`` in one failure's runs."""
    text = (f"Baseline `{STATIC}` (every score's denominator): diverged in {fate['diverged']} of {fate['runs']} runs"
            + (f" (at t = {fate['diverged_at']} s; failure at {fate['failure_time']:g} s, runs of "
               f"{fate['duration']:g} s)" if fate["diverged"] else ""))
    if "passed" in fate:
        text += f"; met every engineering criterion in {fate['passed']} of {fate['runs']} (broken: {fate['broken']})"
    return text + "."


def _fate_table(fates: Sequence[Row]) -> str:
    verdicts = bool(fates) and "passed" in fates[0]
    return _table(["failure", "runs", "diverged", "diverged at t (s)", *(["criteria met", "broken (runs)"]
                                                                         if verdicts else [])],
                  [[f"`{f['failure']}`", f["runs"], f["diverged"], f["diverged_at"],
                    *([f["passed"], f["broken"]] if verdicts else [])] for f in fates])


def _criteria_table(cells: Sequence[Row], failures: Sequence[str]) -> str:
    """Method x failure: runs that met every engineering criterion, of the cell's runs."""
    look = {(c["method"], c["mode"], c["failure"]): c for c in cells}
    body = []
    for m in _method_order(cells):
        for mode in ("blind", "told"):
            if any((m, mode, f) in look for f in failures):
                body.append([m, mode] + [f"{look[(m, mode, f)]['passed']} of {look[(m, mode, f)]['runs']}"
                                         if (m, mode, f) in look else "-" for f in failures])
    return _table(["method", "allocator", *failures], body)


def _ratio_table(ratios: Sequence[Row], failures: Sequence[str]) -> str:
    look = {(r["method"], r["failure"]): r for r in ratios}
    body = []
    for m in sorted({r["method"] for r in ratios}):
        body.append([m] + [(_ci(look[(m, f)]["ratio"], look[(m, f)]["ratio_lo"], look[(m, f)]["ratio_hi"])
                            if (m, f) in look else "-") for f in failures])
    return _table(["method (told / blind)", *failures], body)


def _pick_history_runs(rows: Sequence[Row], cells: Sequence[Row], out: Path) -> list[Row]:
    """Stored runs to draw for one failure: static, the best-ranked told method with a stored
    run, and the same method blind, all at the first stored noise seed."""
    stored = [r for r in rows if history_path(out, r["id"]).exists()]
    if not stored:
        return []
    seed = min(int(r["seed"]) for r in stored)
    at_seed = {(r["method"], _mode(r)): r for r in stored if int(r["seed"]) == seed}
    picked = [at_seed[(STATIC, "blind")]] if (STATIC, "blind") in at_seed else []
    for c in cells:
        if c["mode"] == "told" and c["method"] != STATIC and (c["method"], "told") in at_seed:
            picked.append(at_seed[(c["method"], "told")])
            if (c["method"], "blind") in at_seed:
                picked.append(at_seed[(c["method"], "blind")])
            break
    return picked


def _closed_section(out: Path, scenario: str, setting: str, rows: list[Row], cells: list[Row],
                    ratios: list[Row], agreement: list[Row]) -> tuple[str, list[str]]:
    channels = _channels(rows)
    failures = _failure_order(sorted({r["failure"] for r in rows}))
    r0 = rows[0]
    tag = _slug(f"{scenario}_{setting}")
    title = f"{TITLES.get(scenario, scenario)}, simulator setting `{setting}`"
    lines = [f"### {title}", "",
             f"{len(rows)} runs: {r0['duration']:g} s, failure at t = {r0['failure_time']:g} s "
             f"(the same for every failure of the section), noise seeds {sorted({int(r['seed']) for r in rows})}, "
             f"failures {', '.join(f'`{f}`' for f in failures)}.", ""]
    n_seeds = len({int(r["seed"]) for r in rows})
    if n_seeds < FEW_SEEDS:
        lines += [f"**Only {n_seeds} noise seeds per cell:** a percentile bootstrap of a median over {n_seeds} values "
                  "can only return values between their extremes and under-covers; the intervals, the ties and the "
                  "told/blind verdicts below are indicative, not 95 % statements.", ""]
    figures = []
    png = _plot_heatmap(cells, failures, out, f"heatmap_{tag}", title)
    figures.append(png)
    lines += [f"![heat map: median score per method and failure]({png})", "",
              "Median score [95 % bootstrap CI] per method and failure (the heat map's numbers; "
              f"`{png[:-4]}.csv`):", "", _heatmap_table(cells, failures), ""]
    fates = {f["failure"]: f for f in baseline_fate(rows)}
    if fates:
        _write_csv(out / f"baseline_{tag}.csv", list(fates.values()))
        lines += [f"The baseline's own fate (`{STATIC}`, blind; `baseline_{tag}.csv`):", "",
                  _fate_table([fates[f] for f in failures if f in fates]), ""]
    if has_verdicts(rows):
        lines += ["Runs that met every engineering criterion (`sim.criteria`), per method and failure:", "",
                  _criteria_table(cells, failures), ""]
    for f in failures:
        fc = [c for c in cells if c["failure"] == f]
        lines += [f"#### `{f}`: {_failure_description(scenario, f)}", "",
                  *([_fate_line(fates[f]), ""] if f in fates else []), _ranking_table(fc, channels), ""]
    if ratios:
        png = _plot_forest(ratios, failures, out, f"forest_{tag}", title)
        figures.append(png)
        helps = sum(r["verdict"] == "helps" for r in ratios)
        hurts = sum(r["verdict"] == "hurts" for r in ratios)
        lines += ["#### Told vs blind", "",
                  f"Telling the allocator helps (interval below 1) in {helps} of {len(ratios)} method x failure "
                  f"cells, hurts (interval above 1) in {hurts}, undecided or unscored in "
                  f"{len(ratios) - helps - hurts}.  Ratio [95 % CI] (the forest plot's numbers; `{png[:-4]}.csv`):", "",
                  _ratio_table(ratios, failures), "", f"![told/blind forest plot]({png})", ""]
    if agreement:
        lines += ["#### AMS coverage vs closed-loop score", "",
                  "Spearman rho over the registry methods between coverage of the scenario's allocation problem "
                  "and the median score (negative: more coverage, less error):", "",
                  _table(["failure", "allocator", "methods", "rho", "p"],
                         [[a["failure"], a["mode"], a["methods"], _fmt(a["rho"], 2), _fmt(a["p"], 2)]
                          for a in agreement]), ""]
    for f in failures:
        fc = [c for c in cells if c["failure"] == f]
        picked = _pick_history_runs([r for r in rows if r["failure"] == f], fc, out)
        if len(picked) < 2:
            continue
        name = f"history_{tag}_{_slug(f)}"
        png = _plot_history(out, picked, name, f"{title}, failure {f}, noise seed {int(picked[0]['seed'])}")
        figures.append(png)
        lines += [f"#### Time history, `{f}` (stored runs)", "",
                  _table(["run id", "method", "allocator", "seed", "diverged",
                          *[f"{c} RMS after" for c in channels]],
                         [[p["id"], p["method"], _mode(p), int(p["seed"]), _fmt(p["diverged"]),
                           *[_fmt(p[f"{c}_rms_after"]) for c in channels]] for p in picked]),
                  "", f"![time history {f}]({png})", ""]
    return "\n".join(lines), figures


# ----------------------------------------------------------------------------- across settings
def _across_section(out: Path, scenario: str, rows: list[Row], cells_by_setting: list[Row]) -> tuple[str, list[Row],
                                                                                                    list[Row]]:
    """The scenario's runs pooled over its simulator settings: heat map, ranking, told/blind,
    and which method ranks first in each setting (does the verdict depend on the pilot or the
    frame rate?)."""
    settings = sorted({r["setting"] for r in rows})
    pooled = pooled_rows(rows)
    cells = cell_summaries(pooled)
    ratios = told_blind(pooled)
    failures = _failure_order(sorted({r["failure"] for r in rows}))
    tag = _slug(f"{scenario}_all_settings")
    title = f"{TITLES.get(scenario, scenario)}, all {len(settings)} simulator settings pooled"
    lines = [f"### {title}", "",
             f"{len(rows)} runs; settings {', '.join(f'`{st}`' for st in settings)}; each run scored against `static` "
             "in its own setting and noise seed, then pooled: a cell's median and interval are over every setting and "
             "seed (how a method does across pilots and frame rates, not in one of them).", ""]
    png = _plot_heatmap(cells, failures, out, f"heatmap_{tag}", title)
    lines += [f"![heat map: median score per method and failure, settings pooled]({png})", "",
              f"Median score [95 % bootstrap CI] (the heat map's numbers; `{png[:-4]}.csv`):", "",
              _heatmap_table(cells, failures), ""]
    verdicts = verdicts_by_setting(cells_by_setting, failures)
    _write_csv(out / f"verdicts_{tag}.csv", verdicts)
    stability = verdict_stability(cells_by_setting, failures)
    _write_csv(out / f"verdict_stability_{tag}.csv", stability)
    lines += [f"Does the verdict depend on the pilot or the frame rate?  Rank 1 (ties: overlapping 95 % intervals) "
              f"in every one of the {len(settings)} settings, and in only some (number of settings; "
              f"`verdict_stability_{tag}.csv`; `da*`: the four direct-allocation backends, which agree):", "",
              _table(["failure", "rank 1 in every setting", "rank 1 in some settings"],
                     [[v["failure"], v["always"], v["sometimes"]] for v in stability]), "",
              "<details><summary>Rank 1 per failure in each setting</summary>", "",
              _table(["failure", *settings], [[v["failure"], *[v[st] for st in settings]] for v in verdicts]), "",
              "</details>", ""]
    if ratios:
        png = _plot_forest(ratios, failures, out, f"forest_{tag}", title)
        helps = sum(r["verdict"] == "helps" for r in ratios)
        hurts = sum(r["verdict"] == "hurts" for r in ratios)
        lines += ["#### Told vs blind, settings pooled", "",
                  f"Telling the allocator helps in {helps} of {len(ratios)} method x failure cells, hurts in {hurts}. "
                  f"Ratio [95 % CI], pairs within a setting and noise seed (`{png[:-4]}.csv`):", "",
                  _ratio_table(ratios, failures), "", f"![told/blind forest plot, settings pooled]({png})", ""]
    _write_csv(out / f"closed_{scenario}_pooled_cells.csv", cells)
    return "\n".join(lines), cells, ratios


# ----------------------------------------------------------------------------- open loop
_OPEN_METRICS: list[tuple[str, str, bool, Callable[[float], str]]] = [
    # column, title, higher is better, format
    ("coverage", "AMS coverage (fraction of the AMS volume reached exactly)", True, _pct),
    ("unatt_err_mean", "Moment error on unattainable demands, mean |v - Bu|", False, _fmt),
    ("unatt_err_max", "Moment error on unattainable demands, max |v - Bu|", False, _fmt),
    ("unatt_angle_mean", "Direction error on unattainable demands, mean angle (deg) between Bu and v", False, _fmt),
    ("effort_mean", "Control effort on attainable demands, mean |u - up|", False, _fmt),
    ("traj_err_mean", "Moment error along the rate-limited demand trajectory, mean |v - Bu|", False, _fmt),
    ("rate_violation_max", "Rate-limit violation along the trajectory, max (units/s; 0 = compliant)", False, _fmt),
    ("fallbacks", "Fallbacks (status fallback) over all calls", False, _fmt),
]


def _ranks(values: Sequence[float], *, higher_is_better: bool = False) -> np.ndarray:
    """Ranks (1 = best, ties share the lowest) of values rounded to the 3 significant digits shown."""
    shown = np.array([float(f"{v:.3g}") if math.isfinite(v) else v for v in values])
    return rankdata(-shown if higher_is_better else shown, method="min")


def _open_section(rows: list[Row], spec: Spec) -> str:
    n_random = len({r["problem"] for r in rows if r["problem"].startswith("random")})
    samples, demands, steps = spec["samples"], spec["demands"], spec["steps"]
    titles = {"ice": "ICE", "harv_latdir": "HARV lat-dir", RANDOM: f"random ({n_random}, mean)"}
    lines = ["## Open loop", "",
             f"Problems: ICE (the seed's Eq 4.24 design problem the ICE loop's allocator gets), "
             f"F-18/HARV lat-dir (Eq 4.16), {n_random} seeded random 3 x 8 problems.  Coverage: exact "
             f"polytope volume for the pseudo-inverse family, else seeded Monte Carlo with {samples} samples "
             f"(Wilson 95 % interval in open.csv); the other measures use {demands} demands in and {demands} "
             f"outside the AMS and a {steps}-step trajectory.  Each table is ranked by the "
             f"mean rank over the problem columns (ties, to the 3 digits shown, share a rank).", ""]
    for column, title, higher, fmt in _OPEN_METRICS:
        groups, pivot = _open_pivot(rows, column)
        methods = sorted(pivot)
        ranks = np.mean([_ranks([pivot[m].get(g, math.nan) for m in methods], higher_is_better=higher)
                         for g in groups], axis=0)
        order = sorted(range(len(methods)), key=lambda i: (ranks[i], methods[i]))
        body = [[_fmt(float(ranks[i]), 2), methods[i]] + [fmt(pivot[methods[i]].get(g, math.nan)) for g in groups]
                for i in order]
        lines += [f"### {title}", "", _table(["mean rank", "method"] + [titles[g] for g in groups], body), ""]
    return "\n".join(lines)


def _latency_section(out: Path, meta: dict[str, Any]) -> str:
    path = out / TIMINGS_CSV
    if not path.exists():
        return ""
    rows = [{k: _typed(v) for k, v in r.items()} for r in csv.DictReader(path.open())]
    problems = list(dict.fromkeys(r["problem"] for r in rows))
    look = {(r["method"], r["problem"]): r for r in rows}
    methods = sorted({r["method"] for r in rows}, key=lambda m: look.get((m, problems[0]), {}).get("median_us", 0))
    body = [[m] + [f"{_fmt(look[(m, p)]['median_us'])} / {_fmt(look[(m, p)]['p99_us'])} "
                   f"(x{_fmt(look[(m, p)]['median_over_floor'], 2)})" if (m, p) in look else "-" for p in problems]
            for m in methods]
    floor = ", ".join(f"{p} {_fmt(look[(methods[0], p)]['floor_median_us'])} µs" for p in problems
                      if (methods[0], p) in look)
    return "\n".join([
        "## Latency per allocator call", "",
        f"Measured after the sweep, in one process with no other run of ours active "
        f"(`benchmarks/compare/timing.py`, {int(rows[0]['calls'])} warm calls per method and problem, demands "
        f"inside and outside the AMS).  Median / p99 in µs, and (x) the median over a floor measured in the same "
        f"pass (one Python call doing B @ u: {floor}).  The machine ({meta.get('cores', '?')} cores) was "
        f"shared with other jobs (1-min load average {meta.get('load_avg_1min', '?')} at the end of the sweep): "
        "compare ratios, not absolute times.", "",
        _table(["method", *[f"{p}: median / p99 µs (x floor)" for p in problems]], body), ""])


# ----------------------------------------------------------------------------- report
def _header(meta: dict[str, Any], report_s: float) -> str:
    return "\n".join([
        f"# Allocator comparison: `{meta.get('sweep', '?')}` sweep", "",
        f"- Command: `{meta.get('command', '?')}`",
        f"- Date: {meta.get('date', '?')}",
        f"- Machine: {meta.get('cores', '?')} cores ({meta.get('platform', '?')}), Python {meta.get('python', '?')}, "
        f"numpy {meta.get('numpy', '?')}; shared with other jobs (1-min load average "
        f"{meta.get('load_avg_1min', '?')} after the sweep)",
        f"- Engine: {meta.get('engine', '?')}; {meta.get('runs', '?')} runs in the sweep, this invocation ran "
        f"{meta.get('ran', '?')} and resumed {meta.get('skipped', '?')}; wall time: sweep {_fmt(meta.get('wall_s'))} s, "
        f"latency pass {_fmt(meta.get('latency_pass_s'))} s, report {report_s:.1f} s",
        "",
        "Generated by `benchmarks/compare/report.py` from the CSVs in this folder (one row per run; run "
        "wall times in `*_timings.csv`; stored time histories in `histories/`); every figure `X.png` has its "
        "numbers in `X.csv`.  Nothing is edited by hand.", "",
    ])


def _headline(cells: Sequence[Row], ratios: Sequence[Row], agreement: Sequence[Row]) -> list[str]:
    out = []
    for (scenario, setting), grp in _groups(cells, ("scenario", "setting")).items():
        best = []
        for f in _failure_order(sorted({c["failure"] for c in grp})):
            fc = [c for c in grp if c["failure"] == f]
            if not any(math.isfinite(c["score"]) for c in fc):  # static diverged: nothing to rank against
                best.append(f"`{f}`: no finite score (`{STATIC}` diverged in every seed, or every method did)")
                continue
            top = [f"{c['method']} {c['mode']} ({_fmt(c['score'], 2)})" for c in fc
                   if c["rank"] == 1 and c["method"] != STATIC]
            best.append(f"`{f}`: {', '.join(top) or 'static only'}")
        out.append(f"- **{TITLES.get(scenario, scenario)}, `{setting}`, rank 1 per failure** (median score; "
                   f"ties = overlapping 95 % intervals): " + "; ".join(best) + ".")
        rs = [r for r in ratios if (r["scenario"], r["setting"]) == (scenario, setting)]
        if rs:
            helps = sum(r["verdict"] == "helps" for r in rs)
            hurts = sum(r["verdict"] == "hurts" for r in rs)
            out.append(f"  Telling the allocator helps in {helps} of {len(rs)} method x failure cells (95 % interval "
                       f"of told/blind below 1), hurts in {hurts}.")
        ag = [a for a in agreement if (a["scenario"], a["setting"]) == (scenario, setting) and not math.isnan(a["rho"])]
        if ag:
            sig = sum(a["rho"] < 0 and a["p"] < 0.05 for a in ag)
            out.append(f"  Coverage vs closed-loop score: median Spearman rho {_fmt(float(np.median([a['rho'] for a in ag])), 2)} "
                       f"over {len(ag)} failure x allocator cases; negative with p < 0.05 in {sig}.")
        div = sum(c["diverged"] for c in grp)
        runs = sum(c["runs"] for c in grp)
        out.append(f"  Diverged: {div} of {runs} runs.")
    return out


def _fate_headline(fates: Sequence[Row], cells: Sequence[Row]) -> list[str]:
    """Per scenario and setting: what happened to ``static``, and which entries met every criterion in every run."""
    out = []
    for (scenario, setting), grp in _groups(fates, ("scenario", "setting")).items():
        runs = sum(f["runs"] for f in grp)
        per = "; ".join(f"`{f['failure']}` {f['diverged']} of {f['runs']}"
                        + (f" at t = {f['diverged_at']} s" if f["diverged"] else "") for f in grp)
        line = (f"- **Baseline `{STATIC}`, {TITLES.get(scenario, scenario)}, `{setting}`** (runs of "
                f"{grp[0]['duration']:g} s, failure at {grp[0]['failure_time']:g} s): diverged in "
                f"{sum(f['diverged'] for f in grp)} of {runs} runs ({per})")
        if "passed" in grp[0]:
            line += f"; met every engineering criterion in {sum(f['passed'] for f in grp)} of {runs}"
            good = [c for c in cells if (c["scenario"], c["setting"]) == (scenario, setting) and "passed" in c]
            for f in grp:
                every = sorted(f"{c['method']} {c['mode']}" for c in good
                               if c["failure"] == f["failure"] and c["passed"] == c["runs"])
                line += f".  `{f['failure']}`, every run met every criterion: {', '.join(every) or 'none'}"
        out.append(line + ".")
    return out


def make_report(out: Path | str, specs: Sequence[Spec], meta: dict[str, Any] | None = None) -> Path:
    """Write ``report.md``, its figures and their CSVs into ``out`` from the CSVs of ``specs``."""
    t0 = time.perf_counter()
    out = Path(out)
    meta = meta if meta is not None else json.loads((out / "run.json").read_text())
    tables = load_rows(out, specs)
    open_rows = tables.get("open", [])
    body: list[str] = []
    all_cells: list[Row] = []
    all_ratios: list[Row] = []
    all_agree: list[Row] = []
    pooled_cells: list[Row] = []
    pooled_ratios: list[Row] = []
    all_fates: list[Row] = []
    for name in sorted(t for t in tables if t.startswith("closed_")):
        rows = closed_scores(tables[name])
        if not rows:
            continue
        cells = cell_summaries(rows)
        all_fates += baseline_fate(rows)
        ratios = told_blind(rows)
        agree = coverage_agreement(cells, open_rows) if open_rows else []
        all_cells += cells
        all_ratios += ratios
        all_agree += agree
        _write_csv(out / f"{name}_cells.csv", cells)
        _write_csv(out / f"{name}_told_blind.csv", ratios)
        if any(_mode(r) == "detected" for r in rows):
            _write_csv(out / f"{name}_detected_share.csv", detected_share(rows))
        for (scenario,), grp in _groups(rows, ("scenario",)).items():
            if len({r["setting"] for r in grp}) > 1:
                section, pcells, pratios = _across_section(out, scenario, grp,
                                                           [c for c in cells if c["scenario"] == scenario])
                body.append(section)
                pooled_cells += pcells
                pooled_ratios += pratios
        for (scenario, setting), grp in _groups(rows, ("scenario", "setting")).items():
            key = (scenario, setting)
            section, _ = _closed_section(
                out, scenario, setting, grp,
                [c for c in cells if (c["scenario"], c["setting"]) == key],
                [r for r in ratios if (r["scenario"], r["setting"]) == key],
                [a for a in agree if (a["scenario"], a["setting"]) == key])
            body.append(section)
    parts = ["## Headline", "", *_headline(pooled_cells, pooled_ratios, []), *_headline(all_cells, all_ratios, all_agree),
             *_fate_headline(all_fates, all_cells), ""]
    if body:
        doc = __doc__ or ""
        parts += ["## Closed loop", "", "Definitions:", "",
                  "```", doc.split("\n\n", 1)[1].split("Every figure")[0].strip(), "```", "",
                  f"`{STATIC}` is the seed's printed distribution matrix (ICE: Eq 4.24), the seed's static design; "
                  "a fixed matrix cannot be told of a failure, so it runs blind only.  *blind*: the allocator keeps "
                  "the nominal problem; *told*: it is given the failed effectors' new limits and effectiveness "
                  "(plant changes, bandwidths and delays are never told).  Columns: see "
                  "`benchmarks/compare/closedloop.py` (recover: time until the 1 s windowed RMS error of every "
                  "channel stays within 2x its pre-failure value; effort: mean |u| / max deflection after the "
                  "failure; unattainable / fallback: fractions of post-failure allocator calls).", "", *body]
    if open_rows:
        png = _plot_coverage(open_rows, out)
        parts += [_open_section(open_rows, next(s for s in specs if s["kind"] == "open")),
                  f"![AMS coverage per method]({png})", ""]
    latency = _latency_section(out, meta)
    if latency:
        parts.append(latency)
    parts.insert(0, _header(meta, report_s=time.perf_counter() - t0))
    path = out / "report.md"
    path.write_text("\n".join(parts).rstrip() + "\n")
    return path
