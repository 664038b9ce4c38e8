"""The numbers of the comparison report, from a sweep folder's rows (definitions: the
docstring of :mod:`benchmarks.compare.report`): closed-loop scores, per-cell medians with
bootstrap intervals and ranks, told/blind and detected ratios, open-loop / closed-loop rank
agreement, the verdicts across simulator settings, and the engineering verdicts (:mod:`sim.criteria`)
with the baseline's own fate."""

from __future__ import annotations

import math
from collections import defaultdict
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

import alloc.registry

from .runner import read_table, table_of
from .stats import bootstrap_median, paired_ratio, rank_with_ties, spearman
from .sweep import STATIC, Spec
from .tables import Row

__all__ = ["load_rows", "closed_scores", "cell_summaries", "told_blind", "detected_share", "coverage_agreement",
           "pooled_rows", "verdicts_by_setting", "verdict_stability", "ALL_SETTINGS", "FAMILIES", "RANDOM",
           "has_verdicts", "broken_counts", "baseline_fate"]

RANDOM = "random suite"


COVERAGE_PROBLEM = {"ice": "ice", "harv_latdir": "harv_latdir"}


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


def has_verdicts(rows: Sequence[Row]) -> bool:
    """Whether the rows carry engineering verdicts (rows written before :mod:`sim.criteria` do not)."""
    return any(r.get("verdict_pass") is not None for r in rows)


def _broken(row: Row) -> list[str]:
    text = row.get("verdict_broken")
    return [] if not text else str(text).split(";")


def broken_counts(rows: Sequence[Row], top: int = 4) -> str:
    """The criteria the rows broke, most often first: ``name (runs)``, the ``top`` most frequent
    and how many more; ``-`` when none broke."""
    count: dict[str, int] = defaultdict(int)
    for r in rows:
        for name in _broken(r):
            count[name] += 1
    ordered = sorted(count.items(), key=lambda kv: (-kv[1], kv[0]))
    text = ", ".join(f"{k} ({n})" for k, n in ordered[:top])
    return (text + (f", {len(ordered) - top} more" if len(ordered) > top else "")) or "-"


def _verdict_fields(grp: Sequence[Row]) -> Row:
    if not has_verdicts(grp):
        return {}
    diverged_at = [float(r["simulated"]) for r in grp if r["diverged"]]
    return {"passed": sum(r.get("verdict_pass") is True for r in grp), "broken": broken_counts(grp),
            "diverged_at": _median(diverged_at)}


def baseline_fate(rows: Sequence[Row]) -> list[Row]:
    """The fate of ``static`` (every score's denominator) per (scenario, setting, failure): runs,
    how many diverged and when (s, sorted), and, when the rows carry verdicts, how many passed
    the engineering criteria and which they broke."""
    out = []
    for (scenario, setting, failure), grp in _groups([r for r in rows if r["method"] == STATIC],
                                                     ("scenario", "setting", "failure")).items():
        times = sorted(float(r["simulated"]) for r in grp if r["diverged"])
        fate: Row = {"scenario": scenario, "setting": setting, "failure": failure, "runs": len(grp),
                     "failure_time": float(grp[0]["failure_time"]), "duration": float(grp[0]["duration"]),
                     "diverged": len(times), "diverged_at": ", ".join(f"{t:.2f}" for t in times) or "-"}
        if has_verdicts(grp):
            fate["passed"] = sum(r.get("verdict_pass") is True for r in grp)
            fate["broken"] = broken_counts(grp, top=6)
        out.append(fate)
    out.sort(key=lambda r: (r["scenario"], r["setting"], r["failure"]))
    return out


def cell_summaries(rows: Sequence[Row]) -> list[Row]:
    """One summary per (scenario, setting, failure, method, mode) of scored rows, with ``rank``
    within its (scenario, setting, failure); rows with engineering verdicts add ``passed`` (runs
    that met every criterion), ``broken`` (:func:`broken_counts`) and ``diverged_at`` (median
    time of divergence, s)."""
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
                     "saturation_s": _median([r.get("time_in_position_saturation") for r in grp]),
                     **_verdict_fields(grp)}
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


#: the declared families of more than one method (alloc.registry.families: one allocation by
#: several algorithms, identical closed-loop rows in the sweeps; today direct allocation, ``da``
#: and its three backends); a family is shown as ``<family>*`` when all its members share a verdict
FAMILIES = {name: members for name, members in alloc.registry.families().items() if len(members) > 1}


def _short(entries: Sequence[str]) -> str:
    """``method mode`` entries, with every member of a family in one mode written once as
    ``<family>*`` (``da*``)."""
    items = sorted(set(entries))
    for mode in ("blind", "told"):
        for name, members in FAMILIES.items():
            family = [f"{m} {mode}" for m in members]
            if all(f in items for f in family):
                items = [i for i in items if i not in family] + [f"{name}* {mode}"]
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


def _problem_group(problem: str) -> str:
    return RANDOM if problem.startswith("random") else problem


def _open_pivot(rows: Sequence[Row], column: str) -> tuple[list[str], dict[str, dict[str, float]]]:
    """``method -> group -> value`` (the random suite averaged)."""
    acc: dict[str, dict[str, list[float]]] = defaultdict(lambda: defaultdict(list))
    for r in rows:
        acc[r["method"]][_problem_group(r["problem"])].append(float(r[column]))
    groups = [g for g in ("ice", "harv_latdir", RANDOM) if any(g in v for v in acc.values())]
    return groups, {m: {g: float(np.mean(v)) for g, v in d.items()} for m, d in acc.items()}
