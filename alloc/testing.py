"""Seeded random allocation problems for tests and benchmarks, degenerate ones included."""

from __future__ import annotations

import numpy as np

from .problem import Problem

__all__ = ["KINDS", "random_problem", "random_demands", "diagonal_wv"]

#: Kinds of effector suites: general position and the degenerate cases allocators get wrong.
KINDS = ("general", "collinear", "coplanar", "rank_deficient", "zero_column", "jammed", "duplicate")


def random_problem(
    rng: np.random.Generator,
    k: int,
    m: int,
    kind: str = "general",
    *,
    weights: bool = True,
    rates: bool = True,
) -> Problem:
    """A random ``k x m`` problem of the given kind with limits, weights and rate limits.

    Limits mostly contain zero; about one effector in five is one-sided (``[0, hi]``, like
    the ICE tips and spoilers).
    """
    if kind not in KINDS:
        raise ValueError(f"kind: unknown {kind!r}; one of {KINDS}")
    B = rng.normal(size=(k, m)) * rng.uniform(0.2, 3.0, size=(k, 1))
    if kind == "collinear" and m >= 2:
        B[:, 1] = -0.7 * B[:, 0]
    elif kind == "coplanar" and m >= 3 and k >= 3:
        B[:, 2] = 0.4 * B[:, 0] - 1.3 * B[:, 1]
    elif kind == "rank_deficient" and k >= 2:
        B[-1] = 0.5 * B[0] - B[1 % (k - 1)] if k > 2 else 0.5 * B[0]
    elif kind == "zero_column":
        B[:, rng.integers(m)] = 0.0
    elif kind == "duplicate" and m >= 2:
        B[:, -1] = B[:, 0]
    umax = rng.uniform(0.3, 2.0, size=m)
    umin = -rng.uniform(0.3, 2.0, size=m)
    one_sided = rng.random(m) < 0.2
    umin[one_sided] = 0.0
    if kind == "jammed":
        j = rng.integers(m)
        umin[j] = umax[j] = rng.uniform(umin[j], umax[j])
    up = np.clip(rng.uniform(-0.2, 0.2, size=m), umin, umax) if weights else None
    Wu = Wv = None
    if weights:
        Wu = rng.uniform(0.5, 3.0, size=m)
        if rng.random() < 0.3:
            L = rng.normal(size=(k, k))
            Wv = L @ L.T + k * np.eye(k)
    rate = rng.uniform(1.0, 20.0, size=m) if rates else None
    return Problem(B, umin, umax, up=up, Wu=Wu, Wv=Wv,
                   rate_min=None if rate is None else -rate, rate_max=rate)


def diagonal_wv(p: Problem) -> Problem:
    """``p`` with its axis weights ``Wv`` reduced to their diagonal (the L1 methods, Eqs 1.18-1.19,
    take weight vectors; :func:`random_problem` gives a full ``Wv`` to about 30 % of problems)."""
    return p.replace(Wv=np.diagonal(p.Wv)) if np.count_nonzero(p.Wv - np.diag(np.diagonal(p.Wv))) else p


def random_demands(rng: np.random.Generator, problem: Problem, n: int, attainable_fraction: float = 0.5) -> np.ndarray:
    """``n`` demands: a fraction made as ``B u`` with ``u`` in the box, the rest scaled up past it."""
    u = rng.uniform(problem.umin, problem.umax, size=(n, problem.m))
    V = u @ problem.B.T
    far = rng.random(n) >= attainable_fraction
    V[far] = V[far] * rng.uniform(1.0, 4.0, size=(int(far.sum()), 1)) + rng.normal(size=(int(far.sum()), problem.k))
    return V
