"""The core effector-health model: one meaning per failure kind (alloc.health)."""

import numpy as np
import pytest

import alloc
import alloc.registry
from alloc.health import (
    HEALTHY, EffectorHealth, FailureEvent, FailureKind, apply_event, health_from_dict, health_to_dict,
)


@pytest.fixture
def nominal() -> alloc.Problem:
    return alloc.Problem([[1.0, 2.0, 0.5], [0.0, 1.0, -1.0]], [-10, -20, 0], [10, 20, 60],
                         rate_min=[-40, -40, -40], rate_max=[40, 40, 40], names=["a", "b", "c"])


def test_each_kind_changes_the_problem_as_documented(nominal):
    h = {}
    _, h = apply_event(nominal, h, FailureEvent("a", "jam", position=3.0))
    _, h = apply_event(nominal, h, FailureEvent(1, FailureKind.EFFECTIVENESS, fraction=0.25))
    _, h = apply_event(nominal, h, FailureEvent("c", "rate_limits", rate_min=-5, rate_max=7))
    p = nominal.with_health(h)
    assert (p.umin[0], p.umax[0]) == (3.0, 3.0)
    np.testing.assert_array_equal(p.B[:, 1], nominal.B[:, 1] * 0.25)
    assert (p.rate_min[2], p.rate_max[2]) == (-5.0, 7.0)
    np.testing.assert_array_equal(p.B[:, [0, 2]], nominal.B[:, [0, 2]])


def test_hardover_defaults_to_the_upper_limit_and_float_holds_up(nominal):
    _, h = apply_event(nominal, {}, FailureEvent("b", "hardover"))
    assert h["b"].jam_position == 20.0
    _, h = apply_event(nominal, h, FailureEvent("b", "float"))
    p = nominal.with_health(h)
    assert h["b"].status == "floating" and h["b"].jam_position is None
    assert p.umin[1] == p.umax[1] == nominal.up[1] and not p.B[:, 1].any()


def test_limits_then_jam_then_repair(nominal):
    _, h = apply_event(nominal, {}, FailureEvent("c", "limits", lo=5, hi=30))
    assert nominal.with_health(h).umax[2] == 30.0 and h["c"].status == "degraded"
    _, h = apply_event(nominal, h, FailureEvent("c", "jam", position=50))
    assert nominal.with_health(h).umin[2] == 50.0  # a jam overrides reduced limits
    _, h = apply_event(nominal, h, FailureEvent("c", "repair"))
    assert h == {} and nominal.with_health(h) is nominal


@pytest.mark.parametrize("event, field", [
    (FailureEvent("a", "jam", position=11.0), "position"),
    (FailureEvent("a", "effectiveness", fraction=1.5), "fraction"),
    (FailureEvent("a", "limits", lo=-11, hi=0), "lo"),
    (FailureEvent("a", "limits", lo=2, hi=1), "hi"),
    (FailureEvent("a", "rate_limits", rate_min=-50, rate_max=1), "rate_min"),
])
def test_out_of_range_events_name_the_field(nominal, event, field):
    with pytest.raises(alloc.ProblemError, match=f"^{field}:"):
        apply_event(nominal, {}, event)


@pytest.mark.parametrize("kwargs, field", [
    ({"kind": "melted"}, "kind"), ({"kind": "jam"}, "position"),
    ({"kind": "jam", "position": float("nan")}, "position"), ({"kind": "jam", "position": True}, "position"),
    ({"kind": "limits", "lo": 1.0}, "hi"),
])
def test_malformed_events_name_the_field(kwargs, field):
    with pytest.raises(alloc.ProblemError, match=f"^{field}:"):
        FailureEvent("a", **kwargs)


def test_json_round_trip(nominal):
    h = {"a": EffectorHealth(jam_position=1.0), "b": EffectorHealth(effectiveness=0.5, rate_limits=(-1.0, 2.0)),
         "c": EffectorHealth(floating=True, limits=(0.0, 5.0))}
    assert health_from_dict(health_to_dict(h)) == h
    assert HEALTHY.status == "healthy"


def test_capabilities_are_declared_not_guessed():
    info = {name: alloc.method_info(name)["capabilities"] for name in alloc.methods()}
    assert {n for n, c in info.items() if c["needs_ams"]} == {"da_facet", "da_bisect", "da_table"}
    assert {n for n, c in info.items() if c["affine"]} == {"ganging", "pinv", "pinv_clip"}
    assert {n for n, c in info.items() if c["supports_priorities"]} == {"qp", "lp", "cgi"}
    for name, caps in info.items():
        cls = alloc.registry.get_method(name)
        assert caps["supports_priorities"] == ("priorities" in cls.options), name
        assert caps["supports_batch"] == (cls.solve_batch is not alloc.registry.Method.solve_batch), name
    p = alloc.Problem(np.ones((3, 11)), -np.ones(11), np.ones(11))
    assert alloc.registry.get_method("da_facet").facet_subsets(p, {}) == 55
    assert alloc.registry.get_method("pinv").facet_subsets(p, {}) == 0


@pytest.mark.parametrize("msg, field", [
    ("rate_min: rate_min[1] = 2 must be <= 0", "rate_min"), ("umin/umax: umin[0] > umax[0]", "umin/umax"),
    ("Wu[3]: negative", "Wu"), ("no field here", None), ("two words: reason", None),
])
def test_errors_carry_the_field(msg, field):
    assert alloc.ProblemError(msg).field == field
    assert alloc.OptionError("x", field="gamma").field == "gamma"
