"""Markdown report and PNG plots from the sweep's CSVs (every number comes from them).

Closed-loop score
    For each run, the post-failure RMS tracking error of each channel divided by that of
    the seed's static distribution (``static``, blind) with the same noise seed, averaged
    over the channels: 1 = as good as the seed's design, 0.5 = half its error.  A diverged
    run scores infinity.  A method's score is the mean over noise seeds.

Open-loop / closed-loop agreement
    Spearman rank correlation between a method's open-loop rank on the ICE problem
    (coverage: higher is better; moment error on unattainable demands: lower is better)
    and its closed-loop rank (score after the ICE failure), over the registry methods run
    in both.  +1: the open-loop measure orders the methods exactly as the closed loop does;
    0: no relation; negative: the opposite order.
"""

from __future__ import annotations

import json
import math
import time
from collections import defaultdict
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from scipy.stats import rankdata, spearmanr

from .runner import read_table, table_of
from .sweep import STATIC, Spec

__all__ = ["make_report", "load_rows", "closed_scores"]

Row = dict[str, Any]
DPI = 80
RANDOM = "random suite"
#: Coverage above which methods count as "covering" the AMS in the restricted rank correlation
GOOD_COVERAGE = 0.9


# ----------------------------------------------------------------------------- loading
def _typed(value: str) -> Any:
    if value == "":
        return None
    if value in ("True", "False"):
        return value == "True"
    try:
        return float(value)
    except ValueError:
        return value


def load_rows(out: Path, specs: Sequence[Spec]) -> dict[str, list[Row]]:
    """Typed rows of this sweep's specs, per table (rows of other sweeps in ``out`` ignored)."""
    wanted = {s["id"] for s in specs}
    tables: dict[str, list[Row]] = {}
    for name in sorted({table_of(s) for s in specs}):
        rows = [{k: _typed(v) for k, v in r.items()} for r in read_table(out / f"{name}.csv")]
        timing = {r["id"]: {k: _typed(v) for k, v in r.items()} for r in read_table(out / f"{name}_timings.csv")}
        for r in rows:
            r["id"] = str(r["id"])
            r.update({k: v for k, v in timing.get(r["id"], {}).items() if k != "id"})
        tables[name] = [r for r in rows if r["id"] in wanted]
    return tables


# ----------------------------------------------------------------------------- helpers
def _fmt(x: Any, digits: int = 3) -> str:
    if x is None:
        return "-"
    if isinstance(x, bool):
        return "yes" if x else "no"
    if isinstance(x, float):
        if math.isinf(x):
            return "diverged"
        if math.isnan(x):
            return "-"
        if x == 0:
            return "0"
        return f"{x:.{digits}g}"
    return str(x)


def _pct(x: float | None) -> str:
    return "-" if x is None or math.isnan(x) else f"{100 * x:.1f} %"


def _table(headers: Sequence[str], rows: Sequence[Sequence[Any]]) -> str:
    lines = ["| " + " | ".join(headers) + " |", "|" + "|".join("---" for _ in headers) + "|"]
    lines += ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]
    return "\n".join(lines)


def _channels(rows: Sequence[Row]) -> list[str]:
    return [k[: -len("_rms_after")] for k in rows[0] if k.endswith("_rms_after")] if rows else []


def _mode(row: Row) -> str:
    return "told" if row["told"] else "blind"


def _ranks(values: Sequence[float], *, higher_is_better: bool = False) -> np.ndarray:
    """Ranks (1 = best, ties share the lowest) of values rounded to the 3 significant digits
    shown, so differences below the printed precision (round-off) do not reorder methods."""
    shown = np.array([float(f"{v:.3g}") if math.isfinite(v) else v for v in values])
    return rankdata(-shown if higher_is_better else shown, method="min")


def _spearman(a: Sequence[float], b: Sequence[float]) -> float:
    a, b = np.asarray(a, float), np.asarray(b, float)
    if len(a) < 3 or np.ptp(a) == 0 or np.ptp(b) == 0:
        return math.nan
    return float(spearmanr(a, b).statistic)


