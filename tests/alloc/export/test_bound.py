"""The per-call iteration bound of the active-set and ``lp`` kernels (alloc/export/certify.py):
certified by sampling, stated in the header, enforced by the generated code, and driven to.

One small kernel is compiled per test (the 4 x 6 hexacopter's ``wls``, its factorisations
tabulated, and its ``lp``, whose count is the simplex's pivots), unoptimised, as in
tests/alloc/export/test_export.py.
"""

from __future__ import annotations

import numpy as np
import pytest
from test_export import STATUS, build  # noqa: F401 - build is the compiling fixture

import alloc
import alloc.vehicles
from alloc.export import ExportError, export_c
from alloc.export.certify import SIMPLEX_RANDOM_DEMANDS, analytic_bound, certification_demands
from alloc.testing import random_demands

pytestmark = pytest.mark.usefixtures("build")


def _certified(method: str):
    """The hexacopter's ``method`` kernel with its certified bound, and the library beside it."""
    p = alloc.vehicles.problem("hexa-x")
    kernel = export_c(p, method, iteration_bound="certify", prefix=f"cert_{method}")
    return p, kernel, alloc.make_allocator(p, method)


@pytest.fixture(scope="module", params=["wls", "lp"])
def certified(request):
    return _certified(request.param)


@pytest.fixture(scope="module")
def certified_wls():
    return _certified("wls")


def _safe(allocator, p, v):
    """The library's safe answer with the nominal limits (what it returns at its cap; the kernel's
    transcription of it gives the same bits, a numpy ``c + P @ v`` may differ by an ulp)."""
    return allocator._safe(v, p.umin, p.umax)


def test_the_sampled_bound_is_stated_and_is_the_largest_count_of_the_sample(certified):
    p, kernel, allocator = certified
    cert = kernel.certificate
    parts = certification_demands(p, SIMPLEX_RANDOM_DEMANDS if kernel.method == "lp" else 0)
    assert cert.demands == sum(len(V) for V in parts.values()) > 10_000
    # the bound is the library's count on its worst demand, and no sampled demand part exceeds it
    assert allocator(cert.worst_demand).iterations == cert.bound == kernel.iteration_bound
    assert max(cert.part_max.values()) == cert.bound
    assert f"#define {kernel.prefix.upper()}_ITERATION_BOUND {cert.bound}\n" in kernel.header
    assert "certified BY SAMPLING, not proved" in kernel.header
    if kernel.method == "lp":  # the simplex's pivots, bound flips included; no analytic bound claimed
        assert cert.unit == "pivots" and "No analytic bound" in kernel.header
    else:
        assert cert.unit == "iterations"
        assert f"{analytic_bound(p.m)} iterations" in kernel.header and analytic_bound(6) == 5103


def test_generated_code_reaches_the_bound_and_one_less_gives_the_safe_answer(build, certified):
    p, kernel, allocator = certified
    bound, v = kernel.iteration_bound, kernel.certificate.worst_demand
    r = allocator(v)
    at = build(kernel)
    u, status, it = at(v)
    assert (status, it) == (STATUS[r.status.value], bound)
    np.testing.assert_array_equal(u, r.u)
    short = build(export_c(p, kernel.method, iteration_bound=bound - 1, prefix=f"short_{kernel.method}"))
    u, status, it = short(v)
    assert (status, it) == (2, bound - 1)
    np.testing.assert_array_equal(u, _safe(allocator, p, v))
    # the budget covers the nominal limits only: a rate window as wide as the limits keeps the
    # library's cap per level, and so the library's answer
    u, status, it = short(v, np.asarray(p.up, dtype=float), 1e6)
    assert (status, it) == (STATUS[r.status.value], bound)
    np.testing.assert_array_equal(u, r.u)
    # reduced limits leave the certified class; the nominal ones given back re-enter it
    assert short.set_limits(p.umin, p.umax) == 0
    assert short(v)[1:] == (2, bound - 1)


def test_the_cached_run_time_form_reaches_the_same_bound(build, certified_wls):
    """Factorising at run time with its factorisation cache (table=False), the kernel counts the
    library's iterations too: the worst sampled demand takes exactly the bound, with the cache
    cold and then warm, and one iteration less gives the safe answer."""
    p, kernel, allocator = certified_wls
    bound, v = kernel.iteration_bound, kernel.certificate.worst_demand
    r = allocator(v)
    at = build(export_c(p, "wls", table=False, iteration_bound=bound, prefix="rt_cert_wls"))
    assert "#define TABLE 0\n" in at.kernel.source and "#define CACHE 0\n" not in at.kernel.source
    for _ in range(2):
        u, status, it = at(v)
        assert (status, it) == (STATUS[r.status.value], bound)
        np.testing.assert_array_equal(u, r.u)
    short = build(export_c(p, "wls", table=False, iteration_bound=bound - 1, prefix="rt_short_wls"))
    u, status, it = short(v)
    assert (status, it) == (2, bound - 1)
    np.testing.assert_array_equal(u, _safe(allocator, p, v))


def test_fresh_demands_are_within_the_bound_or_say_so(build, certified):
    """Seeded demands outside the sample (the shared random generator, attainable and not):
    each either is the library's answer within the bound, or needed more and is the safe
    answer with status 2 -- never another answer."""
    p, kernel, allocator = certified
    kern = build(kernel)
    bound = kernel.iteration_bound
    beyond = 0
    for v in random_demands(np.random.default_rng(28), p, 400):
        r = allocator(v)
        u, status, it = kern(v)
        if r.iterations <= bound:
            assert (status, it) == (STATUS[r.status.value], r.iterations)
            np.testing.assert_array_equal(u, r.u)
        else:
            beyond += 1
            assert (status, it) == (2, bound)
            np.testing.assert_array_equal(u, _safe(allocator, p, v))
    assert beyond <= 4  # 1 % of fresh demands; measured: none (wls and lp)


def test_the_default_budget_is_the_library_cap_and_bad_bounds_name_the_field():
    p = alloc.vehicles.problem("hexa-x")
    kernel = export_c(p, "wls")
    assert kernel.iteration_bound == kernel.levels * kernel.maxit and kernel.certificate is None
    assert f"#define ALLOC_WLS_ITERATION_BOUND {kernel.levels * kernel.maxit}\n" in kernel.header
    for bad, kwargs in ((0, {}), (True, {}), (10 ** 9, {}), ("often", {}), ("certify", {"precision": "float"})):
        with pytest.raises(ExportError, match="iteration_bound") as info:
            export_c(p, "wls", iteration_bound=bad, **kwargs)
        assert info.value.field == "iteration_bound"
    with pytest.raises(ExportError, match="iteration_bound: pinv is closed-form"):
        export_c(p, "pinv", iteration_bound=5)


def test_cli_certify_refuses_float_in_one_line(tmp_path):
    from typer.testing import CliRunner

    from alloc.cli import app

    bad = CliRunner().invoke(app, ["export", "--vehicle", "hexa-x", "--method", "wls", "--certify", "--precision",
                                   "float", "--out", str(tmp_path)])
    assert bad.exit_code == 2 and "iteration_bound" in bad.output and len(bad.output.strip().splitlines()) == 1


@pytest.mark.slow
def test_cli_certify_states_the_sampled_bound(tmp_path):
    from typer.testing import CliRunner

    from alloc.cli import app

    out = tmp_path / "kernels"
    result = CliRunner().invoke(app, ["export", "--vehicle", "hexa-x", "--method", "wls", "--certify", "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert "certified BY SAMPLING, not proved" in (out / "alloc_wls.h").read_text()
