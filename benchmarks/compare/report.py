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
    (the seed's claim, section 1.3.4.9: coverage predicts closed-loop rank).

Every figure ``X.png`` is written with ``X.csv``, the exact numbers it draws, taken from the
same summaries as the table printed next to it; time histories are drawn from the runs stored
in ``histories/`` by the sweep (never re-simulated).
"""

from __future__ import annotations

import csv
import json
import math
import time
from collections import defaultdict
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from scipy.stats import rankdata

from .runner import history_path, read_table, table_of
from .stats import bootstrap_median, paired_ratio, rank_with_ties, spearman
from .sweep import STATIC, Spec
from .timing import TIMINGS_CSV

__all__ = ["make_report", "load_rows", "closed_scores", "cell_summaries", "told_blind", "detected_share", "coverage_agreement",
           "parse_markdown_table", "pooled_rows", "verdicts_by_setting", "verdict_stability", "ALL_SETTINGS"]

Row = dict[str, Any]
DPI = 80
RANDOM = "random suite"
TITLES = {"ice": "ICE", "harv_latdir": "F-18/HARV lat-dir"}
COVERAGE_PROBLEM = {"ice": "ice", "harv_latdir": "harv_latdir"}
#: fewer noise seeds than this per cell: the report says its intervals are indicative only
FEW_SEEDS = 10


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
        for r in rows:
            r["id"] = str(r["id"])
            if "setting" in r:
                r["setting"] = str(r["setting"])
        tables[name] = [r for r in rows if r["id"] in wanted]
    return tables


# ----------------------------------------------------------------------------- helpers
def _fmt(x: Any, digits: int = 3) -> str:
    if x is None:
        return "-"
    if isinstance(x, bool):
        return "yes" if x else "no"
    if isinstance(x, (float, np.floating)):
        x = float(x)
        if math.isinf(x):
            return "inf"
        if math.isnan(x):
            return "-"
        if x == 0:
            return "0"
        return f"{x:.{digits}g}"
    return str(x)


def _ci(est: float, lo: float, hi: float) -> str:
    if math.isnan(est):
        return "-"
    return f"{_fmt(est)} [{_fmt(lo)}, {_fmt(hi)}]"


def _pct(x: float | None) -> str:
    return "-" if x is None or math.isnan(x) else f"{100 * x:.1f} %"


def _table(headers: Sequence[str], rows: Sequence[Sequence[Any]]) -> str:
    lines = ["| " + " | ".join(headers) + " |", "|" + "|".join("---" for _ in headers) + "|"]
    lines += ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]
    return "\n".join(lines)


def parse_markdown_table(text: str, first_header: str) -> list[dict[str, str]]:
    """Rows of the first Markdown table in ``text`` whose first header cell is ``first_header``."""
    lines = text.splitlines()
    for i, line in enumerate(lines):
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if line.startswith("|") and cells[0] == first_header:
            out = []
            for body in lines[i + 2:]:
                if not body.startswith("|"):
                    break
                out.append(dict(zip(cells, (c.strip() for c in body.strip().strip("|").split("|")))))
            return out
    raise KeyError(f"no table with first header {first_header!r}")


def _write_csv(path: Path, rows: Sequence[Row]) -> None:
    with path.open("w", newline="") as fh:
        w = csv.DictWriter(fh, list(rows[0]) if rows else [], lineterminator="\n")
        w.writeheader()
        w.writerows(rows)


def _channels(rows: Sequence[Row]) -> list[str]:
    return [k[: -len("_rms_after")] for k in rows[0] if k.endswith("_rms_after")] if rows else []


def _mode(row: Row) -> str:
    if "mode" in row:  # a summary
        return row["mode"]
    if row.get("health"):  # the arm (rows written before the detected arm have none)
        return row["health"]
    return "told" if row["told"] else "blind"


def _median(values: Sequence[Any]) -> float:
    vals = [float(v) for v in values if v is not None and not (isinstance(v, float) and math.isnan(v))]
    return float(np.median(vals)) if vals else math.nan


def _slug(text: str) -> str:
    return "".join(c if c.isalnum() or c in "-_." else "_" for c in text)


# ----------------------------------------------------------------------------- closed loop
def closed_scores(rows: Sequence[Row]) -> list[Row]:
    """Add ``score`` (see module docstring) to each closed-loop row; returns the rows."""
    channels = _channels(rows)
    ref = {(r["scenario"], r["setting"], r["failure"], r["seed"]): r for r in rows if r["method"] == STATIC}
    for r in rows:
        base = ref.get((r["scenario"], r["setting"], r["failure"], r["seed"]))
        if r["diverged"]:
            r["score"] = math.inf
        elif base is None or base["diverged"]:
            r["score"] = math.nan
        else:
            r["score"] = float(np.mean([r[f"{c}_rms_after"] / base[f"{c}_rms_after"] for c in channels]))
    return list(rows)


def _groups(rows: Sequence[Row], keys: Sequence[str]) -> dict[tuple, list[Row]]:
    out: dict[tuple, list[Row]] = defaultdict(list)
    for r in rows:
        out[tuple(_mode(r) if k == "mode" else r[k] for k in keys)].append(r)
    return out


def cell_summaries(rows: Sequence[Row]) -> list[Row]:
    """One summary per (scenario, setting, failure, method, mode) of scored rows, with ``rank``
    within its (scenario, setting, failure)."""
    channels = _channels(rows)
    cells = []
    for (scenario, setting, failure, method, mode), grp in _groups(
            rows, ("scenario", "setting", "failure", "method", "mode")).items():
        est, lo, hi = bootstrap_median([r["score"] for r in grp])
        cell: Row = {"scenario": scenario, "setting": setting, "failure": failure, "method": method, "mode": mode,
                     "runs": len(grp), "diverged": sum(bool(r["diverged"]) for r in grp),
                     "unscored": sum(math.isnan(r["score"]) for r in grp),
                     "score": est, "score_lo": lo, "score_hi": hi,
                     "recover_s": _median([r.get("recover_s") for r in grp]),
                     "effort_after": _median([r.get("effort_after") for r in grp]),
                     "unattainable_after": _median([r.get("unattainable_after") for r in grp]),
                     "fallback_after": _median([r.get("fallback_after") for r in grp]),
                     "saturation_s": _median([r.get("time_in_position_saturation") for r in grp])}
        for c in channels:
            cell[f"{c}_rms_before"] = _median([r[f"{c}_rms_before"] for r in grp])
            cell[f"{c}_rms_after"] = _median([r[f"{c}_rms_after"] for r in grp if not r["diverged"]])
        cells.append(cell)
    for _, grp in _groups(cells, ("scenario", "setting", "failure")).items():
        ranks = rank_with_ties({(c["method"], c["mode"]): (c["score"], c["score_lo"], c["score_hi"]) for c in grp})
        for c in grp:
            c["rank"] = ranks[(c["method"], c["mode"])]
    cells.sort(key=lambda c: (c["scenario"], c["setting"], c["failure"], c["rank"],
                              math.inf if math.isnan(c["score"]) else c["score"], c["method"], c["mode"]))
    return cells


def detected_share(rows: Sequence[Row], resamples: int = 2000, seed: int = 0) -> list[Row]:
    """The oracle's benefit that survives detection, per (scenario, setting, failure, method):
    ``(median blind - median detected) / (median blind - median told)`` of the scores over the seeds
    all three arms ran, with a 95 % bootstrap interval resampling those seeds (NaN where told is no
    better than blind, or a score is not finite)."""
    rng = np.random.default_rng(seed)

    def share(b: np.ndarray, t: np.ndarray, d: np.ndarray) -> float:
        gain = np.median(b) - np.median(t)
        return float((np.median(b) - np.median(d)) / gain) if np.isfinite(gain) and gain > 0 else math.nan

    out = []
    for (scenario, setting, failure, method), grp in _groups(rows, ("scenario", "setting", "failure", "method")).items():
        arms = {a: {int(r["seed"]): float(r["score"]) for r in grp if _mode(r) == a} for a in ("blind", "told", "detected")}
        seeds = sorted(set(arms["blind"]) & set(arms["told"]) & set(arms["detected"]))
        if not seeds:
            continue
        b, t, d = (np.array([arms[a][s] for s in seeds]) for a in ("blind", "told", "detected"))
        est = share(b, t, d) if np.isfinite(np.concatenate([b, t, d])).all() else math.nan
        boots = []
        for _ in range(resamples if not math.isnan(est) else 0):
            i = rng.integers(len(seeds), size=len(seeds))
            boots.append(share(b[i], t[i], d[i]))
        boots_arr = np.array([x for x in boots if not math.isnan(x)])
        lo, hi = (np.percentile(boots_arr, [2.5, 97.5]) if boots_arr.size else (math.nan, math.nan))
        out.append({"scenario": scenario, "setting": setting, "failure": failure, "method": method,
                    "seeds": len(seeds), "share": est, "share_lo": float(lo), "share_hi": float(hi)})
    out.sort(key=lambda r: (r["scenario"], r["setting"], r["failure"], r["method"]))
    return out


def told_blind(rows: Sequence[Row]) -> list[Row]:
    """Paired told/blind ratio per (scenario, setting, failure, method) (see module docstring)."""
    out = []
    for (scenario, setting, failure, method), grp in _groups(rows, ("scenario", "setting", "failure", "method")).items():
        told = {int(r["seed"]): r["score"] for r in grp if _mode(r) == "told"}
        blind = {int(r["seed"]): r["score"] for r in grp if _mode(r) == "blind"}
        seeds = sorted(set(told) & set(blind))
        if not seeds:
            continue
        est, lo, hi = paired_ratio([told[s] for s in seeds], [blind[s] for s in seeds])
        verdict = ("helps" if hi < 1 else "hurts" if lo > 1 else "undecided") if not math.isnan(est) else "no score"
        out.append({"scenario": scenario, "setting": setting, "failure": failure, "method": method, "pairs": len(seeds),
                    "ratio": est, "ratio_lo": lo, "ratio_hi": hi, "verdict": verdict})
    out.sort(key=lambda r: (r["scenario"], r["setting"], r["failure"], r["method"]))
    return out


def coverage_agreement(cells: Sequence[Row], open_rows: Sequence[Row]) -> list[Row]:
    """Spearman rho between coverage on the scenario's problem and the median closed-loop score,
    per (scenario, setting, failure, mode), over the registry methods present in both."""
    out = []
    for (scenario, setting, failure, mode), grp in _groups(cells, ("scenario", "setting", "failure", "mode")).items():
        problem = COVERAGE_PROBLEM.get(scenario)
        cov = {r["method"]: float(r["coverage"]) for r in open_rows if r["problem"] == problem}
        methods = sorted(c["method"] for c in grp if c["method"] in cov)
        score = {c["method"]: c["score"] for c in grp}
        rho, p, n = spearman([cov[m] for m in methods], [score[m] for m in methods])
        out.append({"scenario": scenario, "setting": setting, "failure": failure, "mode": mode, "methods": n,
                    "rho": rho, "p": p})
    out.sort(key=lambda r: (r["scenario"], r["setting"], r["failure"], r["mode"]))
    return out


# ----------------------------------------------------------------------------- plots
def _subplots(*grid: int, **kwargs: Any) -> tuple[Any, Any]:
    """A bare :class:`matplotlib.figure.Figure` and its axes (``Figure.subplots`` arguments).

    No pyplot: no backend is chosen here, and ``savefig`` renders a PNG through Agg
    with or without a display.
    """
    from matplotlib.figure import Figure

    fig = Figure(figsize=kwargs.pop("figsize"))
    return fig, fig.subplots(*grid, **kwargs)


def heatmap_data(cells: Sequence[Row]) -> list[Row]:
    """What the heat map draws: median score per method, mode and failure."""
    return [{"method": c["method"], "mode": c["mode"], "failure": c["failure"], "score": c["score"],
             "score_lo": c["score_lo"], "score_hi": c["score_hi"]} for c in cells]


def _method_order(cells: Sequence[Row]) -> list[str]:
    methods = sorted({c["method"] for c in cells})
    return [STATIC] + [m for m in methods if m != STATIC] if STATIC in methods else methods


def _plot_heatmap(cells: Sequence[Row], failures: Sequence[str], out: Path, name: str, title: str) -> str:
    from matplotlib.colors import LogNorm

    data = heatmap_data(cells)
    _write_csv(out / f"{name}.csv", data)
    methods = _method_order(cells)
    value = {(d["method"], d["mode"], d["failure"]): d["score"] for d in data}
    fig, axes = _subplots(1, 2, figsize=(2.0 + 0.75 * len(failures) * 2, 1.2 + 0.32 * len(methods)), sharey=True)
    norm = LogNorm(vmin=0.25, vmax=4.0)
    for ax, mode in zip(axes, ("blind", "told")):
        grid = np.array([[value.get((m, mode, f), math.nan) for f in failures] for m in methods])
        shown = np.where(np.isinf(grid), 4.0, grid)
        img = ax.imshow(np.clip(shown, 0.25, 4.0), cmap="RdYlGn_r", norm=norm, aspect="auto")
        for i in range(len(methods)):
            for j in range(len(failures)):
                ax.text(j, i, "div" if np.isinf(grid[i, j]) else _fmt(grid[i, j], 2), ha="center", va="center",
                        fontsize=6)
        ax.set_xticks(range(len(failures)), failures, rotation=45, ha="right", fontsize=7)
        ax.set_yticks(range(len(methods)), methods, fontsize=7)
        ax.set_title(f"allocator {mode}", fontsize=8)
    fig.colorbar(img, ax=axes, shrink=0.8).set_label("median score: post-failure RMS / static's\n(log scale; div: diverged)",
                                                     fontsize=7)
    fig.suptitle(title, fontsize=9, y=1.0 + 0.3 / (1.2 + 0.32 * len(methods)))
    fig.savefig(out / f"{name}.png", dpi=DPI, bbox_inches="tight")
    return f"{name}.png"


def _plot_forest(ratios: Sequence[Row], failures: Sequence[str], out: Path, name: str, title: str) -> str:
    data = [{k: r[k] for k in ("failure", "method", "pairs", "ratio", "ratio_lo", "ratio_hi")} for r in ratios]
    _write_csv(out / f"{name}.csv", data)
    methods = sorted({r["method"] for r in ratios})
    cols = min(4, len(failures))
    nrows = math.ceil(len(failures) / cols)
    fig, axes = _subplots(nrows, cols, figsize=(3.0 * cols, 1.0 + nrows * (0.5 + 0.2 * len(methods))),
                             sharey=True, squeeze=False)
    lookup = {(r["failure"], r["method"]): r for r in ratios}
    for k, ax in enumerate(axes.flat):
        if k >= len(failures):
            ax.axis("off")
            continue
        f = failures[k]
        for i, m in enumerate(methods):
            r = lookup.get((f, m))
            if r is None or math.isnan(r["ratio"]):
                continue
            est, lo, hi = (min(max(x, 1 / 16), 16) for x in (r["ratio"], r["ratio_lo"], r["ratio_hi"]))
            colour = "tab:green" if r["ratio_hi"] < 1 else "tab:red" if r["ratio_lo"] > 1 else "0.4"
            ax.plot([lo, hi], [i, i], color=colour, lw=1.2)
            ax.plot([est], [i], "o", color=colour, ms=3)
        ax.axvline(1.0, color="k", lw=0.6)
        ax.set_xscale("log")
        ax.set_xlim(1 / 16, 16)
        ax.set_title(f, fontsize=8)
        ax.set_yticks(range(len(methods)), methods, fontsize=6)
        ax.tick_params(axis="x", labelsize=6)
        ax.grid(axis="x", alpha=0.3)
    fig.suptitle(title + "\ntold / blind median score, 95 % paired bootstrap (< 1: telling helps; clipped to 1/16..16)",
                 fontsize=8)
    fig.tight_layout(rect=(0, 0, 1, 1 - 0.45 / fig.get_figheight()))
    fig.savefig(out / f"{name}.png", dpi=DPI)
    return f"{name}.png"


HISTORY_DECIMATE = 4


def history_data(out: Path, row_ids: Sequence[str], labels: Sequence[str]) -> tuple[list[Row], list[str]]:
    """What a time-history figure draws: every ``HISTORY_DECIMATE``-th stored sample of each run
    (columns ``t`` and ``<label>:<channel>:reference|output``), and the channels."""
    runs = [np.load(history_path(out, i)) for i in row_ids]
    channels = [str(c) for c in runs[0]["channels"]]
    n = min(len(r["t"]) for r in runs)
    rows: list[Row] = []
    for k in range(0, n, HISTORY_DECIMATE):
        row: Row = {"t": float(runs[0]["t"][k])}
        for label, run in zip(labels, runs):
            for j, c in enumerate(channels):
                row[f"{label}:{c}:reference"] = float(run["reference"][k, j])
                row[f"{label}:{c}:output"] = float(run["output"][k, j])
        rows.append(row)
    return rows, channels


def _plot_history(out: Path, picked: Sequence[Row], name: str, title: str) -> str:
    labels = [f"{r['method']} ({_mode(r)})" for r in picked]
    data, channels = history_data(out, [r["id"] for r in picked], labels)
    _write_csv(out / f"{name}.csv", data)
    t = np.array([d["t"] for d in data])
    t_fail = float(picked[0]["failure_time"])
    fig, axes = _subplots(len(channels), 1, figsize=(8, 1.9 * len(channels)), sharex=True, squeeze=False)
    colours = ("k", "tab:red", "tab:blue", "tab:green")
    for ax, c in zip(axes[:, 0], channels):
        for label, colour in zip(labels, colours):
            ax.plot(t, [d[f"{label}:{c}:reference"] for d in data], color=colour, lw=0.6, ls="--")
            ax.plot(t, [d[f"{label}:{c}:output"] for d in data], color=colour, lw=0.9, label=f"{label}")
        ax.axvline(t_fail, color="0.3", lw=0.8, ls=":", label="failure")
        ax.set_ylabel(c, fontsize=8)
        ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=7, loc="upper left", ncols=len(labels) + 1)
    axes[-1, 0].set_xlabel("t (s); solid: output, dashed: reference", fontsize=8)
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    fig.savefig(out / f"{name}.png", dpi=DPI)
    return f"{name}.png"


# ----------------------------------------------------------------------------- closed-loop sections
def _failure_description(scenario: str, failure: str) -> str:
    from .failures import FAILED_EFFECTORS, canonical_name, is_catalogue

    if is_catalogue(failure):
        from alloc import vehicles

        names = {"ice": vehicles.ICE_EFFECTORS, "harv_latdir": vehicles.HARV_LATDIR_EFFECTORS}.get(scenario)
        idx = FAILED_EFFECTORS.get(scenario, ())[: int(failure[-1])]
        who = ", ".join(names[i] for i in idx) if names else "?"
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
    headers = ["rank", "method", "allocator", "median score [95 % CI]", "runs", "diverged", "unscored",
               *[f"{c} RMS after" for c in channels], "recover (s)", "effort", "unattainable", "fallback",
               "pos. sat. (s)"]
    body = [[c["rank"], c["method"], c["mode"], _ci(c["score"], c["score_lo"], c["score_hi"]), c["runs"],
             c["diverged"], c["unscored"], *[_fmt(c[f"{ch}_rms_after"]) for ch in channels], _fmt(c["recover_s"]),
             _fmt(c["effort_after"]), _fmt(c["unattainable_after"]), _fmt(c["fallback_after"]),
             _fmt(c["saturation_s"])] for c in cells]
    return _table(headers, body)


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
             f"(HARV `failure2`: at 0 s), noise seeds {sorted({int(r['seed']) for r in rows})}, "
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
    for f in failures:
        fc = [c for c in cells if c["failure"] == f]
        lines += [f"#### `{f}`: {_failure_description(scenario, f)}", "", _ranking_table(fc, channels), ""]
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
#: the ``setting`` of rows pooled over every simulator setting of a scenario
ALL_SETTINGS = "all settings"


def pooled_rows(rows: Sequence[Row]) -> list[Row]:
    """Copies of scored closed-loop rows with the simulator settings pooled (``setting`` =
    :data:`ALL_SETTINGS`); ``seed`` renumbered per (setting, seed), so told/blind pairs stay
    within one setting and one noise seed.  Scores are those of :func:`closed_scores`, each
    relative to ``static`` in its own setting."""
    ids: dict[tuple[str, int], int] = {}
    out = []
    for r in rows:
        c = dict(r)
        c["setting"] = ALL_SETTINGS
        c["seed"] = ids.setdefault((r["setting"], int(r["seed"])), len(ids) + 1)
        out.append(c)
    return out


def verdicts_by_setting(cells: Sequence[Row], failures: Sequence[str]) -> list[Row]:
    """Rank-1 methods (ties included, ``static`` left out) per failure and simulator setting."""
    settings = sorted({c["setting"] for c in cells})
    out = []
    for f in failures:
        row: Row = {"failure": f}
        for st in settings:
            top = sorted(f"{c['method']} {c['mode']}" for c in cells
                         if c["failure"] == f and c["setting"] == st and c["rank"] == 1 and c["method"] != STATIC)
            row[st] = ", ".join(top) or "static only"
        out.append(row)
    return out


#: the direct-allocation family: one allocation by four backends (identical closed-loop rows in
#: the sweeps); shown as ``da*`` when all four share a verdict
DA_FAMILY = ("da", "da_bisect", "da_facet", "da_table")


def _short(entries: Sequence[str]) -> str:
    """``method mode`` entries, with the four ``da*`` backends of one mode written once as ``da*``."""
    items = sorted(set(entries))
    for mode in ("blind", "told"):
        family = [f"{m} {mode}" for m in DA_FAMILY]
        if all(f in items for f in family):
            items = [i for i in items if i not in family] + [f"da* {mode}"]
    return ", ".join(sorted(items))


def verdict_stability(cells: Sequence[Row], failures: Sequence[str]) -> list[Row]:
    """Per failure: the entries (method and allocator mode, ``static`` left out) at rank 1 in
    every simulator setting, and those at rank 1 in only some, with the count of settings."""
    settings = sorted({c["setting"] for c in cells})
    out = []
    for f in failures:
        count: dict[str, int] = defaultdict(int)
        for c in cells:
            if c["failure"] == f and c["rank"] == 1 and c["method"] != STATIC:
                count[f"{c['method']} {c['mode']}"] += 1
        always = [e for e, n in count.items() if n == len(settings)]
        some = sorted(((e, n) for e, n in count.items() if n < len(settings)), key=lambda en: (-en[1], en[0]))
        out.append({"failure": f, "settings": len(settings), "always": _short(always) or "-",
                    "sometimes": "; ".join(f"{e} ({n})" for e, n in some) or "-"})
    return out


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


def _problem_group(problem: str) -> str:
    return RANDOM if problem.startswith("random") else problem


def _ranks(values: Sequence[float], *, higher_is_better: bool = False) -> np.ndarray:
    """Ranks (1 = best, ties share the lowest) of values rounded to the 3 significant digits shown."""
    shown = np.array([float(f"{v:.3g}") if math.isfinite(v) else v for v in values])
    return rankdata(-shown if higher_is_better else shown, method="min")


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


def _plot_coverage(rows: Sequence[Row], out: Path) -> str:
    groups, pivot = _open_pivot(rows, "coverage")
    methods = sorted(pivot)
    _write_csv(out / "coverage.csv", [{"method": m, **{g: pivot[m].get(g, math.nan) for g in groups}}
                                      for m in methods])
    fig, ax = _subplots(figsize=(9, 3.4))
    width = 0.8 / len(groups)
    for j, g in enumerate(groups):
        vals = 100 * np.array([pivot[m].get(g, math.nan) for m in methods])
        ax.bar(np.arange(len(methods)) + (j - (len(groups) - 1) / 2) * width, vals, width, label=g)
    ax.set_xticks(range(len(methods)), methods, rotation=30, ha="right", fontsize=8)
    ax.set_ylabel("AMS coverage (%)", fontsize=8)
    ax.legend(fontsize=7, ncols=len(groups))
    ax.grid(axis="y", alpha=0.3)
    fig.tight_layout()
    fig.savefig(out / "coverage.png", dpi=DPI)
    return "coverage.png"


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
            top = [f"{c['method']} {c['mode']} ({_fmt(c['score'], 2)})" for c in grp
                   if c["failure"] == f and c["rank"] == 1 and c["method"] != STATIC]
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
    for name in sorted(t for t in tables if t.startswith("closed_")):
        rows = closed_scores(tables[name])
        if not rows:
            continue
        cells = cell_summaries(rows)
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
             ""]
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
