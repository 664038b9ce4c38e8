"""The standing adversarial suite (issue 9): seeded hostile problems against the contract.

The generator, the contract check, the watchdog subprocesses and the shrinker live in
``tests/hostile.py`` (its generator in ``tests/hostile_cases.py``, the contract check in
``tests/hostile_checks.py``).  The default run covers ``DEFAULT_CASES`` seeds; the slow run
(``pytest -m slow``) covers ``SLOW_CASES``, and its result is recorded in the README
("Adversarial suite").  A failure prints the shrunk minimal case, reproducible with
``hostile.check(case)`` or from its seed with ``hostile.case(seed)``.
"""

from __future__ import annotations

import json
import os
from collections import Counter

import pytest

import hostile
import hostile_checks

DEFAULT_CASES = int(os.environ.get("ALLOC_HOSTILE_CASES", "1500"))
SLOW_CASES = 100_000
WORKERS = 2

#: Open item owned by alloc/solvers.py (not this suite's files), listed so it stays
#: visible: qpsolvers' first-order backends (SCS, OSQP, Clarabel) run without a time limit
#: and take seconds, SCS sometimes more than the watchdog's budget, on badly scaled QPs
#: (B ~ 1e47).  Only a slow call or a time-out with one of these *explicitly chosen*
#: backends is tolerated; every other failure, and any slow call on a default backend,
#: fails the test.
SLOW_THIRD_PARTY = ("scs", "osqp", "clarabel")


def _tolerated(f: dict) -> bool:
    backend = f["minimal"]["options"].get("backend") if isinstance(f["minimal"]["options"], dict) else None
    return backend in SLOW_THIRD_PARTY and all(s.startswith(("slow call", "hang")) for s in f["fail"])


def _assert_contract(report: dict) -> None:
    hard = [f for f in report["fail"] if not _tolerated(f)]
    soft = [f for f in report["fail"] if _tolerated(f)]
    if soft:
        print(f"{len(soft)} slow calls on third-party first-order backends (see SLOW_THIRD_PARTY)")
    assert not hard, "contract violations (shrunk):\n" + "\n".join(
        json.dumps(f, default=str)[:3000] for f in hard[:5])


def test_generator_is_reproducible():
    assert hostile.case(123) == hostile.case(123)
    assert hostile.case(123) != hostile.case(124)


def test_contract_check_catches_a_planted_violation(monkeypatch):
    """The checker can fail: a method returning a NaN-moment 'exact' would be caught."""
    import numpy as np

    import alloc
    from alloc.result import Result, Status

    c = {"seed": -1, "method": "pinv", "options": {},
         "fields": {"B": [[1.0, 1.0]], "umin": [-1, -1], "umax": [1, 1]}, "calls": [{"v": [5.0]}]}
    hostile.check(c)  # loads the compiled kernels (a first call in a process may be slow)
    assert hostile.check(c)["fail"] == []

    def lying(self, v, *, u_prev=None, dt=None):
        u = np.zeros(2)
        u.setflags(write=False)
        vv = np.array(v, dtype=float)
        vv.setflags(write=False)
        return Result(u, vv, u[:1], Status.EXACT, "pinv")

    monkeypatch.setattr(alloc.Allocator, "__call__", lying)
    assert any("dishonest exact" in s for s in hostile.check(c)["fail"])


def test_slow_call_rule_counts_cpu_not_waiting(monkeypatch):
    """A call is slow by the CPU seconds it costs (the registry's unit), not by wall time:
    a call that waits 0.3 s passes a 0.1 CPU-second limit, one that computes 0.3 s fails it,
    and a wait beyond the wall-clock backstop fails as well."""
    import time

    import alloc

    c = {"seed": -1, "method": "pinv", "options": {},
         "fields": {"B": [[1.0, 1.0]], "umin": [-1, -1], "umax": [1, 1]}, "calls": [{"v": [0.5]}]}
    hostile.check(c)
    real = alloc.Allocator.__call__
    monkeypatch.setattr(hostile_checks, "CALL_LIMIT", 0.1)

    def waiting(self, v, **kw):
        time.sleep(0.3)
        return real(self, v, **kw)

    def computing(self, v, **kw):
        t0 = time.thread_time()
        while time.thread_time() - t0 < 0.3:
            pass
        return real(self, v, **kw)

    monkeypatch.setattr(alloc.Allocator, "__call__", waiting)
    assert hostile.check(c)["fail"] == []
    monkeypatch.setattr(hostile_checks, "CALL_WALL_LIMIT", 0.2)
    assert any(s.startswith("slow call") for s in hostile.check(c)["fail"])
    monkeypatch.setattr(hostile_checks, "CALL_WALL_LIMIT", 20.0)
    monkeypatch.setattr(alloc.Allocator, "__call__", computing)
    fails = hostile.check(c)["fail"]
    assert len(fails) == 1 and fails[0].startswith("slow call: 0.3")