# ----------------------------------------------------------------------------- closed loop
def closed_scores(rows: Sequence[Row]) -> list[Row]:
    """Add ``score`` (see module docstring) to each closed-loop row; returns the rows."""
    channels = _channels(rows)
    ref: dict[tuple, Row] = {}
    for r in rows:
        if r["method"] == STATIC:
            ref[(r["scenario"], r["failure"], r["seed"])] = r
    for r in rows:
        base = ref.get((r["scenario"], r["failure"], r["seed"]))
        if r["diverged"]:
            r["score"] = math.inf
        elif base is None or base["diverged"]:
            r["score"] = math.nan
        else:
            r["score"] = float(np.mean([r[f"{c}_rms_after"] / base[f"{c}_rms_after"] for c in channels]))
    return list(rows)


def _by_method_mode(rows: Sequence[Row]) -> dict[tuple[str, str], list[Row]]:
    groups: dict[tuple[str, str], list[Row]] = defaultdict(list)
    for r in rows:
        groups[(r["method"], _mode(r))].append(r)
    return groups


def _mean(values: Sequence[float]) -> float:
    vals = [v for v in values if v is not None]
    if not vals:
        return math.nan
    return math.inf if any(math.isinf(v) for v in vals) else float(np.mean(vals))


def _closed_summary(rows: Sequence[Row]) -> list[Row]:
    """One line per (method, blind/told): means over seeds, sorted by score."""
    channels = _channels(rows)
    out = []
    for (method, mode), grp in _by_method_mode(rows).items():
        line: Row = {"method": method, "mode": mode, "runs": len(grp),
                     "diverged": sum(bool(r["diverged"]) for r in grp),
                     "score": _mean([r["score"] for r in grp]),
                     "saturation": _mean([r["time_in_position_saturation"] for r in grp])}
        for c in channels:
            for metric in ("rms_before", "rms_after", "max_after"):
                line[f"{c}_{metric}"] = _mean([r[f"{c}_{metric}"] for r in grp])
        out.append(line)
    out.sort(key=lambda x: (math.isnan(x["score"]), x["score"], x["method"], x["mode"]))
    return out


def _closed_section(title: str, rows: list[Row]) -> tuple[str, list[Row]]:
    summary = _closed_summary(rows)
    channels = _channels(rows)
    r0 = rows[0]
    lines = [f"### {title}", "",
             f"{len(rows)} runs: {r0['duration']:g} s, failure at t = {r0['failure_time']:g} s, "
             f"noise seeds {sorted({int(r['seed']) for r in rows})}.  Ranked by score "
             "(mean over channels of post-failure RMS / the seed's static distribution's; lower is better).", ""]
    headers = ["rank", "method", "allocator", "score"] + [f"{c} RMS after" for c in channels] + \
        [f"{c} max after" for c in channels] + ["pos. sat. (s)", "diverged"]
    body = []
    for i, s in enumerate(summary, 1):
        body.append([i, s["method"], s["mode"], _fmt(s["score"])] +
                    [_fmt(s[f"{c}_rms_after"]) for c in channels] + [_fmt(s[f"{c}_max_after"]) for c in channels] +
                    [_fmt(s["saturation"]), f"{s['diverged']}/{s['runs']}"])
    lines += [_table(headers, body), ""]
    lines += ["Before the failure (sanity check: every allocator tracks the nominal plant), RMS:", ""]
    pre = sorted(summary, key=lambda s: (s["method"], s["mode"]))
    lines += [_table(["method", "allocator"] + [f"{c} RMS before" for c in channels],
                     [[s["method"], s["mode"]] + [_fmt(s[f"{c}_rms_before"]) for c in channels] for s in pre]), ""]
    told = {s["method"]: s for s in summary if s["mode"] == "told"}
    blind = {s["method"]: s for s in summary if s["mode"] == "blind"}
    both = sorted(set(told) & set(blind), key=lambda m: told[m]["score"])
    if both:
        lines += ["Blind vs told (score; ratio < 1: telling the allocator about the failed effectors helps):", ""]
        lines += [_table(["method", "blind", "told", "told / blind"],
                         [[m, _fmt(blind[m]["score"]), _fmt(told[m]["score"]),
                           _fmt(told[m]["score"] / blind[m]["score"]) if blind[m]["score"] else "-"] for m in both]), ""]
    return "\n".join(lines), summary


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
    ("latency_median_us", "Latency, median per call (µs, warm, in the worker)", False, _fmt),
    ("latency_p99_us", "Latency, 99th percentile per call (µs)", False, _fmt),
]


