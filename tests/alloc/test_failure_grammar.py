"""The failure grammar (:mod:`alloc.failure_grammar`): what it reads back, and what it refuses.

Round trip: ``parse_failure(format_failure(spec)) == spec`` over a seeded generator of valid
specs (every kind of the table, values inside their ranges, effector names with the
characters a vehicle file allows).  Hostile text -- a seeded generator of bad kinds, unknown
effectors, bad or non-finite numbers, empty, huge and non-ASCII text -- is refused with an
:class:`alloc.AllocError` whose field is ``failure``.
"""

from __future__ import annotations

import numpy as np
import pytest

import alloc
from alloc.failure_grammar import (
    GRAMMAR,
    MAX_PARTS,
    MAX_TEXT,
    EffectorFailure,
    failure_kinds,
    format_failure,
    parse_failure,
)
from alloc.health import (
    FAILURE_KINDS,
    PARAMETERS,
    SIMULATOR_ONLY,
    SIMULATOR_PARAMETERS,
    Range,
)

EFFECTORS = ("elevon_l", "lef_l", "motor 1", "rotor:3", "flap-2", "élevon")
LIMITS = (-30.0, 30.0)
RATE = 100.0


def _value(rng: np.random.Generator, param: str) -> float:
    """A value inside ``param``'s range on an effector with :data:`LIMITS` and rate :data:`RATE`."""
    known = PARAMETERS.get(param) or SIMULATOR_PARAMETERS[param]
    draw = {
        Range.POSITION: lambda: rng.uniform(*LIMITS), Range.FRACTION: lambda: rng.uniform(0.0, 1.0),
        Range.RATE_MIN: lambda: -rng.uniform(0.0, RATE), Range.RATE_MAX: lambda: rng.uniform(0.0, RATE),
        Range.POSITIVE: lambda: rng.uniform(1e-3, 1e3), Range.NON_NEGATIVE: lambda: rng.uniform(0.0, 1.0),
    }[known.range]()
    # whole numbers, long binary fractions and small or large magnitudes alike (15, 30.000000000000004, 1e-07)
    if known.range is not Range.POSITIVE and rng.random() < 0.3:
        return float(np.round(draw))
    if known.range in (Range.POSITIVE, Range.NON_NEGATIVE):
        return float(draw * 10.0 ** int(rng.integers(-8, 9)))
    return float(draw)


def _spec(rng: np.random.Generator) -> tuple[EffectorFailure, ...]:
    out = []
    for _ in range(int(rng.integers(1, 5))):
        kind = str(rng.choice(failure_kinds()))
        row = SIMULATOR_ONLY.get(kind) or FAILURE_KINDS[kind]
        order = list(row.params)
        required = sum(1 for p in order if row.params[p] is None)
        n = int(rng.integers(required, len(order) + 1))
        params = {p: _value(rng, p) for p in order[:n]}
        if "lo" in params and "hi" in params and params["lo"] > params["hi"]:
            params["lo"], params["hi"] = params["hi"], params["lo"]
        out.append(EffectorFailure(kind, str(rng.choice(EFFECTORS)), params))
    return tuple(out)


def test_the_documented_examples_read_as_written():
    assert parse_failure("jam:elevon_l@5") == (EffectorFailure("jam", "elevon_l", {"position": 5.0}),)
    assert parse_failure(" float:motor1 ") == (EffectorFailure("float", "motor1"),)
    # a jam without a value holds where the surface is at the failure: no parameter given
    assert parse_failure("jam:x")[0].params == {}
    two = parse_failure("effectiveness:elevon_l@0.25+limits:lef_l@-10:10")
    assert [(f.kind, f.effector, dict(f.params)) for f in two] == [
        ("effectiveness", "elevon_l", {"fraction": 0.25}), ("limits", "lef_l", {"lo": -10.0, "hi": 10.0})]
    assert format_failure(two) == "effectiveness:elevon_l@0.25+limits:lef_l@-10:10"
    assert parse_failure("bandwidth:pitch_tv@10")[0].params == {"wn": 10.0}
    assert format_failure(EffectorFailure("rate_limits", "x", {"rate_min": -0.2 * 150, "rate_max": 0.2 * 150})) \
        == "rate_limits:x@-30:30"
    assert format_failure(EffectorFailure("jam", "x", {"position": 0.1 + 0.2})) == "jam:x@0.30000000000000004"


def test_the_kinds_are_the_tables():
    assert failure_kinds() == (*FAILURE_KINDS, *(k for k, s in SIMULATOR_ONLY.items() if s.per_actuator))


@pytest.mark.parametrize("seed", range(8))
def test_format_then_parse_is_the_identity(seed):
    rng = np.random.default_rng(seed)
    for _ in range(200):
        spec = _spec(rng)
        text = format_failure(spec)
        back = parse_failure(text, EFFECTORS, limits=[LIMITS] * len(EFFECTORS),
                             rate_limits=[(-RATE, RATE)] * len(EFFECTORS))
        assert back == spec, text
        # bit for bit: the floats a sweep flies are the floats written
        for a, b in zip(back, spec, strict=True):
            assert [np.float64(v).tobytes() for v in a.params.values()] == \
                [np.float64(v).tobytes() for v in b.params.values()]
        assert format_failure(back) == text


