"""Bad input gets a clear error naming the field; never a crash deep in a solver."""

from __future__ import annotations

import numpy as np
import pytest

import alloc
from alloc.vehicles import ice

B = [[1.0, 0.5, 0.0], [0.0, 1.0, 1.0]]
LO, HI = [-1, -1, -1], [1, 1, 1]


@pytest.mark.parametrize(
    "kwargs,field",
    [
        (dict(B=[[1.0, 2.0]], umin=[-1, -1, -1], umax=[1, 1, 1]), "umin"),
        (dict(B=B, umin=LO, umax=[1, 1]), "umax"),
        (dict(B=[[1.0, np.nan, 0.0], [0, 1, 1]], umin=LO, umax=HI), "B"),
        (dict(B=[[1.0, np.inf, 0.0], [0, 1, 1]], umin=LO, umax=HI), "B"),
        (dict(B=B, umin=[-1, 2, -1], umax=HI), "umin/umax"),
        (dict(B=B, umin=LO, umax=HI, Wu=[1, -1, 1]), "Wu"),
        (dict(B=B, umin=LO, umax=HI, Wu=[[1, 2, 0], [2, 1, 0], [0, 0, 1]]), "Wu"),
        (dict(B=B, umin=LO, umax=HI, Wu=[[1, 0.5, 0], [0, 1, 0], [0, 0, 1]]), "Wu"),
        (dict(B=B, umin=LO, umax=HI, Wv=np.zeros((2, 2))), "Wv"),
        (dict(B=B, umin=LO, umax=HI, rate_min=[1, -1, -1]), "rate_min"),
        (dict(B=B, umin=LO, umax=HI, rate_max=[1, -1, 1]), "rate_max"),
        (dict(B=B, umin=LO, umax=HI, up=[0, 2, 0]), "up"),
        (dict(B=B, umin=LO, umax=HI, names=["a", "a", "b"]), "names"),
        (dict(B=[["x", 1, 2]], umin=LO, umax=HI), "B"),
        (dict(B=np.zeros((2, 2, 2)), umin=LO, umax=HI), "B"),
    ],
)
def test_problem_validation_names_the_field(kwargs, field):
    with pytest.raises(alloc.ProblemError, match=field) as info:
        alloc.Problem(kwargs.pop("B"), kwargs.pop("umin"), kwargs.pop("umax"), **kwargs)
    assert isinstance(info.value, ValueError)


def test_problem_is_immutable():
    p = alloc.Problem(B, LO, HI)
    with pytest.raises(AttributeError):
        p.B = np.eye(2)
    with pytest.raises(ValueError):
        p.B[0, 0] = 3.0


@pytest.mark.parametrize(
    "call,field",
    [
        (lambda a: a([1.0]), "v"),
        (lambda a: a([1.0, np.nan]), "v"),
        (lambda a: a(["a", 1.0]), "v"),
        (lambda a: a([1.0, 0.0], u_prev=[0, 0, 0], dt=-0.01), "dt"),
        (lambda a: a([1.0, 0.0], u_prev=[0, 0, 0], dt=0.0), "dt"),
        (lambda a: a([1.0, 0.0], u_prev=[0, 0], dt=0.01), "u_prev"),
        (lambda a: a([1.0, 0.0], u_prev=[0, np.inf, 0], dt=0.01), "u_prev"),
        (lambda a: a([1.0, 0.0], u_prev=[0, 0, 0]), "u_prev/dt"),
    ],
)
@pytest.mark.parametrize("method", alloc.methods())
def test_bad_demands_name_the_field(call, field, method):
    p = alloc.Problem(B, LO, HI, rate_min=[-1, -1, -1], rate_max=[1, 1, 1])
    with pytest.raises(alloc.DemandError, match=field):
        call(alloc.make_allocator(p, method))


def test_unknown_method_lists_registered_names():
    with pytest.raises(alloc.UnknownMethodError, match="registered: .*pinv"):
        alloc.make_allocator(alloc.Problem(B, LO, HI), "simplex")


@pytest.mark.parametrize("method", alloc.methods())
def test_unknown_option_is_a_type_error(method):
    with pytest.raises(TypeError, match="unknown option"):
        alloc.make_allocator(alloc.Problem(B, LO, HI), method, frobnicate=1)


@pytest.mark.parametrize(
    "method,options,field",
    [
        ("ganging", dict(G=np.ones((2, 3))), "G"),
        ("daisy", dict(groups=[[0, 1], [1, 2]]), "groups"),
        ("daisy", dict(groups=[[0, 7]]), "effector"),
        ("cgi", dict(priorities=[1, 2, 3]), "priorities"),
        ("qp", dict(priorities=[1.5, float("nan")]), "priorities"),
        ("qp", dict(backend="nope"), "backend"),
        ("lp", dict(backend="osqp"), "backend"),
    ],
)
def test_bad_options_name_the_option(method, options, field):
    with pytest.raises((ValueError, TypeError), match=field):
        alloc.make_allocator(alloc.Problem(B, LO, HI), method, **options)


def test_effective_bounds_follow_eq_1_28():
    p = alloc.Problem(B, LO, HI, rate_min=[-2, -2, -2], rate_max=[1, 1, 1])
    lo, hi = p.effective_bounds([0.95, 0.0, -0.9], dt=0.1)
    np.testing.assert_allclose(lo, [0.75, -0.2, -1.0])
    np.testing.assert_allclose(hi, [1.0, 0.1, -0.8])


def test_u_prev_outside_reduced_limits_goes_to_the_nearest_limit():
    p = alloc.Problem(B, LO, HI, rate_min=[-1, -1, -1], rate_max=[1, 1, 1]).with_limits(0, -0.2, 0.2)
    lo, hi = p.effective_bounds([0.9, 0.0, 0.0], dt=0.01)
    assert lo[0] == hi[0] == pytest.approx(0.2)


def test_reconfiguration_helpers():
    p = ice()
    jam = p.with_jam("lef_l", 10.0)
    assert jam.umin[7] == jam.umax[7] == 10.0 and jam.up[7] == 10.0
    with pytest.raises(alloc.ProblemError, match="position"):
        p.with_jam("lef_l", 50.0)
    half = p.with_effectiveness(0, 0.5)
    np.testing.assert_allclose(half.B[:, 0], 0.5 * p.B[:, 0])
    with pytest.raises(alloc.ProblemError, match="fraction"):
        p.with_effectiveness(0, 1.5)
    with pytest.raises(alloc.ProblemError, match="unknown name"):
        p.with_jam("canard", 0.0)
