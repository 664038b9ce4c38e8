"""Statistics of the comparison report: bootstrap intervals, paired ratios, rankings with ties.

All resampling is seeded (``seed``), so a report is reproducible from its CSVs.  Scores may be
``inf`` (a diverged run); intervals use the order statistics of the bootstrap distribution
(``numpy.quantile`` methods ``lower``/``higher``: no interpolation, so ``inf`` stays ``inf``
and never turns into ``nan``).  ``nan`` entries (no score: the reference run diverged) are
dropped before resampling and counted apart by the caller.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np
from scipy.stats import rankdata, spearmanr

__all__ = ["Interval", "bootstrap_median", "paired_ratio", "rank_with_ties", "spearman", "N_BOOT"]

N_BOOT = 4000
LEVEL = 0.95

#: (estimate, lower, upper)
Interval = tuple[float, float, float]


def _bounds(samples: np.ndarray) -> tuple[float, float]:
    samples = samples[~np.isnan(samples)]
    if samples.size == 0:
        return math.nan, math.nan
    a = (1.0 - LEVEL) / 2
    return float(np.quantile(samples, a, method="lower")), float(np.quantile(samples, 1 - a, method="higher"))


def bootstrap_median(x: Sequence[float], *, n_boot: int = N_BOOT, seed: int = 0) -> Interval:
    """Median of ``x`` and its percentile-bootstrap 95 % interval (``nan`` entries dropped).

    With fewer than 2 values the interval is the value itself (no spread to resample)."""
    a = np.asarray(x, dtype=float)
    a = a[~np.isnan(a)]
    if a.size == 0:
        return math.nan, math.nan, math.nan
    med = float(np.median(a))
    if a.size < 2:
        return med, med, med
    rng = np.random.default_rng(seed)
    boot = np.median(a[rng.integers(0, a.size, (n_boot, a.size))], axis=1)
    lo, hi = _bounds(boot)
    return med, lo, hi


def _ratio(num: np.ndarray, den: np.ndarray) -> np.ndarray:
    with np.errstate(divide="ignore", invalid="ignore"):
        r = num / den
    # finite / inf = 0 (told survives, blind diverged); inf / inf and 0 / 0 stay nan
    return r


def paired_ratio(told: Sequence[float], blind: Sequence[float], *, n_boot: int = N_BOOT, seed: int = 0) -> Interval:
    """``median(told) / median(blind)`` over pairs (same noise seed) and its paired-bootstrap 95 %
    interval: both columns are resampled with the same indices.  Pairs with a ``nan`` are dropped."""
    t, b = np.asarray(told, dtype=float), np.asarray(blind, dtype=float)
    if t.shape != b.shape:
        raise ValueError(f"told/blind: paired samples must have one shape, got {t.shape} and {b.shape}")
    keep = ~(np.isnan(t) | np.isnan(b))
    t, b = t[keep], b[keep]
    if t.size == 0:
        return math.nan, math.nan, math.nan
    est = float(_ratio(np.median(t), np.median(b)))
    if t.size < 2:
        return est, est, est
    rng = np.random.default_rng(seed)
    idx = rng.integers(0, t.size, (n_boot, t.size))
    boot = _ratio(np.median(t[idx], axis=1), np.median(b[idx], axis=1))
    lo, hi = _bounds(boot)
    return est, lo, hi


def rank_with_ties(intervals: Mapping[str, Interval]) -> dict[str, int]:
    """Rank 1 = best (lowest).  A method's rank is 1 + the number of methods whose interval lies
    entirely below its own (upper bound < its lower bound): methods whose intervals overlap share
    a rank unless a third method separates them.  An infinite estimate (a median run that
    diverged) ranks after every finite one, whatever its interval: a method that diverges in
    most runs never ties for first because some of its runs survived.  ``nan`` estimates rank
    last."""
    names = list(intervals)
    finite = [n for n in names if math.isfinite(intervals[n][0])]
    ranks = {}
    for n in names:
        est, lo, _ = intervals[n]
        if math.isnan(est):
            ranks[n] = len(names)
            continue
        below = sum(1 for o in names if o != n and not math.isnan(intervals[o][0]) and intervals[o][2] < lo)
        ranks[n] = 1 + (below if math.isfinite(est) else max(below, len(finite)))
    return ranks


def spearman(a: Sequence[float], b: Sequence[float]) -> tuple[float, float, int]:
    """Spearman rank correlation, its two-sided p-value, and the number of finite-or-inf pairs
    used (ties share average ranks; ``inf`` ranks last).  ``nan`` with fewer than 3 pairs."""
    x, y = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    keep = ~(np.isnan(x) | np.isnan(y))
    x, y = x[keep], y[keep]
    n = int(x.size)
    if n < 3 or np.all(x == x[0]) or np.all(y == y[0]):
        return math.nan, math.nan, n
    # rank first: scipy would turn inf into nan
    res = spearmanr(rankdata(x), rankdata(y))
    return float(res.statistic), float(res.pvalue), n
