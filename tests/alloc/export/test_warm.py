"""The warm start of the active-set kernels (``export_c(..., warm_start=True)``), against the library.

The library's default allocator starts cold (its answers are functions of the call alone), so
a warm kernel cannot be its bits: it must give the cold library's statuses, its commands to
round-off where the optimum is strictly determined, and elsewhere (a flat optimum, where the
optimality test's tolerance admits several working sets: ``wls`` at its small default gamma) a
command that an independent KKT check accepts.  Sequences are smooth (where a warm start pays) and random
(where the kernel must notice that the last answer is a bad start); forgetting the warm start
(``PREFIX_warm_reset``, ``PREFIX_set_limits``) must give the library's bits again, and a warm run
that spends the budget must be redone from the cold start.  Against the library's own opt-in
``warm_start=True`` allocator, which follows the same rule, a double warm kernel is bit for bit.
"""

from __future__ import annotations


import numpy as np
import pytest
from test_export import (CC, FLOAT_U_TOL, OPTIMISED, STATUS, _float_limits, _float_rate_trajectory, _hostile_cases, _suite,
                         build)  # noqa: F401 - build is the compiling fixture

import alloc
import alloc.vehicles
from alloc.export import ExportError, export_c
from alloc.testing import random_demands

pytestmark = pytest.mark.skipif(CC is None, reason="no C compiler (cc, gcc or clang) on PATH: the generated "
                                "kernels cannot be compiled here")

METHODS = ("qp", "wls", "dynamic")
#: |u_warm - u_library| / max(1, limit span) where the optimum is strictly determined (measured
#: max 1.2e-14 on ICE and hexa-x, smooth and random, attainable and 5x past the attainable set)
U_TOL = 1e-12
#: the relative KKT residual accepted on a flat optimum (tests/alloc/test_kkt_exact.py's KKT_RTOL)
KKT_RTOL = 1e-12


def _smooth(rng: np.random.Generator, p: alloc.Problem, n: int, knots: int = 8) -> np.ndarray:
    """``n`` demands interpolated smoothly through ``knots`` random ones (attainable and not)."""
    K = random_demands(rng, p, knots)
    s = np.linspace(0.0, knots - 1.0, n)
    i = np.minimum(s.astype(int), knots - 2)
    t = s - i
    t = t * t * (3.0 - 2.0 * t)
    return K[i] * (1.0 - t)[:, None] + K[i + 1] * t[:, None]


def _kkt_wls(p: alloc.Problem, v: np.ndarray, u: np.ndarray, lo: np.ndarray, hi: np.ndarray, gamma: float) -> float:
    """Relative KKT residual of min (Bu-v)'Wv(Bu-v) + gamma^2 (u-up)'Wu(u-up) over [lo, hi]
    (the checker of tests/alloc/test_kkt_exact.py: only the answer and the data)."""
    G = p.B.T @ p.Wv
    g = G @ (p.B @ u - v) + gamma ** 2 * p.Wu @ (u - p.up)
    den = (np.abs(G).sum(axis=1).max() * (np.abs(p.B @ u).max() + np.abs(v).max())
           + gamma ** 2 * np.abs(p.Wu).sum(axis=1).max() * (np.abs(u).max() + np.abs(p.up).max()))
    tol = 1e-12 * np.maximum(1.0, hi - lo)
    viol = np.abs(g)
    atlo, athi = (u <= lo + tol) & (lo < hi), (u >= hi - tol) & (lo < hi)
    viol[atlo] = np.maximum(0.0, -g[atlo])
    viol[athi] = np.maximum(0.0, g[athi])
    viol[lo == hi] = 0.0
    return float(viol.max() / (den + 1e-300))