def _problem_group(problem: str) -> str:
    return RANDOM if problem.startswith("random") else problem


def _open_pivot(rows: Sequence[Row], column: str) -> tuple[list[str], dict[str, dict[str, float]]]:
    """``method -> group -> value`` (the random suite averaged)."""
    acc: dict[str, dict[str, list[float]]] = defaultdict(lambda: defaultdict(list))
    for r in rows:
        acc[r["method"]][_problem_group(r["problem"])].append(float(r[column]))
    groups = [g for g in ("ice", "harv_latdir", RANDOM) if any(g in v for v in acc.values())]
    return groups, {m: {g: float(np.mean(v)) for g, v in d.items()} for m, d in acc.items()}


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
             f"mean rank over the problem columns (ties, to the 3 digits shown, share a rank).  Latencies are "
             f"measured in the worker while the sweep's other runs share the cores: compare them within this "
             f"report, not across machines.", ""]
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


# ----------------------------------------------------------------------------- agreement
def _agreement(open_rows: Sequence[Row], summary: Sequence[Row]) -> tuple[str, dict[str, float]]:
    ice = {r["method"]: r for r in open_rows if r["problem"] == "ice"}
    rho: dict[str, float] = {}
    lines = []
    for mode in ("told", "blind"):
        score = {s["method"]: s["score"] for s in summary if s["mode"] == mode and s["method"] in ice}
        methods = sorted(score)
        if len(methods) < 3:
            continue
        closed_rank = _ranks([score[m] for m in methods])
        cov_rank = _ranks([ice[m]["coverage"] for m in methods], higher_is_better=True)
        err_rank = _ranks([ice[m]["unatt_err_mean"] for m in methods])
        rho[f"coverage_{mode}"] = _spearman(cov_rank, closed_rank)
        rho[f"error_{mode}"] = _spearman(err_rank, closed_rank)
        good = [m for m in methods if ice[m]["coverage"] >= GOOD_COVERAGE]
        rho[f"n_good_{mode}"] = len(good)
        rho[f"coverage_good_{mode}"] = _spearman(_ranks([ice[m]["coverage"] for m in good], higher_is_better=True),
                                                 _ranks([score[m] for m in good]))
        lines += [f"Allocator {mode} ({len(methods)} methods): Spearman rho(coverage rank, closed-loop rank) = "
                  f"{_fmt(rho[f'coverage_{mode}'], 2)}; rho(unattainable moment error rank, closed-loop rank) = "
                  f"{_fmt(rho[f'error_{mode}'], 2)}.  Among the {len(good)} methods reaching >= "
                  f"{100 * GOOD_COVERAGE:.0f} % of the AMS ({', '.join(good)}): rho(coverage, closed loop) = "
                  f"{_fmt(rho[f'coverage_good_{mode}'], 2)}.", ""]
        lines += [_table(["method", "ICE coverage", "coverage rank", "unatt. error", "error rank",
                          f"closed-loop score ({mode})", "closed-loop rank"],
                         [[m, _pct(ice[m]["coverage"]), _fmt(float(c), 3), _fmt(ice[m]["unatt_err_mean"]),
                           _fmt(float(e), 3), _fmt(score[m]), _fmt(float(r), 3)]
                          for m, c, e, r in sorted(zip(methods, cov_rank, err_rank, closed_rank), key=lambda t: t[3])]), ""]
    return "\n".join(lines), rho


