"""Every reproducer of issue 9 ("the allocation contract holds for every input") as a test.

Each case either lies outside the valid input domain (then a clear ``AllocError`` naming
the field, raised before any numerics) or inside it (then no exception, a finite admissible
``u`` and an honest status).  The in-domain twin of each out-of-domain reproducer (the same
structure at the domain's edge, 1e48 instead of 1e300) is tested too.
"""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

import alloc
from alloc.problem import MAX_MAGNITUDE
from alloc.result import EXACT_RTOL

DA = ["da", "da_facet", "da_bisect", "da_table"]


def assert_honest(p: alloc.Problem, r: alloc.Result, lo=None, hi=None) -> None:
    lo = p.umin if lo is None else lo
    hi = p.umax if hi is None else hi
    assert np.isfinite(r.u).all() and (r.u >= lo).all() and (r.u <= hi).all()
    assert np.isfinite(r.v_achieved).all() and np.isfinite(r.unallocated).all()
    err = float(np.abs(p.B @ r.u - r.v).max())
    tol = EXACT_RTOL * max(1.0, float(np.abs(r.v).max()))
    if r.status.value == "exact":
        assert err <= tol * (1 + 1e-9) + 1e-9 * float((np.abs(p.B) @ np.abs(r.u)).max())


def run_isolated(code: str, timeout: float = 120.0) -> str:
    """Run ``code`` in a fresh interpreter: a hang holding the GIL fails by timeout."""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=timeout)
    assert out.returncode == 0, out.stderr[-2000:]
    return out.stdout


# --------------------------------------------------------------------------- the hang
HANG_B = [[1e300, 1, 2, .5], [1e300, 3, 1, .1], [1e300, -1, 2, 3]]


def test_hang_reproducer_is_a_prompt_domain_error():
    with pytest.raises(alloc.ProblemError, match=r"^B: .*1e\+50"):
        alloc.Problem(HANG_B, [-1] * 4, [1] * 4, Wu=[1e-20, 1, 1, 1])


def test_scaled_pseudo_inverse_never_hands_lapack_a_non_finite_matrix():
    # the weighted pseudo-inverse of the hang, called directly below the Problem boundary
    out = run_isolated(
        "import numpy as np\n"
        "from alloc._engine._linalg import weighted_pinv\n"
        f"P = weighted_pinv(np.array({HANG_B!r}), np.diag([1e-20, 1, 1, 1]))\n"
        "print(np.isfinite(P).all())\n")
    assert out.strip().endswith("True")


def test_every_method_at_the_domain_edge_builds_and_answers():
    out = run_isolated(
        "import numpy as np, alloc\n"
        "B = [[1e48, 1, 2, .5], [1e48, 3, 1, .1], [1e48, -1, 2, 3]]\n"
        "p = alloc.Problem(B, [-1] * 4, [1] * 4, Wu=[1e-45, 1, 1, 1])\n"
        "for m in alloc.methods():\n"
        "    f = alloc.make_allocator(p, m)\n"
        "    for v in ([1.0, 2.0, 0.5], [1e49, -1e49, 3.0], [0.0, 0.0, 0.0]):\n"
        "        r = f(np.array(v))\n"
        "        assert np.isfinite(r.u).all() and (np.abs(r.u) <= 1).all(), m\n"
        "        assert np.isfinite(r.unallocated).all(), m\n"
        "print('ok')\n", timeout=300)
    assert out.strip().endswith("ok")


# --------------------------------------------------------------------------- call-time escapes
P3 = alloc.Problem([[1, 2, .5], [1, -1, 0]], [-1] * 3, [1] * 3)


@pytest.mark.parametrize("method,options", [("da", dict(backend="daqp")), ("da", dict(backend="highs")),
                                            ("da_bisect", {}), ("da_facet", {}), ("da_table", {})])