class Agreement:
    """Runs a warm kernel and the library over a sequence and keeps the evidence."""

    def __init__(self, kern, allocator, method: str, options: dict) -> None:
        self.kern, self.allocator, self.method = kern, allocator, method
        self.gamma = options.get("gamma", 1e-4)
        self.calls = self.flat = 0
        self.worst = 0.0

    def call(self, v, u_prev=None, dt=0.0):
        p = self.allocator.problem
        r = self.allocator(v) if u_prev is None else self.allocator(v, u_prev=u_prev, dt=dt)
        u, status, it = self.kern(v) if u_prev is None else self.kern(v, u_prev, dt)
        assert status == STATUS[r.status.value], (v, status, r.status)
        lo, hi = (p.umin, p.umax) if u_prev is None else p.effective_bounds(u_prev, dt)
        assert np.isfinite(u).all() and (u >= lo).all() and (u <= hi).all()
        du = float(np.abs(u - r.u).max() / max(1.0, float(np.max(p.umax - p.umin))))
        self.calls += 1
        if du > U_TOL:
            # a flat optimum: only wls's one level can have it here (qp's and dynamic's last level
            # is strictly convex); the warm answer must be an optimum as well
            assert self.method == "wls" and status < 2, (self.method, v, du)
            assert _kkt_wls(p, v, u, lo, hi, self.gamma) <= KKT_RTOL, (v, du)
            self.flat += 1
        else:
            self.worst = max(self.worst, du)
        return u, status, it, r


def _problems():
    """ICE (with its rate limits), hexa-x (qp with its priority levels) and the random suite."""
    for name in ("ice", "hexa-x"):
        yield name, alloc.vehicles.problem(name), lambda m, name=name: alloc.vehicles.method_options(name, m)
    for i, (p, _) in enumerate(_suite(300)):
        levels = {"priorities": [1 + j % 2 for j in range(p.k)]} if i % 2 else {}
        yield f"suite{i}", p, lambda m, levels=levels: levels if m == "qp" else {}


@pytest.mark.parametrize("method", METHODS)
def test_warm_agrees_with_the_library_on_smooth_random_and_rate_limited_sequences(build, method):
    rng = np.random.default_rng(41 + METHODS.index(method))
    calls = flat = 0
    for name, p, options in _problems():
        opts = options(method)
        kern = build(export_c(p, method, options=opts, prefix=f"w_{name}_{method}".replace("-", "_"), warm_start=True))
        check = Agreement(kern, alloc.make_allocator(p, method, **opts), method, opts)
        for v in np.vstack([_smooth(rng, p, 150), random_demands(rng, p, 60), 3.0 * _smooth(rng, p, 60)]):
            check.call(v)
        # a rate-limited trajectory (Eq 1.28): each step's window from the last answer
        u_prev = np.clip(p.up, p.umin, p.umax)
        for v in _smooth(rng, p, 80):
            u_prev = check.call(v, u_prev, 0.01)[0]
        calls += check.calls
        flat += check.flat
    assert calls >= 9 * 350
    assert flat <= 0.01 * calls, flat  # flat optima are rare (measured: 1 call in 2,000 on hexa-x wls)


@pytest.mark.parametrize("method", METHODS)
def test_warm_start_saves_iterations_on_smooth_demands(build, method):
    """The point of the warm start: a slowly moving demand takes fewer iterations than from the
    cold start (each kernel's count, on ICE)."""
    p = alloc.vehicles.problem("ice")
    V = _smooth(np.random.default_rng(5), p, 400, knots=4)
    warm = build(export_c(p, method, prefix=f"sw_{method}", warm_start=True), OPTIMISED)
    cold = build(export_c(p, method, prefix=f"sc_{method}"), OPTIMISED)
    its_warm = [warm(v)[2] for v in V]
    its_cold = [cold(v)[2] for v in V]
    assert np.mean(its_warm) < 0.8 * np.mean(its_cold), (np.mean(its_warm), np.mean(its_cold))


