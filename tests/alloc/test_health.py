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


# ------------------------------------------------------------------ the specification table
from dataclasses import replace  # noqa: E402

from alloc import health  # noqa: E402
from alloc.health import (  # noqa: E402
    EFFECT_READS, FAILURE_KINDS, PARAMETERS, SIMULATOR_ONLY, TOLD_READS, Default, Effect, FailureKindError, KindSpec,
    Told,
)


@pytest.fixture
def scratch_table():
    """Kinds registered in a test disappear after it."""
    saved = dict(health._TABLE)
    yield
    health._TABLE.clear()
    health._TABLE.update(saved)


def test_every_row_is_complete_and_every_kind_is_told_its_example(nominal):
    assert list(FAILURE_KINDS) == ["jam", "hardover", "float", "effectiveness", "limits", "rate_limits", "repair"]
    for kind in FailureKind:
        spec = kind.spec
        assert spec.effects and spec.told and spec.meaning, kind
        reads = {p for e in spec.effects for p in EFFECT_READS[e]} | {p for t in spec.told for p in TOLD_READS[t]}
        assert reads == set(spec.params), kind
        assert not {Effect.BANDWIDTH, Effect.DELAY} & set(spec.effects), kind
        _, h = apply_event(nominal, {"a": EffectorHealth(effectiveness=0.8)}, FailureEvent("a", kind, **spec.example))
        assert (h == {}) == (kind is FailureKind.REPAIR)
    assert FailureKind.JAM.spec.params == {"position": Default.AT_FAILURE}
    assert FailureKind.HARDOVER.spec.params == {"position": Default.UPPER_LIMIT}
    # the simulator-only effects have their own rows, and no told rule
    assert {name: s.effects for name, s in SIMULATOR_ONLY.items()} == {"bandwidth": (Effect.BANDWIDTH,),
                                                                      "delay": (Effect.DELAY,)}
    assert not set(SIMULATOR_ONLY) & set(FAILURE_KINDS)


def test_failure_kind_is_a_closed_str_of_the_table():
    import pickle

    assert FailureKind("jam") is FailureKind.JAM and FailureKind(FailureKind.JAM) is FailureKind.JAM
    assert FailureKind.JAM == "jam" and FailureKind.JAM.value == "jam" and type(FailureKind.JAM.value) is str
    assert pickle.loads(pickle.dumps(FailureKind.LIMITS)) is FailureKind.LIMITS
    for bad in ("bandwidth", "loe", "", 3, None, "JAM"):
        with pytest.raises(ValueError, match="is not a failure kind"):
            FailureKind(bad)
    with pytest.raises(alloc.ProblemError, match="^position: a 'float' failure does not take it"):
        FailureEvent("a", "float", position=1.0)


def test_a_jam_position_must_be_given_outside_a_simulator(nominal):
    with pytest.raises(alloc.ProblemError, match="^position: required for a 'jam' failure"):
        FailureEvent("a", "jam")
    applied = health.resolve_event(nominal, FailureEvent("b", "hardover"))
    assert applied.position == 20.0 and applied.params == {"position": 20.0}


_EXAMPLE_VALUE = {"position": (-1, 1), "fraction": (0, 1), "lo": (-1, -0.1), "hi": (0.1, 1), "rate_min": (-20, 0),
                  "rate_max": (0, 20), "wn": (1, 10), "bogus": (0, 1)}


def _pick(rng: np.random.Generator, items: list, low: int, high: int) -> tuple:
    """``low`` to ``high - 1`` distinct items, as they are (numpy would turn them into its strings)."""
    return tuple(items[j] for j in rng.choice(len(items), size=rng.integers(low, high), replace=False))


def _random_spec(rng: np.random.Generator, i: int) -> KindSpec:
    """A consistent table row, then (half the time) broken in one or two ways."""
    told_effects = [e for e in Effect if e not in (Effect.BANDWIDTH, Effect.DELAY)]
    effects = _pick(rng, told_effects, 1, 3)
    told = _pick(rng, list(Told), 1, 3)
    reads = dict.fromkeys(p for e in effects for p in EFFECT_READS[e]) | dict.fromkeys(
        p for t in told for p in TOLD_READS[t])
    params = {n: None for n in reads}
    if "position" in params and {Effect.HOLD, Effect.RUN_TO_STOP} & set(effects):
        params["position"] = _pick(rng, [None, Default.UPPER_LIMIT, Default.AT_FAILURE], 1, 2)[0]
    example = {n: float(rng.uniform(*_EXAMPLE_VALUE[n])) for n in params if params[n] is None or rng.random() < 0.5}
    spec = KindSpec(f"kind_{i}", "a generated kind", params, effects, told, example)
    breaks = {
        "no effect": lambda s: replace(s, effects=()),
        "no told rule": lambda s: replace(s, told=()),
        "a dynamics effect": lambda s: replace(s, effects=(*s.effects, Effect.BANDWIDTH), params={**s.params, "wn": None}),
        "an unknown parameter": lambda s: replace(s, params={**s.params, "bogus": None}),
        "an unread parameter": lambda s: replace(s, params={**s.params, **{n: None for n in PARAMETERS
                                                                          if n not in s.params and n != "hi"}}),
        "a parameter missing": lambda s: replace(s, params=dict(list(s.params.items())[1:])),
        "a bad default": lambda s: replace(s, params={n: "later" for n in s.params}),
        "an at-failure default without a hold": lambda s: replace(
            s, effects=(Effect.TRAIL,), told=(Told.LIMITS,), params={"lo": Default.AT_FAILURE, "hi": None}),
        "an example without a required value": lambda s: replace(s, example={}),
        "an example of text": lambda s: replace(s, example={n: "half" for n in s.params}),
        "a name taken": lambda s: replace(s, name=_pick(rng, ["jam", "bandwidth", "repair"], 1, 2)[0]),
        "a bad name": lambda s: replace(s, name=_pick(rng, ["Bad-name", "x", "", "kind 2"], 1, 2)[0]),
        "no meaning": lambda s: replace(s, meaning=" "),
    }
    if rng.random() < 0.5:
        for key in _pick(rng, list(breaks), 1, 3):
            spec = breaks[key](spec)
    return spec