def test_issue_22_classes_are_drawn_without_changing_the_earlier_classes():
    cases = [hostile.case(s) for s in range(2000)]
    counts = Counter(k for c in cases for k in hostile.case_classes(c))
    for name in ("non-real problem", "non-real option", "non-real call", "health API", "round trip"):
        assert counts[name] >= 40, (name, counts)
    assert 150 <= counts["health API"] <= 250 and 150 <= counts["round trip"] <= 250  # 10 % each
    kinds = Counter(c["hostile"]["kind"] for c in cases if "hostile" in c)
    assert set(kinds) == set(hostile.NON_REAL), kinds
    # a case without those classes is the earlier generator's case, draw for draw
    plain = next(c for c in cases if not hostile.case_classes(c))
    assert set(plain) == {"seed", "method", "fields", "options", "calls"}


_COMPLEX_B = {"seed": -1, "method": "pinv", "options": {}, "calls": [{"v": [0.5]}],
              "fields": {"B": {"$array": "complex128", "data": [[1.0, 1.0]]}, "umin": [-1.0, -1.0], "umax": [1.0, 1.0]},
              "hostile": {"where": "problem", "field": "B", "kind": "complex array"}}


def test_contract_check_catches_an_accepted_complex_value(monkeypatch):
    import warnings

    import alloc.domain

    assert hostile.check(_COMPLEX_B)["fail"] == [] and hostile.check(_COMPLEX_B)["refused"] == "problem"
    monkeypatch.setattr(alloc.domain, "_not_real", lambda value: None)  # the old boundary
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # numpy's ComplexWarning as it drops the imaginary part
        assert hostile.check(_COMPLEX_B)["fail"] == ["accepted a complex array value in B"]
    call = {**_COMPLEX_B, "fields": {**_COMPLEX_B["fields"], "B": [[1.0, 1.0]]},
            "calls": [{"v": {"$array": "complex128", "data": [0.5]}, "hostile": "v"}],
            "hostile": {"where": "call", "field": "v"}}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert any(f.startswith("accepted a non-real value in v") for f in hostile.check(call)["fail"])


def test_contract_check_catches_health_abuse_accepted(monkeypatch):
    import alloc.health

    c = {"seed": -1, "method": "pinv", "options": {}, "calls": [{"v": [0.5]}],
         "fields": {"B": [[1.0, 1.0]], "umin": [-1.0, -1.0], "umax": [1.0, 1.0]},
         "health": {"events": [], "record_effector": 0,
                    "record": {"floating": "false", "limits": [-5.0, 5.0], "effectiveness": 0.5}}}
    assert hostile.check(c)["fail"] == []
    monkeypatch.setattr(alloc.health.EffectorHealth, "__post_init__", lambda self: None)  # no checks
    fails = hostile.check(c)["fail"]
    assert "health record accepted floating = 'false'" in fails
    assert "health from_dict accepted floating = 'false'" in fails


def test_contract_check_catches_a_writeable_result_after_a_round_trip(monkeypatch):
    from alloc.result import Result

    c = {"seed": -1, "method": "qp", "options": {}, "calls": [{"v": [0.5]}, {"v": [3.0]}], "round_trip": "pickle",
         "fields": {"B": [[1.0, 1.0]], "umin": [-1.0, -1.0], "umax": [1.0, 1.0]}}
    assert hostile.check(c)["fail"] == []
    monkeypatch.setattr(Result, "__reduce__", lambda self: (tuple.__new__, (Result, tuple(self))))
    assert hostile.check(c)["fail"] == ["round trip (pickle): result array writeable"] * 2


def test_shrinker_reduces_a_failing_case(monkeypatch):
    import numpy as np

    c = next(c for c in map(hostile.case, range(200))
             if c["method"] == "pinv" and np.array(c["fields"]["B"], dtype=object).ndim == 2
             and len(c["fields"]["B"][0]) >= 4 and len(c["calls"]) >= 2)

    def fake_check(case):  # a synthetic failure: any B with more than two columns "fails"
        wide = len(case["fields"]["B"][0]) > 2
        return {"fail": ["wide: B"] if wide else [], "status": {}, "refused": ""}

    monkeypatch.setattr(hostile, "check", fake_check)
    small = hostile.shrink(c, ["wide: B"])
    assert len(small["fields"]["B"][0]) == 3  # the smallest B that still fails
    assert len(small["calls"]) == 1


def test_adversarial_default_run():
    report = hostile.run(range(DEFAULT_CASES), workers=WORKERS)
    assert report["cases"] == DEFAULT_CASES
    _assert_contract(report)
    # the run must exercise the methods, not only their input checks
    for name, counts in report["by_method"].items():
        assert sum(counts.values()) > 0, name


@pytest.mark.slow
def test_adversarial_large_run():
    report = hostile.run(range(10_000_000, 10_000_000 + SLOW_CASES), workers=WORKERS)
    assert report["cases"] == SLOW_CASES
    _assert_contract(report)