@pytest.mark.parametrize("method", METHODS)
def test_forgetting_the_warm_start_gives_the_library_bit_for_bit(build, method):
    """After PREFIX_warm_reset or PREFIX_set_limits the next call starts cold: the library's bits,
    status and iteration count; the calls after a warm one did start warm (fewer iterations)."""
    p = alloc.vehicles.problem("ice")
    kern = build(export_c(p, method, prefix=f"rs_{method}", warm_start=True))
    reset = getattr(kern.lib, f"rs_{method}_warm_reset")
    reset.restype = None
    allocator = alloc.make_allocator(p, method)
    V = _smooth(np.random.default_rng(9), p, 60, knots=3)
    warm_its, cold_its = [], []
    for i, v in enumerate(V):
        r = allocator(v)
        if i % 3 == 1:
            reset()
        elif i % 3 == 2:
            assert kern.set_limits(None, None) == 0
        u, status, it = kern(v)
        if i % 3:
            np.testing.assert_array_equal(u, r.u)
            assert (status, it) == (STATUS[r.status.value], r.iterations)
        else:
            warm_its.append(it)
            cold_its.append(r.iterations)
    assert sum(warm_its) < sum(cold_its), (warm_its, cold_its)  # the calls between the resets started warm


def test_a_warm_run_that_spends_the_budget_is_redone_cold(build):
    """With a per-call budget just above what the cold start needs on most demands, a warm run
    from a far-away last answer reaches the budget: the call is then the cold kernel's (its bits,
    status, and its iterations after the warm run's), and never more than twice the budget."""
    p = alloc.vehicles.problem("ice")
    budget = 4
    warm = build(export_c(p, "qp", prefix="bw", warm_start=True, iteration_bound=budget))
    cold = build(export_c(p, "qp", prefix="bc", iteration_bound=budget))
    redone = 0
    for v in random_demands(np.random.default_rng(13), p, 400):
        uw, sw, iw = warm(v)
        uc, sc, ic = cold(v)
        assert iw <= 2 * budget
        if iw > budget:  # the warm run spent the budget, then the cold one ran
            redone += 1
            np.testing.assert_array_equal(uw, uc)
            assert sw == sc and iw == budget + ic
        elif sw == 2:  # no warm start taken and the cold start spent the budget
            assert sc == 2 and iw == ic
    assert redone >= 5, redone


@pytest.mark.parametrize("method", ["qp", "wls"])
def test_float_warm_is_always_within_its_bounds_and_agrees(build, method):
    """float: commands within the call's float bounds exactly, on warm and rate-limited calls;
    qp within the float tolerance of the library on nearly every call (as the cold float build)."""
    du = []
    for i, (p, rng) in enumerate(_suite(500 + METHODS.index(method))):
        kern = build(export_c(p, method, precision="float", prefix=f"fw{i}_{method}", warm_start=True))
        allocator = alloc.make_allocator(p, method)
        lo32, hi32 = _float_limits(kern)
        span = max(1.0, float(np.max(p.umax - p.umin)))
        for v in np.vstack([_smooth(rng, p, 40), random_demands(rng, p, 20)]):
            u, status, _ = kern(v)
            assert np.isfinite(u).all() and (u >= lo32).all() and (u <= hi32).all()
            du.append(float(np.abs(u - allocator(v).u).max()) / span)
        _float_rate_trajectory(kern, p, rng, 30, demands=_smooth)
    if method == "qp":
        du = np.array(du)
        assert np.quantile(du, 0.99) <= FLOAT_U_TOL and (du > 1e-4).mean() <= 0.01, np.sort(du)[-10:]


