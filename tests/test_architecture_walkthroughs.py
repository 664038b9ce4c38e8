"""docs/ARCHITECTURE.md checked against the code: every failure kind defined once and applied, and the
page names the tests that perform its walk-throughs (tests/walkthroughs/: add a method, a failure
kind, a vehicle)."""

from __future__ import annotations

import pytest

import alloc
from alloc import health, vehicles

ROOT_DOC = "docs/ARCHITECTURE.md"


@pytest.mark.parametrize("kind", list(health.FailureKind), ids=lambda k: k.value)
def test_every_failure_kind_is_defined_once_and_applied(kind):
    """Each row of the table (alloc.health.FAILURE_KINDS) is documented and its example event told.

    Adding a kind end to end (simulator, service, sweep) is tests/walkthroughs/test_add_failure_kind.py.
    """
    assert f"``{kind.value}``" in health.__doc__, f"document what {kind.value!r} means in alloc/health.py"
    nominal = vehicles.problem("ice")
    event = health.FailureEvent("elevon_l", kind, **kind.spec.example)
    start = {"elevon_l": health.EffectorHealth(effectiveness=0.8)}
    name, after = health.apply_event(nominal, start, event)
    assert name == "elevon_l"
    if kind is health.FailureKind.REPAIR:
        assert after == {}
        return
    assert after["elevon_l"] != start["elevon_l"], f"{kind.value!r} changed nothing: check its told rules"
    told = nominal.with_health(after)
    assert told is not nominal and told.m == nominal.m
    # what the allocator is told is admissible and allocates
    r = alloc.allocate(told, [1.0, 5.0, 0.1], "qp")
    assert (r.u >= told.umin - 1e-9).all() and (r.u <= told.umax + 1e-9).all()
    roundtrip = health.health_from_dict(health.health_to_dict(after))
    assert roundtrip == after


def test_architecture_doc_names_the_tests_that_exercise_it():
    from pathlib import Path

    text = (Path(__file__).resolve().parents[1] / ROOT_DOC).read_text()
    for name in ("tests/walkthroughs/test_add_a_method.py", "tests/walkthroughs/test_add_an_exportable_method.py",
                 "tests/test_private_access.py", "test_every_failure_kind_is_defined_once_and_applied",
                 "test_layering.py", "tests/walkthroughs/test_add_failure_kind.py",
                 "tests/walkthroughs/test_add_a_vehicle.py", "tests/walkthroughs/test_add_a_plant.py"):
        assert name in text