# ----------------------------------------------------------------------------- plots
def _plt() -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _plot_open_bars(rows: Sequence[Row], out: Path) -> list[str]:
    plt = _plt()
    files = []
    for column, name, ylabel, log in (("coverage", "coverage.png", "AMS coverage (%)", False),
                                      ("latency_median_us", "latency.png", "latency per call (µs)", True)):
        groups, pivot = _open_pivot(rows, column)
        methods = sorted(pivot)
        fig, ax = plt.subplots(figsize=(9, 3.4))
        width = 0.8 / len(groups)
        for j, g in enumerate(groups):
            vals = np.array([pivot[m].get(g, math.nan) for m in methods])
            if column == "coverage":
                vals = 100 * vals
            bars = ax.bar(np.arange(len(methods)) + (j - (len(groups) - 1) / 2) * width, vals, width, label=g)
            if column == "latency_median_us":
                _, p99 = _open_pivot(rows, "latency_p99_us")
                hi = np.array([p99[m].get(g, math.nan) for m in methods])
                ax.errorbar([b.get_x() + b.get_width() / 2 for b in bars], vals,
                            yerr=[np.zeros_like(vals), np.maximum(hi - vals, 0)], fmt="none", ecolor="k", lw=0.7)
        ax.set_xticks(range(len(methods)), methods, rotation=30, ha="right", fontsize=8)
        ax.set_ylabel(ylabel + (" (bar: median, whisker: p99)" if log else ""), fontsize=8)
        if log:
            ax.set_yscale("log")
        ax.legend(fontsize=7, ncols=len(groups))
        ax.grid(axis="y", alpha=0.3)
        fig.tight_layout()
        fig.savefig(out / name, dpi=DPI)
        plt.close(fig)
        files.append(name)
    return files


def _plot_distributions(rows: Sequence[Row], summary: Sequence[Row], out: Path, name: str) -> str:
    plt = _plt()
    channels = _channels(rows)
    order = list(dict.fromkeys(s["method"] for s in summary))
    fig, axes = plt.subplots(1, len(channels), figsize=(3.3 * len(channels), 3.4), sharey=False)
    for ax, c in zip(np.atleast_1d(axes), channels):
        for k, (mode, colour, dx) in enumerate((("blind", "tab:red", -0.15), ("told", "tab:blue", 0.15))):
            xs, ys = [], []
            for i, m in enumerate(order):
                for r in rows:
                    if r["method"] == m and _mode(r) == mode and not r["diverged"]:
                        xs.append(i + dx)
                        ys.append(r[f"{c}_rms_after"])
            ax.scatter(xs, ys, s=14, color=colour, label=mode, alpha=0.8)
        ax.set_xticks(range(len(order)), order, rotation=45, ha="right", fontsize=7)
        ax.set_title(f"{c}: RMS error after failure (diverged runs omitted)", fontsize=8)
        ax.set_yscale("log")
        ax.grid(alpha=0.3)
    np.atleast_1d(axes)[0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out / name, dpi=DPI)
    plt.close(fig)
    return name


def _plot_history(best: Row, seed_row: Row, out: Path, name: str) -> str:
    """Re-run two specs (pure functions of their specs: same numbers) and overlay them."""
    from .closedloop import simulate_spec

    plt = _plt()
    runs = []
    for r in (seed_row, best):
        spec = {k: r[k] for k in ("scenario", "failure", "method", "told", "duration", "failure_time", "noise")}
        spec["seed"] = int(r["seed"])
        runs.append((f"{r['method']} ({_mode(r)})", simulate_spec(spec)))
    t_fail = float(best["failure_time"])
    fig, axes = plt.subplots(len(runs[0][1].channels), 1, figsize=(8, 6), sharex=True)
    for j, (ax, c) in enumerate(zip(axes, runs[0][1].channels)):
        for (label, res), colour in zip(runs, ("tab:red", "tab:blue")):
            sel = res.t >= t_fail - 1.0
            ax.plot(res.t[sel], res.reference[sel, j], color=colour, lw=0.8, ls="--")
            ax.plot(res.t[sel], res.output[sel, j], color=colour, lw=1.0, label=f"{label}: output (ref dashed)")
        ax.axvline(t_fail, color="k", lw=0.6)
        ax.set_ylabel(c, fontsize=8)
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=7, loc="upper left")
    axes[-1].set_xlabel("t (s); vertical line: failure", fontsize=8)
    fig.tight_layout()
    fig.savefig(out / name, dpi=DPI)
    plt.close(fig)
    return name