def _hostile_warm(build, cases: int, start: int) -> tuple[int, int]:
    """The adversarial suite's in-domain problems, their demands in order then smooth ones, then
    rate-limited smooth ones:
    (calls checked, problems whose warm start the export refused for their conditioning)."""
    calls = refused = 0
    for i, (seed, p, V) in enumerate(_hostile_cases(cases, start)):
        method = METHODS[i % len(METHODS)]
        try:
            kernel = export_c(p, method, prefix=f"hw{seed}_{method}", table=False, warm_start=True)
        except ExportError as exc:
            assert exc.field == "warm_start" and "condition number" in str(exc), (seed, exc)
            refused += 1
            continue
        check = Agreement(build(kernel), alloc.make_allocator(p, method), method, {})
        with np.errstate(over="ignore", invalid="ignore"):
            extra = _smooth(np.random.default_rng(seed), p, 30)
        extra = extra[(np.abs(extra) <= alloc.problem.MAX_MAGNITUDE).all(axis=1)]
        try:
            for v in np.vstack([V, extra]):
                check.call(v)
            u_prev = np.clip(p.up, p.umin, p.umax)  # then a rate-limited trajectory (Eq 1.28)
            for v in extra[:15]:
                u_prev = check.call(v, u_prev, 0.01)[0]
        except AssertionError as exc:  # name the case: reproducible from its seed
            raise AssertionError(f"hostile seed {seed}, method {method}: {exc}") from None
        calls += check.calls
    return calls, refused


def test_warm_on_hostile_problems(build):
    calls, refused = _hostile_warm(build, 30, 0)
    # measured: 610 calls on 13 problems, 17 refused (the suite is built to be ill-conditioned)
    assert calls >= 10 * 30 and refused <= 20, (calls, refused)


@pytest.mark.slow
def test_warm_on_many_hostile_problems(build):
    calls, refused = _hostile_warm(build, 300, 1000)
    assert calls >= 150 * 30, (calls, refused)  # measured: 8,431 calls, 121 of the 300 refused


def test_warm_start_is_refused_where_the_optimum_is_round_off():
    """Where a level's weighted effectiveness or the preference weight is conditioned beyond
    WARM_COND_MAX, the answer is determined only to round-off times that: the warm start ends
    elsewhere (on the adversarial suite: 0.6 of the span apart at 1e9), so the export refuses it
    and says why; the cold kernel of the same problem is exported."""
    from alloc.export.base import WARM_COND_MAX

    p = alloc.vehicles.problem("ice")
    B = p.B.copy()
    B[2] = B[0] + 1e-8 * np.random.default_rng(1).normal(size=p.m)  # rows parallel to 1e-8: condition above 1e6
    near = p.replace(B=B)
    refusal = "warm_start: the problem's weighted effectiveness .* condition number"
    with pytest.raises(ExportError, match=refusal) as info:
        export_c(near, "qp", warm_start=True)
    assert info.value.field == "warm_start"
    export_c(near, "qp")
    stiff = p.replace(Wu=np.diag(np.geomspace(1.0, 10 * WARM_COND_MAX, p.m)))
    with pytest.raises(ExportError, match="preference weight Wu has condition number 1e\\+07"):
        export_c(stiff, "wls", warm_start=True)
    export_c(p.replace(Wu=np.diag(np.geomspace(1.0, WARM_COND_MAX / 10, p.m))), "wls", warm_start=True)
    # the case that took the library's own warm start out (alloc/_engine/_active_set.py): Wv's eigenvalues
    # 7.7e29 and 3.4e13, where a long-lived allocator answered another point than a fresh one
    import hostile

    c = hostile.case(10037684)
    weak = alloc.Problem(**{key: hostile.decode(val) for key, val in c["fields"].items()})
    for method in METHODS:
        with pytest.raises(ExportError, match="warm_start: .* condition number"):
            export_c(weak, method, warm_start=True)


def test_warm_start_errors_name_the_field():
    with pytest.raises(ExportError, match="warm_start: expected True or False") as info:
        export_c("ice", "qp", warm_start="yes")
    assert info.value.field == "warm_start"
    for method in ("pinv", "pinv_scale", "ganging", "cgi", "lp"):
        with pytest.raises(ExportError, match=f"warm_start: {method} has no working set"):
            export_c("hexa-x", method, warm_start=True)