def _hostile(rng: np.random.Generator) -> str:
    """Text the grammar must refuse (each draw one way of being wrong)."""
    good_value = f"{rng.uniform(-5, 5):.3f}"

    def pick(options: list[str]) -> str:  # by index: numpy's strings drop a trailing NUL
        return options[int(rng.integers(len(options)))]

    return pick([
        "", "   ", "+", "jam", "jam:", ":elevon_l", "jam:@5", "jam:elevon_l+",
        f"{pick(['jamm', 'JAM', 'loe', 'delay', 'hard over', 'jam1', '☃'])}:elevon_l@{good_value}",
        f"jam:{pick(['elevon', 'ELEVON_L', 'elevon_l ', 'x' * 300, 'de3', 'ℯlevon_l'])}@{good_value}",
        f"jam:elevon_l@{pick(['nan', 'NaN', 'inf', '-inf', 'infinity', '1e999', '-1e400', '0x10'])}",
        # (blanks around the whole text are ignored, inside it they are not)
        f"jam:elevon_l@{pick(['', 'five', '1_000', ' 5', '5 +float:lef_l', '１２', '٣', '1,5', '--1', '1e', '.', '+'])}",
        f"jam:elevon_l@{good_value}:{good_value}", "float:elevon_l@1",
        f"jam:elevon_l@{rng.uniform(31, 1e6):.1f}", f"effectiveness:elevon_l@{rng.uniform(1.01, 9):.2f}",
        "effectiveness:elevon_l", "limits:elevon_l@5:-5", f"rate_limits:elevon_l@{rng.uniform(1, 9):.1f}:5",
        "bandwidth:elevon_l@0", "bandwidth:elevon_l@-3",
        "+".join(["float:elevon_l"] * (MAX_PARTS + 1)), "jam:elevon_l@" + "9" * MAX_TEXT,
        "jam:elevon_l@5\x00", "jam:elevon_l@5+\n", "jam\u200b:elevon_l@5", "jam:elevon_l@5\n+float:lef_l",
    ])


@pytest.mark.parametrize("seed", range(4))
def test_hostile_text_is_refused_naming_the_field(seed):
    rng = np.random.default_rng(1000 + seed)
    for _ in range(300):
        text = _hostile(rng)
        with pytest.raises(alloc.AllocError) as info:
            parse_failure(text, ("elevon_l", "lef_l"), limits=[LIMITS] * 2, rate_limits=[(-RATE, RATE)] * 2)
        exc = info.value
        assert exc.field == "failure" and str(exc).startswith("failure: "), (text, str(exc))
        assert isinstance(exc, ValueError) and len(str(exc)) < 1000, text


@pytest.mark.parametrize("text, says", [
    ("foo:elevon_l", ("unknown kind 'foo'; kinds: jam, hardover, float, effectiveness, limits, rate_limits, "
                      "repair, bandwidth")),
    ("jam:zz@1", "unknown effector 'zz'; effectors: elevon_l, lef_l"),
    ("jam:elevon_l@nan", "position 'nan' is not a finite number"),
    ("jam:elevon_l@40", "outside its nominal limits [-30, 30]"),
    ("jam:elevon_l@1:2", "2 values; jam takes position"),
    ("effectiveness:elevon_l", "fraction is required"),
    ("", f"empty; expected {GRAMMAR}"),
])
def test_a_refusal_names_the_reason_and_what_is_known(text, says):
    with pytest.raises(alloc.ProblemError, match="^failure: ") as info:
        parse_failure(text, ("elevon_l", "lef_l"), limits=[LIMITS] * 2)
    assert says in str(info.value)


def test_non_text_is_refused():
    for value in (None, 5, b"jam:x@1", ["jam:x@1"], {"failure": "jam:x@1"}):
        with pytest.raises(alloc.ProblemError, match="^failure: expected text") as info:
            parse_failure(value)
        assert info.value.field == "failure"


@pytest.mark.parametrize("spec, says", [
    ((), "nothing to write"),
    (EffectorFailure("jam", "a+b", {"position": 1.0}), "cannot be written"),
    (EffectorFailure("jam", "a@b", {}), "cannot be written"),
    (EffectorFailure("jam", "", {}), "cannot be written"),
    (EffectorFailure("limits", "x", {"hi": 1.0}), "are not the first of"),
    (EffectorFailure("jam", "x", {"position": float("nan")}), "not a finite number"),
    (EffectorFailure("warp", "x", {}), "unknown kind"),
])
def test_format_refuses_what_it_cannot_write(spec, says):
    with pytest.raises(alloc.ProblemError, match="^failure: ") as info:
        format_failure(spec)
    assert says in str(info.value) and info.value.field == "failure"