# ----------------------------------------------------------------------------- report
def _header(meta: dict[str, Any], report_s: float) -> str:
    return "\n".join([
        f"# Allocator comparison: `{meta.get('sweep', '?')}` sweep", "",
        f"- Command: `{meta.get('command', '?')}`",
        f"- Date: {meta.get('date', '?')}",
        f"- Machine: {meta.get('cores', '?')} cores ({meta.get('platform', '?')}), Python {meta.get('python', '?')}, "
        f"numpy {meta.get('numpy', '?')}",
        f"- Engine: {meta.get('engine', '?')}; this invocation ran {meta.get('ran', '?')} runs and skipped "
        f"{meta.get('skipped', '?')} already in the CSVs; wall time: sweep {_fmt(meta.get('wall_s'))} s, "
        f"report {report_s:.1f} s (tables, plots, two re-simulated time histories)",
        "",
        "Generated by `benchmarks/compare/report.py` from the CSVs in this folder (one row per run; "
        "timings in the `*_timings.csv` files); nothing is edited by hand.", "",
    ])


def make_report(out: Path | str, specs: Sequence[Spec], meta: dict[str, Any] | None = None,
                *, history: bool = True) -> Path:
    """Write ``report.md`` and its PNGs into ``out`` from the CSVs of ``specs``."""
    t0 = time.perf_counter()
    out = Path(out)
    meta = meta if meta is not None else json.loads((out / "run.json").read_text())
    tables = load_rows(out, specs)
    open_rows = tables.get("open", [])
    parts: list[str] = []
    headline: list[str] = []
    body: list[str] = []
    figures: list[str] = []
    ice_summary: list[Row] = []
    for name in sorted(t for t in tables if t.startswith("closed_")):
        rows = closed_scores(tables[name])
        for failure in sorted({r["failure"] for r in rows}):
            sub = [r for r in rows if r["failure"] == failure]
            scenario = sub[0]["scenario"]
            section, summary = _closed_section(f"{scenario}, failure `{failure}`", sub)
            body.append(section)
            tag = f"{scenario}_{failure}"
            figures.append(f"![{tag} tracking errors]({_plot_distributions(sub, summary, out, f'errors_{tag}.png')})")
            if scenario == "ice":
                ice_summary = summary
                headline += _headline_closed(summary, sub)
                finite = [s for s in summary if s["method"] != STATIC and math.isfinite(s["score"])]
                static = [r for r in sub if r["method"] == STATIC]
                if history and finite and static:
                    best = finite[0]
                    seed = min(int(r["seed"]) for r in static)
                    best_row = next(r for r in sub if r["method"] == best["method"] and _mode(r) == best["mode"]
                                    and int(r["seed"]) == seed)
                    static_row = next(r for r in static if int(r["seed"]) == seed)
                    png = _plot_history(best_row, static_row, out, f"history_{tag}.png")
                    figures.append(f"![{tag} time history: best method vs the seed's static distribution]({png})")
    agreement = ""
    if open_rows and ice_summary:
        agreement, rho = _agreement(open_rows, ice_summary)
        headline.append(
            "- **Open loop vs closed loop** (ICE, Spearman rank correlation with the post-failure score rank): "
            f"coverage rho = {_fmt(rho.get('coverage_told'), 2)} told, {_fmt(rho.get('coverage_blind'), 2)} blind; "
            f"moment error on unattainable demands rho = {_fmt(rho.get('error_told'), 2)} told, "
            f"{_fmt(rho.get('error_blind'), 2)} blind (+1 = same order, 0 = unrelated).  Among the methods "
            f"reaching >= {100 * GOOD_COVERAGE:.0f} % of the AMS ({_fmt(rho.get('n_good_told'))} told, "
            f"{_fmt(rho.get('n_good_blind'))} blind), coverage rho = {_fmt(rho.get('coverage_good_told'), 2)} told, "
            f"{_fmt(rho.get('coverage_good_blind'), 2)} blind.")
    if open_rows:
        headline += _headline_open(open_rows)
        figures = [f"![{f}]({f})" for f in _plot_open_bars(open_rows, out)] + figures
    parts += ["## Headline", "", *headline, ""]
    if body:
        parts += ["## Closed loop", "", "Score: " + (__doc__ or "").split("Closed-loop score")[1]
                  .split("Open-loop / closed-loop")[0].strip().replace("\n    ", " "), "",
                  f"`{STATIC}` is the seed's printed distribution matrix (ICE: Eq 4.24), the seed's static design; "
                  "a fixed matrix cannot be told of a failure, so it runs blind only.  *blind*: the allocator keeps "
                  "the nominal problem; *told*: it is given the failed effectors' new limits "
                  "(`allocator_knows_failure`; plant changes, bandwidth and delays are never told).", "", *body]
    if agreement:
        parts += ["## Open-loop ranking vs closed-loop ranking (ICE)", "", agreement]
    if open_rows:
        parts.append(_open_section(open_rows, next(s for s in specs if s["kind"] == "open")))
    if figures:
        parts += ["## Figures", "", *[f + "\n" for f in figures]]
    parts.insert(0, _header(meta, report_s=time.perf_counter() - t0))
    path = out / "report.md"
    path.write_text("\n".join(parts).rstrip() + "\n")
    return path


