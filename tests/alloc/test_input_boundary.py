"""The input boundary (issue 22): every numeric field refuses what is not a real number of
the valid domain with an AllocError naming the field.

Refused everywhere a number is expected: complex values (a cast would drop the imaginary
part), booleans (``True`` is an ``int`` to Python but never a limit or a weight), text,
``None`` (except as JSON ``null`` for "no rate limit"), Python integers too large for a
float, NaN/inf and magnitudes above ``MAX_MAGNITUDE``.  Numeric arrays of any real dtype
(float16/32, ints, big-endian) and object arrays of real numbers are accepted.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import alloc
from alloc.health import (
    EffectorHealth, FailureEvent, apply_event, apply_health, health_from_dict,
)
from alloc.problem import MAX_MAGNITUDE, MIN_WEIGHT

B = [[1.0, 0.5, -0.3], [0.2, 1.0, 0.7]]
LO, HI = [-1.0] * 3, [1.0] * 3

#: one hostile scalar per class the boundary refuses
BAD = {
    "big int": 10**400, "complex": 1 + 2j, "numpy complex": np.complex128(1.0), "bool": True,
    "numpy bool": np.bool_(True), "text": "1.5", "object": object(), "nan": float("nan"), "huge": 1e300,
}
FILL = {"B": 0.5, "umin": -1.0, "umax": 1.0, "up": 0.0, "Wu": 1.0, "Wv": 1.0, "rate_min": -1.0, "rate_max": 1.0}


@pytest.fixture(autouse=True)
def _no_complex_warning():
    # a silently dropped imaginary part shows as numpy's ComplexWarning: make it an error
    with warnings.catch_warnings():
        warnings.simplefilter("error", np.exceptions.ComplexWarning)
        yield


def _problem_with(field: str, bad: object) -> dict:
    n = 2 if field == "Wv" else 3
    fields = {"B": [list(r) for r in B], "umin": list(LO), "umax": list(HI)}
    if field == "B":
        fields["B"][0][1] = bad
    else:
        fields[field] = [bad] + [FILL[field]] * (n - 1)
    return fields


@pytest.mark.parametrize("bad", list(BAD), ids=list(BAD))
@pytest.mark.parametrize("field", list(FILL))
def test_problem_refuses_each_non_real_element_naming_the_field(field, bad):
    with pytest.raises(alloc.ProblemError) as info:
        alloc.Problem(**_problem_with(field, BAD[bad]))
    assert info.value.field == field


@pytest.mark.parametrize("dtype", [complex, bool, "U3"])
@pytest.mark.parametrize("field", list(FILL))
def test_problem_refuses_non_real_arrays(field, dtype):
    n = 2 if field == "Wv" else 3
    fields = {"B": np.array(B), "umin": np.array(LO), "umax": np.array(HI)}
    shape = (2, 3) if field == "B" else (n,)
    fields[field] = np.ones(shape).astype(dtype)
    with pytest.raises(alloc.ProblemError, match=f"^{field}: (complex|boolean|text) values are not accepted") as info:
        alloc.Problem(**fields)
    assert info.value.field == field


@pytest.mark.parametrize("bad", list(BAD), ids=list(BAD))
@pytest.mark.parametrize("field", ["umin", "umax", "B", "Wu"])
def test_replace_refuses_each_non_real_element_naming_the_field(field, bad):
    """``replace`` re-clips ``up`` into new limits before validating: that step must not
    raise a raw TypeError/OverflowError/ValueError of its own."""
    p = alloc.Problem(B, LO, HI)
    with pytest.raises(alloc.ProblemError) as info:
        p.replace(**{field: _problem_with(field, BAD[bad])[field]})
    assert info.value.field == field


@pytest.mark.parametrize("dtype", [np.float16, np.float32, np.int8, ">f8", object])
def test_real_arrays_of_any_dtype_are_accepted(dtype):
    p = alloc.Problem(np.array(B).astype(dtype), np.array(LO).astype(dtype), np.array(HI).astype(dtype))
    assert p.B.dtype == np.float64 and p.B[0, 1] == np.float64(np.array(0.5).astype(dtype))
    np.testing.assert_array_equal(alloc.Problem([[2**70, 1]], [-1, -1], [1, 1]).B, [[2.0**70, 1.0]])


# ------------------------------------------------------------------------- the call arguments
@pytest.fixture(scope="module")
def problem() -> alloc.Problem:
    return alloc.Problem(B, LO, HI, rate_min=[-1.0] * 3, rate_max=[1.0] * 3)


#: fused closed form (C call path), packed compiled call, Python call path
CALL_METHODS = ["pinv", "qp", "lp", "dynamic"]


@pytest.mark.parametrize("bad", list(BAD), ids=list(BAD))
@pytest.mark.parametrize("method", CALL_METHODS)
def test_calls_refuse_each_non_real_value_naming_the_argument(problem, method, bad):
    f = alloc.make_allocator(problem, method)
    x = BAD[bad]
    cases = {
        "v": lambda: f([x, 0.1]),
        "u_prev": lambda: f(np.array([0.1, 0.1]), u_prev=[x, 0.0, 0.0], dt=0.1),
        "dt": lambda: f(np.array([0.1, 0.1]), u_prev=np.zeros(3), dt=x),
        "V": lambda: f.batch([[x, 0.1]]),
    }
    for field, call in cases.items():
        with pytest.raises(alloc.DemandError) as info:
            call()
        assert info.value.field == field, (field, str(info.value))


@pytest.mark.parametrize("method", CALL_METHODS)
def test_complex_and_boolean_arrays_are_refused_on_every_call_path(problem, method):
    """The issue's reproducer: a complex ``v`` (and ``u_prev``, ``V``) was accepted and its
    imaginary part silently dropped."""
    f = alloc.make_allocator(problem, method)
    for dtype in (np.complex128, np.complex64, bool):
        with pytest.raises(alloc.DemandError, match="^v: "):
            f(np.ones(2, dtype=dtype))
        with pytest.raises(alloc.DemandError, match="^u_prev: "):
            f(np.ones(2), u_prev=np.zeros(3, dtype=dtype), dt=0.1)
        with pytest.raises(alloc.DemandError, match="^V: "):
            f.batch(np.ones((3, 2), dtype=dtype))
    with pytest.raises(alloc.DemandError, match="^dt: "):
        f(np.ones(2), u_prev=np.zeros(3), dt=np.complex128(0.1))
    r = f(np.ones(2, dtype=np.float32) * 0.25)  # a real dtype other than float64 is a demand
    assert r.v.dtype == np.float64 and r.v[0] == 0.25


# ----------------------------------------------------------------------------- options
def _numeric_options():
    import alloc.registry

    for method in alloc.methods():
        for name, spec in alloc.registry.get_method(method).options.items():
            if spec.type in ("float", "int", "matrix", "weight"):
                yield method, name, spec.type


@pytest.mark.parametrize("bad", ["big int", "complex", "numpy complex", "bool", "text", "nan", "huge"])
@pytest.mark.parametrize("method, name, kind", list(_numeric_options()))
def test_numeric_options_refuse_non_real_values_naming_the_option(problem, method, name, kind, bad):
    x = BAD[bad]
    value = [[x, 0.0], [0.0, 1.0], [1.0, 1.0]] if kind == "matrix" else x
    with pytest.raises(alloc.OptionError) as info:
        alloc.make_allocator(problem, method, **{name: value})
    assert name in str(info.value)
    if (method, name) not in FIELD_FROM_METHOD:
        assert info.value.field == name


#: Options whose admissible range the method checks after the registry (its spec leaves the
#: range open): the message names the option, ``field`` names the method.  alloc/methods/
#: facet_search.py's ``resolution`` spec needs ``high=256`` to close this.
FIELD_FROM_METHOD = {("da_table", "resolution")}


@pytest.mark.parametrize("method, options", [
    ("wls", {"gamma": 10**400}), ("pinv", {"rcond": 10**400}), ("cgi", {"rcond": -(10**400)}),
    ("ganging", {"G": [[10**400, 0.0], [0.0, 1.0], [1.0, 1.0]]}), ("ganging", {"G": np.ones((3, 2)) * 1e300}),
    ("dynamic", {"W1": 10**400}), ("dynamic", {"W2": [[1 + 1j, 0, 0], [0, 1, 0], [0, 0, 1]]}),
])
def test_issue_reproducers_big_integer_options_are_refused_not_built(problem, method, options):
    """Issue 22: ``gamma=10**400`` built an allocator whose every call fell back."""
    (name,) = options
    with pytest.raises(alloc.OptionError, match=f"^{name}: ") as info:
        alloc.make_allocator(problem, method, **options)
    assert info.value.field == name


# ----------------------------------------------------------------------------- weights
def test_a_weight_whose_largest_eigenvalue_leaves_the_domain_is_refused():
    """Issue 22: entries within 1e50 but the largest eigenvalue about 5e52 passed the check."""
    n = 512
    a, b = 0.9e50, 0.1e50
    W = a * np.ones((n, n)) + b * np.eye(n)  # eigenvalues b (n - 1 times) and b + n a = 4.6e52
    assert np.abs(W).max() <= MAX_MAGNITUDE
    Bw = np.ones((1, n))
    with pytest.raises(alloc.ProblemError, match="^Wu: weight matrix's largest eigenvalue 4.6") as info:
        alloc.Problem(Bw, -np.ones(n), np.ones(n), Wu=W)
    assert info.value.field == "Wu"
    edge = np.array([[2.0, 1.0], [1.0, 2.0]]) * (MAX_MAGNITUDE / 3.0)  # eigenvalues 1/3 and 1 of the cap
    assert alloc.Problem([[1.0, 1.0]], [-1, -1], [1, 1], Wu=edge).Wu[0, 0] == edge[0, 0]
    over = np.array([[0.9, 0.6], [0.6, 0.9]]) * MAX_MAGNITUDE  # eigenvalues 0.3 and 1.5 of the cap
    with pytest.raises(alloc.ProblemError, match="^Wv: weight matrix's largest eigenvalue 1.5e\\+50"):
        alloc.Problem([[1.0], [1.0]], [-1], [1], Wv=over)


# ----------------------------------------------------------------------------- dynamic W1, W2
@pytest.mark.parametrize("field", ["W1", "W2"])
@pytest.mark.parametrize("value", [1e30, 1e-30, 1e-200, [1.0, 1.0, 1e26], [[1.0, 1.0, 0.0], [1.0, 1.0, 0.0], [0, 0, 1]]])
def test_dynamic_weights_are_range_checked_by_their_own_names(problem, field, value):
    """Issue 22: large W1 was refused naming ``Wu`` (never passed), tiny W1 and W2 built an
    allocator whose every call fell back."""
    with pytest.raises(alloc.OptionError, match=f"^{field}: ") as info:
        alloc.make_allocator(problem, "dynamic", **{field: value})
    assert info.value.field == field
    assert "Wu" not in str(info.value)


def _rank_deficient(rng: np.random.Generator, n: int) -> np.ndarray:
    """A random n x n matrix of rank below n, scaled over 40 decades: exactly singular, but its
    computed singular values and eigenvalues are round-off, not zero."""
    r = int(rng.integers(0, n))
    F = rng.standard_normal((n, r)) @ rng.standard_normal((r, n)) if r else np.zeros((n, n))
    if rng.random() < 0.5:  # duplicated rows and columns, the shape of a copy-paste error
        F = rng.standard_normal((n, n))
        j = rng.integers(0, n, size=2)
        F[j[0]] = F[j[1]] if j[0] != j[1] else 0.0
    return F * 10.0 ** rng.uniform(-20, 20)


@pytest.mark.parametrize("seed", range(4))
def test_rank_deficient_weight_matrices_are_refused_whatever_the_round_off(seed):
    """Issue 22 class: with numpy 2.4.6 the zero singular value of a rank-2 W1 came out as
    3e-17, above the absolute floor, and the singular W1 built an allocator.  A full matrix must
    be numerically nonsingular (smallest over largest above n eps) for W1, W2, Wu and Wv."""
    rng = np.random.default_rng(seed)
    for _ in range(40):
        F = _rank_deficient(rng, 3)
        if not np.abs(F).max() > 0:
            continue
        for field in ("W1", "W2"):
            with pytest.raises(alloc.OptionError, match=f"^{field}: ") as info:
                alloc.make_allocator(alloc.Problem(B, LO, HI), "dynamic", **{field: F})
            assert info.value.field == field
        Q = F.T @ F  # positive semidefinite, singular
        with pytest.raises(alloc.ProblemError, match="^Wu: weight matrix is not positive definite") as info:
            alloc.Problem(B, LO, HI, Wu=Q)
        assert info.value.field == "Wu"
        G = _rank_deficient(rng, 2)
        if np.abs(G).max() > 0:
            with pytest.raises(alloc.ProblemError, match="^Wv: weight matrix is not positive definite"):
                alloc.Problem(B, LO, HI, Wv=G.T @ G)
    # the relative test leaves well-conditioned full matrices and exact diagonals alone
    R = np.linalg.qr(rng.standard_normal((3, 3)))[0]
    alloc.make_allocator(alloc.Problem(B, LO, HI, Wu=R @ np.diag([1e-6, 1.0, 1e6]) @ R.T), "dynamic", W1=R)
    alloc.Problem(B, LO, HI, Wu=np.diag([1e-40, 1.0, 1e40]))


def test_dynamic_weights_at_the_ends_of_their_range_allocate_without_fallback(problem):
    from alloc.methods.dynamic import W_MAX, W_MIN

    assert W_MIN**2 >= MIN_WEIGHT and 2 * W_MAX**2 <= MAX_MAGNITUDE
    v = np.array([0.3, -0.2])
    for W1, W2 in [(W_MIN, W_MIN), (W_MAX, W_MAX), (W_MIN, W_MAX), (W_MAX, W_MIN), (1.0, 1.0)]:
        f = alloc.make_allocator(problem, "dynamic", W1=W1, W2=W2)
        assert f.build_error == ""
        for r in (f(v), f(v, u_prev=np.full(3, 0.1), dt=1.0)):  # the rate window holds v
            assert r.status.value == "exact", (W1, W2, r.message)
            np.testing.assert_allclose(problem.B @ r.u, v, atol=1e-9)


# ----------------------------------------------------------------------------- health API
@pytest.fixture(scope="module")
def nominal() -> alloc.Problem:
    return alloc.Problem(B, [-1.0, -2.0, 0.0], [1.0, 2.0, 3.0], rate_min=[-4.0] * 3, rate_max=[4.0] * 3,
                         names=["a", "b", "c"])


@pytest.mark.parametrize("call, field", [
    (lambda: FailureEvent(0, "jam", position=10**400), "position"),
    (lambda: FailureEvent(0, "jam", position=1j), "position"),
    (lambda: FailureEvent(0, "jam", position="0.5"), "position"),
    (lambda: FailureEvent(0, "effectiveness", fraction=True), "fraction"),
    (lambda: FailureEvent(0, "limits", lo=-(10**400), hi=1), "lo"),
    (lambda: FailureEvent(0, "rate_limits", rate_min=-1, rate_max=float("inf")), "rate_max"),
    (lambda: FailureEvent([0], "float"), "effector"),
    (lambda: FailureEvent(True, "float"), "effector"),
    (lambda: FailureEvent(0, "melted"), "kind"),
    (lambda: EffectorHealth(jam_position="x"), "jam_position"),
    (lambda: EffectorHealth(floating="false"), "floating"),
    (lambda: EffectorHealth(floating=1), "floating"),
    (lambda: EffectorHealth(effectiveness=1.5), "effectiveness"),
    (lambda: EffectorHealth(effectiveness=10**400), "effectiveness"),
    (lambda: EffectorHealth(limits=(2.0, 1.0)), "limits"),
    (lambda: EffectorHealth(limits="ab"), "limits"),
    (lambda: EffectorHealth(limits=(0.0, 1.0, 2.0)), "limits"),
    (lambda: EffectorHealth(rate_limits=(1.0, 2.0)), "rate_limits"),
    (lambda: health_from_dict({"a": {"effectiveness": "x"}}), "effectiveness"),
    (lambda: health_from_dict({"a": {"floating": "false"}}), "floating"),
    (lambda: health_from_dict({"a": {"limits": [0, "1"]}}), "limits"),
    (lambda: health_from_dict({"a": {"colour": "red"}}), "health"),
    (lambda: health_from_dict({"a": 3}), "health"),
    (lambda: health_from_dict([1, 2]), "health"),
    (lambda: health_from_dict({1: {}}), "health"),
])
def test_health_values_raise_problem_error_naming_the_field(call, field):
    """Issue 22: the health API raised raw OverflowError/ValueError/AttributeError/IndexError
    and read ``"floating": "false"`` as ``True``."""
    with pytest.raises(alloc.ProblemError) as info:
        call()
    assert info.value.field == field, str(info.value)


@pytest.mark.parametrize("call, field", [
    (lambda p: p.with_jam(0, "abc"), "position"),
    (lambda p: p.with_jam(0, 10**400), "position"),
    (lambda p: p.with_jam(0, 1j), "position"),
    (lambda p: p.with_limits(0, -(10**400), 1), "lo"),
    (lambda p: p.with_limits(0, -0.5, None), "hi"),
    (lambda p: p.with_limits(0, -5.0, 0.5), "limits"),  # wider than the nominal limits
    (lambda p: p.with_limits(0, 0.5, -0.5), "limits"),
    (lambda p: p.with_effectiveness(0, "0.5"), "fraction"),
    (lambda p: p.with_effectiveness(0, True), "fraction"),
    (lambda p: p.with_jam(10**400, 0.0), "effector"),
    (lambda p: p.with_health([1, 2]), "health"),
    (lambda p: p.with_health({"a": {"effectiveness": 0.5}}), "health"),
    (lambda p: p.with_health({"a": EffectorHealth(jam_position=5.0)}), "position"),
    (lambda p: p.with_health({"a": EffectorHealth(limits=(5.0, 6.0))}), "limits"),
    (lambda p: apply_event(p, {}, {"effector": "a", "kind": "float"}), "event"),
    (lambda p: apply_event(p, None, FailureEvent("a", "float")), "health"),
    (lambda p: apply_health(p, {"zz": EffectorHealth(effectiveness=0.5)}), "effector"),
])
def test_problem_health_entry_points_raise_problem_error_naming_the_field(nominal, call, field):
    with pytest.raises(alloc.ProblemError) as info:
        call(nominal)
    assert info.value.field == field, str(info.value)


def test_with_health_intersects_reduced_limits_with_the_nominal_ones(nominal):
    """Issue 22: ``with_health`` applied reduced limits wider than the nominal ones."""
    h = {"a": EffectorHealth(limits=(-5.0, 0.5)), "b": EffectorHealth(limits=(-1.0, 9.0), rate_limits=(-9.0, 2.0))}
    p = nominal.with_health(h)
    np.testing.assert_array_equal(p.umin, [-1.0, -1.0, 0.0])
    np.testing.assert_array_equal(p.umax, [0.5, 2.0, 3.0])
    np.testing.assert_array_equal(p.rate_min, [-4.0, -4.0, -4.0])
    np.testing.assert_array_equal(p.rate_max, [4.0, 2.0, 4.0])
    assert (p.umin <= nominal.umax).all() and (p.umin >= nominal.umin).all() and (p.umax <= nominal.umax).all()


def test_health_round_trips_through_its_json_form_exactly(nominal):
    from alloc.health import health_to_dict

    h = {"a": EffectorHealth(jam_position=0.25), "b": EffectorHealth(floating=True),
         "c": EffectorHealth(effectiveness=0.3, limits=(0.5, 2.5), rate_limits=(-1.0, 1.5))}
    assert health_from_dict(health_to_dict(h)) == h
    assert health_from_dict(None) == {} and health_from_dict({}) == {}
    assert health_from_dict({"a": {"floating": False, "effectiveness": 1}}) == {"a": EffectorHealth()}


# ------------------------------------------------------------------------- structure
def _deep(depth: int = 100_000) -> list:
    x: list = [0.1]
    for _ in range(depth):
        x = [x]
    return x


def test_deeply_nested_values_are_refused_naming_the_field(problem):
    """A message quoting the value must not exhaust the recursion limit (a RecursionError at
    build became a silent fallback allocator)."""
    import alloc.health as health

    deep = _deep()
    f = alloc.make_allocator(problem, "pinv")
    cases = {
        "v": lambda: f(deep), "dt": lambda: f(np.ones(2), u_prev=np.zeros(3), dt=deep),
        "u_prev": lambda: f(np.ones(2), u_prev=deep, dt=0.1), "V": lambda: f.batch(deep),
        "B": lambda: alloc.Problem(deep, [-1], [1]), "position": lambda: problem.with_jam(0, deep),
        "gamma": lambda: alloc.make_allocator(problem, "wls", gamma=deep),
        "G": lambda: alloc.make_allocator(problem, "ganging", G=deep),
        "W1": lambda: alloc.make_allocator(problem, "dynamic", W1=deep),
        "priorities": lambda: alloc.make_allocator(problem, "qp", priorities=deep),
        "kind": lambda: health.FailureEvent(0, deep), "effector": lambda: health.FailureEvent(deep, "float"),
        "limits": lambda: health.health_from_dict({"u0": {"limits": deep}}),
        "names": lambda: alloc.Problem(B, LO, HI, names=[deep, "b", "c"]),
    }
    for field, call in cases.items():
        with pytest.raises(alloc.AllocError) as info:
            call()
        assert info.value.field == field, (field, str(info.value))
        assert len(str(info.value)) < 400


@pytest.mark.parametrize("labels", [[1, 2, 3], [None, "b", "c"], ["a", b"b", "c"], 5])
def test_names_must_be_strings(labels):
    """``1`` and ``"1"`` are one name in JSON and two in Python: names are strings only."""
    with pytest.raises(alloc.ProblemError, match="^names: ") as info:
        alloc.Problem(B, LO, HI, names=labels)
    assert info.value.field == "names"
    assert alloc.Problem(B, LO, HI, names=np.array(["a", "b", "c"])).names == ("a", "b", "c")
