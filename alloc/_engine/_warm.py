"""When a warm-started active set may be used: one definition for the host and the C export.

A warm start (the last answer's working set kept from call to call) ends at the cold start's
optimum where that optimum is determined beyond round-off.  Where it is not -- a nearly (not
exactly) rank-deficient weighted effectiveness, two nearly parallel effectors, axes weighted
far apart, an ill-conditioned preference weight -- the optimum is known only to round-off times
the condition number and a warm start ends elsewhere within that (measured on the adversarial
suite, tests/hostile.py: answers apart by up to 0.85 of the limit span at condition numbers of
1e9 and beyond, none apart by more than 1e-12 below 1e6).  Read by the active-set methods'
``warm_start`` option (:class:`alloc.methods.quadratic.LexicoLS`) and by
:func:`alloc.export.export_c`'s ``warm_start``; numpy only.
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

__all__ = ["WARM_COND_MAX", "WARM_ROUND_OFF", "warm_conditioning"]

#: the warm start is refused beyond this condition number of a level's weighted effectiveness
#: (its singular values above the round-off cut) or of the preference weight: two decades below
#: the smallest at which a disagreement was measured (1e8 for ``Wu``, 1e9 for the effectiveness)
WARM_COND_MAX = 1e6
#: singular values below this fraction of the largest are round-off (an exactly rank-deficient
#: effectiveness, which the factorisation cuts at 1e-12 and the warm start handles): two
#: decades under that cut, since a column subset's largest singular value can be smaller
WARM_ROUND_OFF = 1e-14


def _gray(M: np.ndarray) -> float | None:
    """The condition number of ``M`` over its singular values above round-off, when some lies
    between round-off and ``1 / WARM_COND_MAX`` of the largest; else None."""
    s = np.linalg.svd(M, compute_uv=False)
    if not s.size or not s[0] > 0:
        return None
    bad = s[(s > WARM_ROUND_OFF * s[0]) & (s * WARM_COND_MAX < s[0])]
    return float(s[0] / bad[-1]) if bad.size else None


def warm_conditioning(A: np.ndarray, wus: Iterable[np.ndarray]) -> tuple[float, str] | None:
    """``(condition number, what)`` of the first part of the problem that rules a warm start
    out, or None when it may be used.  ``A`` is the weighted effectiveness ``Wv^(1/2) B`` (rows
    by level), ``wus`` the preference weights of the solver instances."""
    worst = _gray(A)
    what = "weighted effectiveness Wv^(1/2) B"
    rows = np.abs(A).max(axis=1) if A.size else np.zeros(0)
    rows = rows[rows > 0]
    if worst is None and rows.size and rows.max() / WARM_COND_MAX > rows.min():
        # a weak row with a large demand still moves the optimum, but a factorisation resolves
        # it only to round-off of the strong rows (its singular vectors' entries are relative)
        with np.errstate(over="ignore"):
            worst, what = float(rows.max() / rows.min()), "weighted effectiveness's rows (axes scaled apart)"
    m = A.shape[1]
    if worst is None:
        for i in range(m):
            for j in range(i + 1, m):
                if (c := _gray(A[:, [i, j]])) is not None:
                    return c, f"weighted effectiveness's columns {i} and {j} (nearly parallel)"
    if worst is None:
        for Wu in wus:
            w = np.linalg.eigvalsh(Wu)
            with np.errstate(over="ignore", divide="ignore"):
                c = w[-1] / w[0] if w[0] > 0 else np.inf
            if not c <= WARM_COND_MAX:
                return float(c), "preference weight Wu"
    return None if worst is None else (worst, what)
