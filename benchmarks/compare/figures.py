"""The report's figures: each ``X.png`` drawn on a bare matplotlib ``Figure`` (no pyplot, no
backend chosen) and written with ``X.csv``, the exact numbers it draws."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from .runner import history_path
from .summaries import _mode, _open_pivot
from .sweep import STATIC
from .tables import Row, _fmt, _write_csv

__all__ = ["heatmap_data", "history_data", "HISTORY_DECIMATE", "DPI"]

DPI = 80


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
