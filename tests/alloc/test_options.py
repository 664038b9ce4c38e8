"""Method options are a typed specification validated once by the registry (alloc.options)."""

from __future__ import annotations

import inspect
import json

import numpy as np
import pytest

import alloc
from alloc.options import Option, validate
from alloc.registry import get_method

B = [[1.0, 0.5, 0.0], [0.0, 1.0, 1.0]]
LO, HI = [-1, -1, -1], [1, 1, 1]


def _constructor_options(cls) -> dict[str, inspect.Parameter]:
    """Keyword parameters of the first ``__init__`` in the MRO that names them."""
    for klass in cls.__mro__:
        if "__init__" not in vars(klass):
            continue
        params = list(inspect.signature(klass.__init__).parameters.values())[2:]  # self, problem
        if params and all(p.kind is p.VAR_KEYWORD for p in params):
            continue  # passes **options on to its base
        return {p.name: p for p in params}
    return {}


@pytest.mark.parametrize("method", alloc.methods())
def test_spec_names_and_defaults_are_the_constructors(method):
    cls = get_method(method)
    params = _constructor_options(cls)
    assert set(cls.options) == set(params)
    for name, spec in cls.options.items():
        assert isinstance(spec, Option)
        assert spec.default == params[name].default, name
        if spec.default is not None:
            assert spec.check(spec.default) == spec.default  # the default is admissible


@pytest.mark.parametrize("method", alloc.methods())
def test_method_info_lists_json_specs(method):
    info = alloc.method_info(method)
    json.dumps(info)
    assert set(info["options"]) == set(info["option_specs"]) == set(get_method(method).options)
    for spec in info["option_specs"].values():
        assert set(spec) == {"type", "default", "constraint", "doc"}


@pytest.mark.parametrize(
    "method,options,message",
    [
        ("pinv", {"rcond": 2.0}, "rcond: must be in [0, 1), got 2.0"),
        ("pinv_scale", {"rcond": -1e-3}, "rcond: must be in [0, 1), got -0.001"),
        ("cgi", {"rcond": float("nan")}, "rcond: must be a finite number, got nan"),
        ("daisy", {"rcond": 1.0}, "rcond: must be in [0, 1), got 1.0"),
        ("pinv", {"incremental": "yes"}, "incremental: must be true or false, got 'yes'"),
        ("wls", {"gamma": 0.0}, "gamma: must be in (0, 1e+50], got 0.0"),
        ("wls", {"gamma": "big"}, "gamma: must be a finite number, got 'big'"),
        ("qp", {"backend": "nope"}, "backend: must be one of active_set, daqp"),
        ("lp", {"backend": "osqp"}, "backend: must be one of simplex, daqp, highs, got 'osqp'"),
        ("da", {"backend": "osqp"}, "backend: must be one of auto, facet, simplex, daqp, highs, got 'osqp'"),
        ("da_bisect", {"angles": 0}, "angles: must be >= 1 and <= 1024, got 0"),
        ("da_bisect", {"max_rounds": 2.5}, "max_rounds: must be an integer, got 2.5"),
        ("da_table", {"resolution": 1}, "resolution: must be >= 2, got 1"),
        ("da_table", {"resolution": True}, "resolution: must be an integer, got True"),
        ("ganging", {"G": [[1.0, np.inf]] * 3}, "G: must have finite entries"),
        ("ganging", {"G": [1.0, 2.0]}, "G: must be a matrix (2-D), got 1-D"),
        ("qp", {"priorities": [float("nan"), 2]}, "priorities: must be a list of finite real numbers, got [nan, 2]"),
        ("cgi", {"priorities": "12"}, "priorities: must be a list of finite real numbers"),
        ("daisy", {"groups": [0, 1]}, "groups: must be a list of lists of effector indices or names"),
    ],
)
def test_bad_values_raise_one_option_error_naming_the_option(method, options, message):
    with pytest.raises(alloc.OptionError) as info:
        alloc.make_allocator(alloc.Problem(B, LO, HI), method, **options)
    assert str(info.value).startswith(message)
    assert info.value.field == next(iter(options))
    assert isinstance(info.value, TypeError) and isinstance(info.value, alloc.AllocError)


@pytest.mark.parametrize("method", alloc.methods())
def test_unknown_option_lists_the_accepted_ones(method):
    with pytest.raises(alloc.OptionError) as info:
        alloc.make_allocator(alloc.Problem(B, LO, HI), method, frobnicate=1)
    accepted = ", ".join(sorted(get_method(method).options)) or "none"
    assert str(info.value) == f"{method}: unknown option(s) ['frobnicate']; accepted: {accepted}"
    assert info.value.field == "frobnicate"


def test_values_are_normalised_and_only_given_ones_passed():
    spec = get_method("pinv").options
    assert validate("pinv", spec, {"rcond": 0}) == {"rcond": 0.0}
    assert type(validate("pinv", spec, {"rcond": np.float32(1e-8)})["rcond"]) is float
    assert validate("pinv", spec, {}) == {}
    assert validate("pinv", spec, {"incremental": np.bool_(True)}) == {"incremental": True}


def test_admissible_values_still_allocate():
    p = alloc.Problem(B, LO, HI)
    r = alloc.allocate(p, [0.5, 0.5], "pinv", rcond=0.0, incremental=True)
    assert r.status.value == "exact"
    r = alloc.allocate(p, [0.5, 0.5], "daisy", groups=[[0, 1], ["u2"]])
    assert r.status.value == "exact"
    np.testing.assert_allclose(np.asarray(B) @ r.u, [0.5, 0.5], atol=1e-12)


def test_problem_dependent_checks_stay_with_the_method():
    """A matrix of the wrong shape is only wrong for this problem: the method says so."""
    with pytest.raises(alloc.ProblemError, match=r"G: expected shape \(3, 2\)"):
        alloc.make_allocator(alloc.Problem(B, LO, HI), "ganging", G=np.ones((2, 3)))