def _registrable(spec: KindSpec) -> bool:
    """The rules of a row, written out independently of alloc.health's checker."""
    import re

    if not re.fullmatch(r"[a-z][a-z0-9_]{1,30}", spec.name) or spec.name in FAILURE_KINDS or spec.name in SIMULATOR_ONLY:
        return False
    if not spec.meaning.strip() or not spec.effects or not spec.told:
        return False
    if any(n not in PARAMETERS or not (d is None or isinstance(d, Default)) for n, d in spec.params.items()):
        return False
    if "hi" in spec.params and "lo" not in spec.params:
        return False
    reads = {p for e in spec.effects for p in EFFECT_READS[e]} | {p for t in spec.told for p in TOLD_READS[t]}
    if reads != set(spec.params) or {Effect.BANDWIDTH, Effect.DELAY} & set(spec.effects):
        return False
    if Default.AT_FAILURE in spec.params.values() and not {Effect.HOLD, Effect.RUN_TO_STOP} & set(spec.effects):
        return False
    required = {n for n, d in spec.params.items() if d in (None, Default.AT_FAILURE)}
    return required <= set(spec.example) <= set(spec.params) and all(
        isinstance(v, float) for v in spec.example.values())  # (a text value is not a number)


def test_hostile_rows_fail_at_registration_and_registered_ones_work_everywhere(scratch_table):
    """Seeded generator: a row registers iff it is complete and consistent; a registered kind's
    example event is then told by the library (admissible problem, allocation within limits) and
    executed by the simulator's actuators, which tell the same health."""
    from sim.allocation import health_events
    from sim.blocks import ActuatorBank, ActuatorFailure, ActuatorSpec

    rng = np.random.default_rng(20261201)
    nominal = alloc.Problem([[1.0, 2.0, 0.5], [0.0, 1.0, -1.0]], [-1, -1, -1], [1, 1, 1],
                            rate_min=[-20, -20, -20], rate_max=[20, 20, 20], names=["a", "b", "c"])
    registered = 0
    for i in range(400):
        spec = _random_spec(rng, i)
        if not _registrable(spec):
            before = dict(FAILURE_KINDS)
            with pytest.raises(FailureKindError, match="^kind: failure kind"):
                health.register_failure_kind(spec)
            assert dict(FAILURE_KINDS) == before  # a refused row leaves the table as it was
            continue
        kind = health.register_failure_kind(spec)
        registered += 1
        _, h = apply_event(nominal, {}, FailureEvent("a", kind, **spec.example))
        told = nominal.with_health(h)
        r = alloc.allocate(told, [0.5, 0.2], "qp")
        assert np.isfinite(r.u).all() and (r.u >= told.umin - 1e-9).all() and (r.u <= told.umax + 1e-9).all()
        # the simulator executes the row's effects and tells what the library tells
        executes_rates = Effect.RATE_LIMITS in spec.effects
        if executes_rates and spec.example["rate_min"] != -spec.example["rate_max"]:
            with pytest.raises(alloc.ProblemError, match="^rate_min: the simulator's actuators have one symmetric"):
                ActuatorFailure(0, kind, **spec.example)
            continue
        bank = ActuatorBank([ActuatorSpec.second_order(n, 30.0, 0.7, -1.0, 1.0, 20.0) for n in "abc"], 0.0005)
        executed = bank.apply_failure(ActuatorFailure(0, kind, **spec.example))
        assert executed.params == health.resolve_defaults(spec, spec.example, limits=(-1.0, 1.0), position=0.0)
        for _ in range(20):
            pos = bank.step(np.array([2.0, -2.0, 0.3]))
        assert np.isfinite(pos).all() and 0.0 <= bank.effectiveness[0] <= 1.0
        vehicle = type("V", (), {"effector_names": ["a", "b", "c"]})
        failure = type("F", (), {"actuators": (executed,)})
        told_sim = {}
        for event in health_events(vehicle, failure):
            _, told_sim = apply_event(nominal, told_sim, event)
        _, from_library = apply_event(nominal, {}, FailureEvent("a", kind, **executed.params))
        assert told_sim == from_library
    assert registered >= 150  # the generator reaches the registrable rows, not only the refusals