def test_warm_header_states_the_semantics_and_the_default_kernel_is_unchanged():
    warm, cold = export_c("ice", "qp", warm_start=True), export_c("ice", "qp")
    assert warm.warm_start and not cold.warm_start
    assert "void alloc_qp_warm_reset(void);" in warm.header and "warm_reset" not in cold.header
    assert "at most twice the budget a call" in warm.header and "depends on the calls" in warm.header
    assert "warm" not in cold.source


def _hostile_calls(rng: np.random.Generator, p: alloc.Problem, n: int) -> list[tuple]:
    """``n`` calls ``(v, u_prev, dt)`` in seeded segments of random kinds: independent demands,
    sines at 2 kHz (slow and 20x faster), 3x unattainable ones, and rate-limited stretches
    (``u_prev`` the last answer, the string "last", or a jump elsewhere; ``dt`` 0.5 ms to 0.1 s)
    interleaved with nominal calls (``u_prev`` None)."""
    calls: list[tuple] = []
    reach = np.abs(p.B) @ np.maximum(np.abs(p.umin), np.abs(p.umax)) + 1e-12
    while len(calls) < n:
        kind = rng.choice(["random", "sines", "unattainable", "rate", "rate_jump"])
        length = int(rng.integers(5, 40))
        if kind == "random":
            V = random_demands(rng, p, length)
        elif kind == "unattainable":
            V = 3.0 * random_demands(rng, p, length, attainable_fraction=0.0)
        else:
            t = np.arange(length)[:, None] / 2000.0 * rng.choice([1.0, 20.0])
            f = rng.uniform(0.2, 5.0, (1, p.k))
            V = rng.uniform(0.1, 1.5) * reach * np.sin(2 * np.pi * f * t + rng.uniform(0, 6.3, (1, p.k)))
        for v in V:
            if kind.startswith("rate"):
                jump = kind == "rate_jump" and rng.random() < 0.3
                calls.append((v, rng.uniform(p.umin, p.umax) if jump else "last", float(rng.choice([5e-4, 1e-2, 0.1]))))
            else:
                calls.append((v, None, 0.0))
    return calls[:n]


@pytest.mark.parametrize("method", METHODS)
def test_warm_kernel_is_the_library_warm_start_bit_for_bit(build, method):
    """The double warm kernel mirrors the library's ``warm_start=True`` allocator
    (alloc/_engine/_active_set.py: ``_warm_pick``, ``_levels``' entry at the step): the same commands
    bit for bit, statuses and iteration counts over hostile sequences; every output finite and
    within the call's bounds; and the answers the cold library's to round-off (U_TOL)."""
    rng = np.random.default_rng(77 + METHODS.index(method))
    calls = warm_its = cold_its = 0
    for name, p, options in _problems():
        opts = options(method)
        kern = build(export_c(p, method, options=opts, prefix=f"wb_{name}_{method}".replace("-", "_"), warm_start=True))
        warm = alloc.make_allocator(p, method, warm_start=True, **opts)
        check = Agreement(kern, alloc.make_allocator(p, method, **opts), method, opts)
        last = np.clip(p.up, p.umin, p.umax)
        for v, u_prev, dt in _hostile_calls(rng, p, 120):
            u0 = last if isinstance(u_prev, str) else u_prev
            r = warm(v) if u0 is None else warm(v, u_prev=u0, dt=dt)
            u, status, it, cold = check.call(v, u0, dt)  # also: finite, within bounds, the cold answer
            np.testing.assert_array_equal(u, r.u, err_msg=f"{name} {method}")
            assert status == STATUS[r.status.value] and (status == 2 or it == r.iterations), (name, it, r.iterations)
            warm_its += it
            cold_its += cold.iterations
            last = u
        calls += check.calls
    assert calls >= 9 * 120
    assert warm_its < cold_its, (warm_its, cold_its)
