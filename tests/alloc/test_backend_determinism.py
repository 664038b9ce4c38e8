"""Third-party backends answer from the call's data alone: not from the machine's load, not
from earlier calls (issue 22).

- Load: every backend is bounded by iteration counts (alloc.solvers.ITERATION_LIMITS), never
  by wall-clock time.  With OSQP under a 0.1 s time limit the same call returned
  ``unattainable`` on an idle CPU and ``fallback`` on a busy one; here the same calls are made
  idle and under three CPU-burning processes and must give the same bits.
- History: ``lp`` on HiGHS answered a demand differently after two rate-limited calls than a
  fresh allocator did (u off by up to 0.95, both ``exact``), and a batch row differed from
  the single call, on degenerate problems (B near 1e-100, a zero row, a duplicated column).
  A seeded generator of such problems and call sequences checks every LP/QP backend: each
  answer equals a fresh allocator's, and each batch row a fresh allocator's single call.
"""

from __future__ import annotations

import multiprocessing
import time
import warnings
from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest

import alloc
import alloc.vehicles
from alloc import solvers
from alloc.solvers import backends
from alloc.testing import random_demands, random_problem


def test_every_backend_is_bounded_by_iterations_not_time() -> None:
    for name, settings in solvers._TIGHT.items():  # the settings handed to qpsolvers
        assert not any("time" in key for key in settings), (name, settings)
        assert any("iter" in key for key in settings), (name, settings)
        assert int(next(v for k, v in settings.items() if "iter" in k)) == solvers.ITERATION_LIMITS[name]
    assert not hasattr(solvers, "QP_TIME_LIMIT_S")
    assert set(solvers.ITERATION_LIMITS) >= {"daqp", "highs", "osqp", "clarabel"}


def _burn(stop: Any) -> None:  # pragma: no cover - runs in a child process
    x = 0
    while not stop.is_set():
        for _ in range(100_000):
            x += 1


def _answers(cases: list[tuple[alloc.Problem, str, dict[str, Any], np.ndarray]]) -> list[tuple[bytes, str, str]]:
    out = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # qpsolvers' conversion and status warnings
        for p, method, options, V in cases:
            f = alloc.make_allocator(p, method, **options)
            for v in V:
                r = f(v)
                out.append((r.u.tobytes(), r.status.value, r.message))
    return out


def _load_cases() -> list[tuple[alloc.Problem, str, dict[str, Any], np.ndarray]]:
    """Calls that take the iterative backends many iterations: degenerate 6 x 16 problems
    (OSQP: median 75 iterations, the slowest 1 % over 30,000 at the tightened tolerances)."""
    rng = np.random.default_rng(2026_22_03)
    problems = [alloc.vehicles.problem("ice")] + [random_problem(rng, 6, 16, kind) for kind in ("coplanar", "jammed", "rank_deficient")]
    cases = []
    for b in ("osqp", "clarabel"):
        if b not in backends():
            continue
        for p in problems:
            V = random_demands(rng, p, 3)
            cases += [(p, "qp", {"backend": b}, V), (p, "wls", {"backend": b}, V)]
    p = problems[1]
    V = random_demands(rng, p, 4)
    cases += [(p, "lp", {"backend": "highs"}, V), (p, "da", {"backend": "highs"}, V), (p, "qp", {"backend": "daqp"}, V)]
    return cases


def test_answers_do_not_depend_on_the_machines_load() -> None:
    cases = _load_cases()
    idle = _answers(cases)
    ctx = multiprocessing.get_context("spawn")
    stop = ctx.Event()
    burners = [ctx.Process(target=_burn, args=(stop,), daemon=True) for _ in range(3)]
    for b in burners:
        b.start()
    try:
        time.sleep(0.5)  # the burners running before the first call
        busy = _answers(cases)
    finally:
        stop.set()
        for b in burners:
            b.join(10)
    assert len(idle) == len(busy) >= 40
    assert [a[1] for a in idle] == [b[1] for b in busy]
    assert idle == busy


# ------------------------------------------------------------------------------- history
def degenerate_problem(rng: np.random.Generator) -> alloc.Problem:
    """A small problem of the kinds that leave an LP a face of optima: B at 1e-100 (whole, in
    part, or integer-valued times 1e-100), a zero row, duplicated or opposite columns, fewer
    effectors than axes, limits at 1e48, jammed effectors, weights over 40 decades; with
    rate limits."""
    k = int(rng.integers(1, 7))
    m = int(rng.integers(1, 13))
    B = rng.standard_normal((k, m))
    kind = rng.integers(5)
    if kind == 0:
        B *= 1e-100
    elif kind == 1:
        B[rng.random((k, m)) < 0.3] *= 1e-100
    elif kind == 2:
        B = rng.integers(-2, 3, size=(k, m)) * 1e-100
    elif kind == 3:
        B = rng.integers(-2, 3, size=(k, m)).astype(float)
    if k > 1 and rng.random() < 0.6:
        B[rng.integers(k)] = 0.0
    if m > 1 and rng.random() < 0.6:
        B[:, -1] = B[:, 0]
    if m > 2 and rng.random() < 0.3:
        B[:, 1] = -B[:, 0]
    umax = rng.uniform(0.2, 2.0, m)
    umin = -rng.uniform(0.2, 2.0, m)
    umin[rng.random(m) < 0.2] = 0.0
    if rng.random() < 0.15:
        umin, umax = umin * 1e48, umax * 1e48
    if m > 1 and rng.random() < 0.3:
        j = rng.integers(m)
        umin[j] = umax[j]
    rate = rng.uniform(0.5, 10.0, m) * (1e48 if umax.max() > 1e40 else 1.0)
    up = np.clip(rng.uniform(-0.3, 0.3, m), umin, umax) if rng.random() < 0.4 else None
    Wu = 10.0 ** rng.uniform(-20, 20, m) if rng.random() < 0.3 else None
    Wv = 10.0 ** rng.uniform(-3, 3, k) if rng.random() < 0.3 else None
    return alloc.Problem(B, umin, umax, up=up, Wu=Wu, Wv=Wv, rate_min=-rate, rate_max=rate)