def test_huge_demand_is_a_demand_error_and_the_edge_is_answered(method, options):
    f = alloc.make_allocator(P3, method, **options)
    with pytest.raises(alloc.DemandError, match="^v: "):
        f([1e200, 0])
    for v in ([1e49, 0.0], [-3e48, 7e47], [5e-324, 0.0]):
        r = f(np.array(v))
        assert_honest(P3, r)
        assert r.status.value != "fallback"


def test_limits_of_1e300_are_a_problem_error_and_1e48_is_answered():
    B = [[1, 2, .5, -1], [1, -1, 0, 2], [0.3, 0.2, 1, 1]]
    with pytest.raises(alloc.ProblemError, match="^umin: "):
        alloc.Problem(B, [-1e300] * 4, [1e300] * 4)
    p = alloc.Problem(B, [-1e48] * 4, [1e48] * 4)
    for method in DA:
        f = alloc.make_allocator(p, method)
        for v in ([1e49, 1, 1], [1.0, 2.0, 3.0], [-4e49, 2e49, 1e49]):
            assert_honest(p, f(np.array(v)))


@pytest.mark.parametrize("method", DA)
def test_rank_two_3x4_with_edge_demand(method):
    rng = np.random.default_rng(3)
    B = rng.standard_normal((3, 2)) @ rng.standard_normal((2, 4))
    p = alloc.Problem(B, [-1] * 4, [1] * 4)
    f = alloc.make_allocator(p, method)
    with pytest.raises(alloc.DemandError, match="^v: "):
        f([1e155, 0, 0])
    V = np.array([[1e49, 0, 0], [0.3, -0.2, 0.1], [1e48, 1e48, -1e48]])
    singles = [f(v) for v in V]
    for r in singles:
        assert_honest(p, r)
    b = alloc.make_allocator(p, method).batch(V)
    for i, r in enumerate(singles):
        np.testing.assert_allclose(b.v_achieved[i], r.v_achieved, rtol=1e-9, atol=1e-9 * max(1, np.abs(r.v).max()))
        assert b.status[i] == r.status.value


@pytest.mark.parametrize("method", DA)
def test_rate_limited_da_on_degenerate_sets(method):
    rng = np.random.default_rng(5)
    for B in (rng.standard_normal((3, 1)) @ rng.standard_normal((1, 6)),  # rank 1
              np.array([[1.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 1.0], [1.0, 1.0, 1.0, 1.0]]),  # rank 2, duplicates
              rng.standard_normal((3, 5))):
        p = alloc.Problem(B, [-1] * B.shape[1], [1] * B.shape[1],
                          rate_min=[-1] * B.shape[1], rate_max=[0] + [1] * (B.shape[1] - 1))
        f = alloc.make_allocator(p, method)
        for u_prev in (np.zeros(B.shape[1]), np.full(B.shape[1], 3.0)):  # inside, outside the limits
            for dt in (1e-300, 0.01, 1e40):
                lo, hi = p.effective_bounds(u_prev, dt)
                r = f(rng.standard_normal(3) * 2, u_prev=u_prev, dt=dt)
                assert_honest(p, r, lo, hi)