def _headline_closed(summary: Sequence[Row], rows: Sequence[Row]) -> list[str]:
    r0 = rows[0]
    out = []
    for mode in ("told", "blind"):
        ranked = [s for s in summary if s["mode"] == mode and s["method"] != STATIC]
        if ranked:
            top = ", ".join(f"{s['method']} ({_fmt(s['score'], 2)})" for s in ranked[:3])
            out.append(f"- **Best tracking after the ICE failure, allocator {mode}** (score: post-failure RMS / the "
                       f"seed's static distribution, 1 = as good as the seed; {r0['duration']:g} s runs, failure at "
                       f"{r0['failure_time']:g} s): {top}.")
    told = {s["method"]: s["score"] for s in summary if s["mode"] == "told"}
    blind = {s["method"]: s["score"] for s in summary if s["mode"] == "blind"}
    both = [m for m in told if m in blind and math.isfinite(told[m]) and math.isfinite(blind[m]) and blind[m] > 0]
    if both:
        ratios = {m: told[m] / blind[m] for m in both}
        better = sorted(m for m in both if ratios[m] < 1)
        out.append(f"- **Blind vs told**: telling the allocator lowers the score for {len(better)} of {len(both)} "
                   f"methods ({', '.join(better) or 'none'}); told/blind ratio from {_fmt(min(ratios.values()), 2)} "
                   f"to {_fmt(max(ratios.values()), 2)} (median {_fmt(float(np.median(list(ratios.values()))), 2)}).")
    diverged = sum(bool(r["diverged"]) for r in rows)
    out.append(f"- Diverged ICE runs: {diverged} of {len(rows)}.")
    return out


def _headline_open(rows: Sequence[Row]) -> list[str]:
    _, cov = _open_pivot(rows, "coverage")
    full = sorted(m for m, d in cov.items() if d.get("ice", 0) >= 0.999)
    worst_rate = max(float(r["rate_violation_max"]) for r in rows)
    fallbacks = int(sum(float(r["fallbacks"]) for r in rows))
    calls = int(sum(float(r["calls"]) for r in rows))
    return [f"- **Open loop**: methods reaching >= 99.9 % of the ICE AMS: {', '.join(full) or 'none'}; "
            f"pinv on ICE: {_pct(cov.get('pinv', {}).get('ice'))}.  Largest rate-limit violation over all methods and problems: "
            f"{_fmt(worst_rate)} units/s; fallbacks: {fallbacks} of {calls} calls."]