def demands(rng: np.random.Generator, p: alloc.Problem, n: int) -> np.ndarray:
    """Attainable, far outside, along one axis, zero, and at scales from 1e-300 to 1e45 (far
    from B's own scale): every face of the LP."""
    V = random_demands(rng, p, n)
    V[rng.random(n) < 0.15] = 0.0
    axis = rng.random(n) < 0.2
    V[axis] *= (np.arange(p.k) == rng.integers(p.k))
    scaled = rng.random(n) < 0.4
    V[scaled] = rng.standard_normal((int(scaled.sum()), p.k)) * rng.choice([1e-300, 1e-12, 1.0, 1e12, 1e45],
                                                                            size=(int(scaled.sum()), 1))
    return V


HISTORY_CASES = [("lp", {"backend": b}) for b in ("simplex", *backends(lp=True))] + \
                [("da", {"backend": b}) for b in backends(lp=True)] + \
                [("qp", {"backend": "daqp"}), ("wls", {"backend": "daqp"})]


def _sequences(seed: int, n_problems: int) -> Iterator[tuple[alloc.Problem, np.ndarray, list[tuple[np.ndarray, float]]]]:
    rng = np.random.default_rng(seed)
    made = 0
    while made < n_problems:
        try:
            p = degenerate_problem(rng)
        except alloc.AllocError:  # a generated problem outside the valid domain: another one
            continue
        made += 1
        V = demands(rng, p, 5)
        rated = [(rng.uniform(p.umin, p.umax), float(rng.choice([1e-3, 0.02, 1.0]))) for _ in range(2)]
        yield p, V, rated


def history_breaks(method: str, options: dict[str, Any], seed: int, n_problems: int) -> list[str]:
    breaks = []
    for i, (p, V, rated) in enumerate(_sequences(seed, n_problems)):
        try:
            f = alloc.make_allocator(p, method, **options)
        except alloc.AllocError:  # a method's size cap or a refused option: nothing to compare
            continue
        for (u_prev, dt), v in zip(rated, V):
            f(v, u_prev=u_prev, dt=dt)  # the history: rate-limited calls
        fresh = [alloc.make_allocator(p, method, **options)(v) for v in V]
        for j, (v, r) in enumerate(zip(V, fresh)):
            a = f(v)
            if not (np.array_equal(a.u, r.u) and a.status == r.status):
                breaks.append(f"problem {i} demand {j}: after history |du| = {np.abs(a.u - r.u).max():.3g}")
        b = alloc.make_allocator(p, method, **options).batch(V)
        for j, r in enumerate(fresh):
            if not (np.array_equal(b.u[j], r.u) and str(b.status[j]) == r.status.value):
                breaks.append(f"problem {i} demand {j}: batch row |du| = {np.abs(b.u[j] - r.u).max():.3g}")
    return breaks


@pytest.mark.parametrize(("method", "options"), HISTORY_CASES,
                         ids=[f"{m}-{o['backend']}" for m, o in HISTORY_CASES])
def test_answers_do_not_depend_on_earlier_calls(method: str, options: dict[str, Any]) -> None:
    assert history_breaks(method, options, seed=2026_12_22, n_problems=30) == []


@pytest.mark.slow
@pytest.mark.parametrize(("method", "options"), HISTORY_CASES,
                         ids=[f"{m}-{o['backend']}" for m, o in HISTORY_CASES])
def test_answers_do_not_depend_on_earlier_calls_at_length(method: str, options: dict[str, Any]) -> None:
    assert history_breaks(method, options, seed=2027, n_problems=600) == []


def test_generated_problems_are_degenerate() -> None:
    """The generator makes the cases it claims (so the test above tests them)."""
    got = {"tiny": 0, "zero_row": 0, "duplicate": 0}
    for p, _, _ in _sequences(2026_12_22, 30):
        B = p.B
        got["tiny"] += bool(np.any((B != 0) & (np.abs(B) < 1e-90)))
        got["zero_row"] += bool(np.any(~B.any(axis=1)))
        got["duplicate"] += bool(p.m > 1 and np.array_equal(B[:, 0], B[:, -1]))
    assert got["tiny"] >= 8 and got["zero_row"] >= 8 and got["duplicate"] >= 8, got