# --------------------------------------------------------------------------- valid problems that could not be built
def _spread(k: int, m: int, smin: float, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    U, _, Vt = np.linalg.svd(rng.standard_normal((k, m)), full_matrices=False)
    return (U * np.logspace(0, np.log10(smin), min(k, m))) @ Vt


@pytest.mark.parametrize("method", DA)
def test_6x6_with_singular_values_down_to_4e_9_builds(method):
    p = alloc.Problem(_spread(6, 6, 4e-9, 0), [-1] * 6, [1] * 6)
    f = alloc.make_allocator(p, method)
    assert f.build_error == ""
    rng = np.random.default_rng(1)
    for _ in range(5):
        r = f(p.B @ rng.uniform(-1, 1, 6) * rng.choice([0.5, 3.0]))
        assert_honest(p, r)
        assert r.status.value != "fallback"


@pytest.mark.parametrize("method", DA)
def test_nearly_rank_one_3x22_builds(method):
    rng = np.random.default_rng(2)
    B = np.outer(rng.standard_normal(3), rng.standard_normal(22)) + 1e-9 * rng.standard_normal((3, 22))
    p = alloc.Problem(B, [-1] * 22, [1] * 22)
    f = alloc.make_allocator(p, method)
    assert f.build_error == ""
    for v in (B @ rng.uniform(-1, 1, 22), rng.standard_normal(3)):
        assert_honest(p, f(v))


@pytest.mark.parametrize("method", ["qp", "wls", "lp"])
def test_near_singular_5x12_with_up_and_large_weights_never_raise(method):
    rng = np.random.default_rng(4)
    B = _spread(5, 12, 1e-9, 4)
    cases = [dict(up=rng.uniform(-0.5, 0.5, 12)), dict(Wu=10.0 ** rng.uniform(-40, 40, 12)),
             dict(Wv=10.0 ** rng.uniform(-40, 40, 5))]
    for kw in cases:
        for scale in (1.0, 1e45):
            p = alloc.Problem(B * scale, [-1] * 12, [1] * 12, **kw)
            f = alloc.make_allocator(p, method)  # builds: a backend failure is a fallback, not an exception
            r = f(p.B @ rng.uniform(-1, 1, 12))
            assert_honest(p, r)
            if r.status.value == "fallback":
                assert r.message


# --------------------------------------------------------------------------- honest status
def test_nan_moment_is_never_exact():
    with pytest.raises(alloc.ProblemError, match="^B: "):
        alloc.Problem([[1e300, -1e300]], [1e10] * 2, [1e10] * 2)
    p = alloc.Problem([[1e48, -1e48]], [1e10] * 2, [1e10] * 2)  # u jammed at 1e10: B u = 0 exactly
    for method in alloc.methods():
        r = alloc.allocate(p, [1.0], method)
        assert np.isfinite(r.v_achieved).all()
        assert r.status.value != "exact"
        assert_honest(p, r)


def test_finish_kernel_classifies_nan_as_non_finite():
    from alloc._engine._kernels import finish, fused_affine

    B = np.array([[1.0, 1.0]])
    v_ach = np.empty(1)
    u = np.array([np.inf, -np.inf])
    assert finish(B, u, np.full(2, -np.inf), np.full(2, np.inf), np.array([1.0]), v_ach, 1e-6) == 2
    Bbig = np.array([[1e308, 1e308]])
    assert finish(Bbig, np.array([1e10, 1e10]), np.full(2, -1e11), np.full(2, 1e11), np.array([1.0]), v_ach, 1e-6) == 2
    W = np.array([[0.0, 1.0, 1e308, -1.0, 1.0], [0.0, 1.0, 1e308, -1.0, 1.0]])
    # fused_affine returns (out, code, iterations)
    assert fused_affine(W, np.array([1.0]), 1e-6, MAX_MAGNITUDE)[1] == 2
    assert fused_affine(W, np.array([np.nan]), 1e-6, MAX_MAGNITUDE)[1] == 3


# --------------------------------------------------------------------------- priorities as ranks
@pytest.mark.parametrize("top", [1e20, 2**63, 2**70, 10**400])
@pytest.mark.parametrize("method", ["cgi", "qp", "lp"])
def test_priorities_are_ranks_never_wrapped(top, method):
    # axis 0 (priority `top`) must be met first; axis 1 (priority 1) takes the shortfall
    p = alloc.Problem([[1.0, 1.0], [1.0, -1.0]], [-1, -1], [1, 1])
    v = np.array([1.5, 1.5])  # not attainable together
    r = alloc.allocate(p, v, method, priorities=[top, 1])
    assert abs(r.v_achieved[0] - 1.5) < 1e-6
    r2 = alloc.allocate(p, v, method, priorities=[1, top])
    assert abs(r2.v_achieved[1] - 1.5) < 1e-6


def test_priority_ranks_compare_exactly():
    from alloc.methods.cascade import priority_ranks

    assert priority_ranks([2**63, 2**63 - 1, 1e20, -0.5], 4) == [2, 1, 3, 0]  # 1e20 > 2**63
    assert priority_ranks(np.array([0.5, 0.25]), 2) == [1, 0]
    with pytest.raises(alloc.ProblemError, match="priorities"):
        priority_ranks([1.0, float("nan")], 2)


# --------------------------------------------------------------------------- input errors name the field
B2 = [[1.0, 0.5, 0.0], [0.0, 1.0, 1.0]]


@pytest.mark.parametrize("kwargs,field", [
    (dict(Wu=[[1, 0, 0], [0, 1]]), "Wu"),
    (dict(Wv=[[1, 0], [0]]), "Wv"),
    (dict(umin=[-1, -1, -(10**400)]), "umin"),
    (dict(umax=[1, 1, 10**400]), "umax"),
    (dict(B=[[10**400, 0, 0], [0, 1, 1]]), "B"),
    (dict(B=[[1, 2, 3], [1, 2]]), "B"),
    (dict(rate_min=[-1, None, float("nan")]), "rate_min"),
    (dict(Wu=[1e-60, 1, 1]), "Wu"),
    (dict(B=np.zeros((33, 3))), "B"),
])
def test_problem_input_errors_name_the_field(kwargs, field):
    args = dict(B=B2, umin=[-1] * 3, umax=[1] * 3)
    args.update(kwargs)
    with pytest.raises(alloc.ProblemError, match=f"^{field}: "):
        alloc.Problem(**args)


def test_representable_big_integers_are_numbers():
    p = alloc.Problem([[2**70, 1, 0], [0, 1, 1]], [-(10**20)] * 3, [10**20] * 3)
    f = alloc.make_allocator(p, "pinv")
    r = f([10**20, 3], u_prev=[0, 10**19, 0], dt=10**3)
    assert np.isfinite(r.u).all()


@pytest.mark.parametrize("call,field", [
    (lambda f: f([10**400, 0.0]), "v"),
    (lambda f: f([[1.0], [2.0, 3.0]]), "v"),
    (lambda f: f([1.0, 0.0], u_prev=[0, 0, 10**400], dt=0.01), "u_prev"),
    (lambda f: f([1.0, 0.0], u_prev=[0, 0, 0], dt=10**400), "dt"),
    (lambda f: f([1.0, 0.0], u_prev=[0, 0, 0], dt=True), "dt"),
    (lambda f: f.batch([[1.0, 2.0], [1.0]]), "V"),
])
@pytest.mark.parametrize("method", ["pinv", "da", "qp"])
def test_demand_errors_name_the_field(call, field, method):
    f = alloc.make_allocator(alloc.Problem(B2, [-1] * 3, [1] * 3, rate_min=[-1] * 3, rate_max=[1] * 3), method)
    with pytest.raises(alloc.DemandError, match=f"^{field}: "):
        call(f)


@pytest.mark.parametrize("method,options,field", [
    ("wls", dict(gamma="x"), "gamma"),
    ("wls", dict(gamma=float("nan")), "gamma"),
    ("pinv", dict(rcond="x"), "rcond"),
    ("cgi", dict(rcond=2.0), "rcond"),
    ("cgi", dict(rcond=-5), "rcond"),
    ("daisy", dict(rcond=2.0), "rcond"),
    ("daisy", dict(rcond=-5), "rcond"),
    ("daisy", dict(groups=[[float("nan")]]), "groups"),
    ("daisy", dict(groups=[[0, 1.7], [2]]), "groups"),
    ("pinv", dict(incremental="yes"), "incremental"),
    ("da_bisect", dict(angles=True), "angles"),
    ("da_table", dict(resolution=10**9), "resolution"),
    ("ganging", dict(G=[[1e300, 0], [0, 1], [1, 1]]), "G"),
])
def test_option_errors_name_the_option(method, options, field):
    p = alloc.Problem(B2, [-1] * 3, [1] * 3)
    with pytest.raises(alloc.AllocError, match=field):
        alloc.make_allocator(p, method, **options)


def test_daisy_group_index_is_never_truncated():
    p = alloc.Problem(B2, [-1] * 3, [1] * 3)
    f = alloc.make_allocator(p, "daisy", groups=[[0, 2.0], [1]])  # 2.0 is the integer 2 (JSON)
    assert [g.tolist() for g in f.impl.groups] == [[0, 2], [1]]


def test_null_rate_limit_round_trips():
    p = alloc.Problem(B2, [-1] * 3, [1] * 3, rate_min=[-1, None, -2], rate_max=[None, 1, 2])
    assert p.rate_min[1] == -np.inf and p.rate_max[0] == np.inf
    d = p.to_dict()
    assert d["rate_min"][1] is None and d["rate_max"][0] is None
    q = alloc.Problem(**d)
    assert q.to_dict() == d
    for a in ("B", "umin", "umax", "up", "Wu", "Wv", "rate_min", "rate_max"):
        np.testing.assert_array_equal(getattr(q, a), getattr(p, a))


# --------------------------------------------------------------------------- batch and single, frozen results
@pytest.mark.parametrize("method", DA)
def test_batch_equals_single_at_the_domain_edge(method):
    rng = np.random.default_rng(7)
    B = rng.standard_normal((3, 6))
    p = alloc.Problem(B, [-1] * 6, [1] * 6)
    V = np.vstack([rng.standard_normal((5, 3)) * s for s in (1.0, 1e30, 1e49)])
    single = alloc.make_allocator(p, method)
    rs = [single(v) for v in V]
    b = alloc.make_allocator(p, method).batch(V)
    for i, r in enumerate(rs):
        np.testing.assert_allclose(b.u[i], r.u, rtol=0, atol=1e-9)
        assert b.status[i] == r.status.value


@pytest.mark.parametrize("method", alloc.methods())
def test_result_owns_read_only_copies(method):
    p = alloc.Problem(B2, [-1] * 3, [1] * 3)
    f = alloc.make_allocator(p, method)
    v = np.array([0.5, 0.25])
    r = f(v)
    status = r.status
    v[0] = 99.0
    assert r.v.tolist() == [0.5, 0.25] and r.status is status
    np.testing.assert_allclose(r.unallocated, r.v - r.v_achieved)
    for a in (r.u, r.v, r.v_achieved):
        assert not a.flags.writeable
    b = f.batch(np.array([[0.5, 0.25]]))
    assert not b.u.flags.writeable and not b.v.flags.writeable


@pytest.mark.parametrize("method", ["qp", "wls", "lp", "da"])
def test_backend_failure_at_build_is_a_fallback_with_reason(method, monkeypatch):
    from alloc import registry
    from alloc.exceptions import SolverError

    def broken(*args, **kwargs):
        raise SolverError("backend refused to set up")

    monkeypatch.setattr(registry.get_method(method), "__init__", broken)
    p = alloc.Problem(B2, [-1] * 3, [1] * 3)
    f = alloc.make_allocator(p, method)
    r = f([0.5, 0.25])
    assert r.status.value == "fallback" and "refused" in r.message
    assert_honest(p, r)


@pytest.mark.parametrize("options", [{"gamma": 1e300}, {"gamma": 1e51}, {"backend": "daqp", "gamma": 1e9}])
def test_wls_gamma_outside_the_domain_is_refused_naming_it(options):
    """Found by the adversarial run (seed 20001645): ``wls`` accepted ``gamma = 1e300``, whose
    square is inf, and every call was a fallback "wls produced non-finite commands"."""
    p = alloc.Problem(B2, [-1] * 3, [1] * 3)
    with pytest.raises(alloc.AllocError) as info:
        alloc.make_allocator(p, "wls", **options)
    assert info.value.field == "gamma" and isinstance(info.value, TypeError)
    r = alloc.make_allocator(p, "wls", gamma=1e50)([0.5, 0.25])  # the domain's edge: an answer, not a fallback
    assert r.status.value in ("exact", "unattainable")
    assert_honest(p, r)
