"""``cgi`` with priority levels exported to C (alloc/export/templates_cascade.py) against the
library's cascade by level, compiled and called through ctypes as in test_export.py.

The generator of prioritised problems draws from every kind of :mod:`alloc.testing` (2-5 axes x
2-5 effectors) with 2 or 3 priority levels per problem,
and the hostile in-domain problems of tests/hostile.py with drawn levels; each is checked on
random demands and on a rate-limited trajectory (Eq 1.28).
"""

from __future__ import annotations

import numpy as np
import pytest
from test_export import (FLOAT_U_TOL, _agree_double, _float_limits, _float_rate_trajectory, _hostile_cases,  # noqa: F401
                         build)

import alloc
import alloc.vehicles
from alloc.export import ExportError, export_c
from alloc.testing import KINDS, random_demands, random_problem

pytestmark = pytest.mark.usefixtures("build")


def _levels(rng, k: int) -> list[int]:
    """Priority levels for k >= 2 axes: 2 or 3 distinct."""
    while True:
        levels = [int(x) for x in rng.integers(1, 4, size=k)]
        if len(set(levels)) > 1:
            return levels


def _prioritised(seed: int, max_m: int = 5):
    """The generator of prioritised problems: every kind of the shared suite, 2-5 axes x 2 to
    ``max_m`` effectors (the generator computes 2^m pseudo-inverses a level), with drawn levels."""
    rng = np.random.default_rng(seed)
    for kind in KINDS:
        p = random_problem(rng, int(rng.integers(2, 6)), int(rng.integers(2, max_m + 1)), kind)
        yield p, rng, {"priorities": _levels(rng, p.k)}


def test_double_cgi_by_level_is_the_library_bit_for_bit(build):
    calls = 0
    for i, (p, rng, opts) in enumerate(_prioritised(400)):
        kern = build(export_c(p, "cgi", options=opts, prefix=f"cl{i}"))
        assert f"#define NL {len(set(opts['priorities']))}\n" in kern.kernel.source
        calls += _agree_double(kern, alloc.make_allocator(p, "cgi", **opts), random_demands(rng, p, 40),
                               rate_steps=20, rng=rng)
    assert calls == len(KINDS) * 60


def test_double_cgi_by_level_on_hostile_problems(build):
    checked = 0
    for seed, p, V in _hostile_cases(60, 2000):
        if p.m > 6 or p.k < 2:  # 2^m pseudo-inverses a level to compute
            continue
        if checked == 3:
            break
        opts = {"priorities": _levels(np.random.default_rng(seed), p.k)}
        kern = build(export_c(p, "cgi", options=opts, prefix=f"clh{seed}"))
        try:
            _agree_double(kern, alloc.make_allocator(p, "cgi", **opts), V, rate_steps=10,
                          rng=np.random.default_rng(seed))
        except AssertionError as exc:  # name the case: reproducible from its seed
            raise AssertionError(f"hostile seed {seed}, priorities {opts['priorities']}: {exc}") from None
        checked += 1
    assert checked == 3


def test_the_vehicle_cgi_priorities_are_exported(build):
    """hexa-x gives cgi its priority levels: the kernel carries them as constants."""
    p = alloc.vehicles.problem("hexa-x")
    opts = alloc.vehicles.method_options("hexa-x", "cgi")
    kern = build(export_c("hexa-x", "cgi", prefix="hexa_cgi_levels"))
    assert len(set(opts["priorities"])) == 3 and "#define NL 3" in kern.kernel.source
    rng = np.random.default_rng(9)
    _agree_double(kern, alloc.make_allocator(p, "cgi", **opts), random_demands(rng, p, 200), rate_steps=100,
                  dt=5e-4, rng=rng)


def test_float_cgi_by_level_agrees_and_is_within_its_bounds(build):
    """float: within FLOAT_U_TOL of the library's command (relative to the limit span) on
    every call of the suite, and within the kernel's own bounds exactly."""
    du = []
    for i, (p, rng, opts) in enumerate(_prioritised(500, max_m=4)):
        kern = build(export_c(p, "cgi", precision="float", options=opts, prefix=f"clf{i}"))
        allocator = alloc.make_allocator(p, "cgi", **opts)
        lo32, hi32 = _float_limits(kern)
        span = max(1.0, float(np.max(p.umax - p.umin)))
        for v in random_demands(rng, p, 25):
            u, status, _ = kern(v)
            assert np.isfinite(u).all() and (u >= lo32).all() and (u <= hi32).all()
            du.append(float(np.abs(u - allocator(v).u).max()) / span)
        _float_rate_trajectory(kern, p, rng, 10)
    assert len(du) == 25 * len(KINDS) and max(du) <= FLOAT_U_TOL, np.sort(du)[-10:]


def test_cgi_by_level_table_budget_names_the_field():
    p = alloc.vehicles.problem("ice")
    with pytest.raises(ExportError, match="table: cgi needs"):
        export_c(p, "cgi", options={"priorities": [2, 1, 1]})
    with pytest.raises(ExportError, match="table: cgi has no run-time form"):
        export_c("hexa-x", "cgi", table=False)
