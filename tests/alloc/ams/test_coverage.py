"""Coverage of the AMS (Bordignon-Durham measure, seed section 1.3.4.9)."""

from __future__ import annotations

import numpy as np
import pytest

import alloc
from alloc.ams import AttainableSet, coverage, sample_ams
from alloc.vehicles import harv_latdir, ice
from alloc.vehicles import ice_mid as ice_mid_up


@pytest.mark.parametrize("method", ["pinv", "pinv_scale", "ganging"])
def test_exact_polytope_coverage_agrees_with_monte_carlo(method):
    p = harv_latdir()
    exact = coverage(p, method)
    assert exact.estimator == "polytope" and exact.stderr == 0.0
    mc = coverage(p, method, samples=20_000, seed=3, exact=False)
    assert mc.estimator == "monte-carlo"
    assert abs(exact.fraction - mc.fraction) < 4 * mc.stderr
    assert 0.5 < exact.fraction < 0.6  # measured 54.6 %


def test_two_dimensional_polytope_coverage():
    rng = np.random.default_rng(2)
    p = alloc.Problem(rng.standard_normal((2, 5)), -np.ones(5), np.ones(5))
    exact = coverage(p, "pinv")
    mc = coverage(p, "pinv", samples=20_000, seed=4, exact=False)
    assert abs(exact.fraction - mc.fraction) < 4 * mc.stderr


def test_direct_allocation_reaches_everything():
    for p in (ice(), harv_latdir()):
        for method in ("da_facet", "da_bisect"):
            r = coverage(p, method, samples=2_000, seed=5)
            assert r.fraction == 1.0


def test_ice_pinv_coverage_depends_on_the_preferred_position():
    # up = 0 parks AMT and SSD at their lower limit: any pseudo-inverse increment that
    # moves one of them negative is inadmissible, and the four such halfspaces leave no volume
    assert coverage(ice(), "pinv").fraction == 0.0
    assert coverage(ice(), "pinv", samples=2_000, seed=6, exact=False).fraction == 0.0
    mid = coverage(ice_mid_up(), "pinv")
    assert 0.13 < mid.fraction < 0.42  # the seed's range for pseudo-inverse variants; measured 16.4 %


def test_samples_are_uniform_in_the_ams():
    p = harv_latdir()
    ams = AttainableSet(p)
    V = sample_ams(ams, 20_000, np.random.default_rng(7))
    assert ams.contains(V).all()
    # the AMS is centrally symmetric about B (lo+hi)/2: the sample mean sits at the centre
    centre = p.B @ ((p.umin + p.umax) / 2)
    se = V.std(axis=0) / np.sqrt(len(V))
    assert (np.abs(V.mean(axis=0) - centre) < 4 * se).all()


def test_cli_summary_plot_and_coverage(tmp_path):
    import json

    from typer.testing import CliRunner

    from alloc.ams.cli import app

    runner = CliRunner()
    res = runner.invoke(app, ["summary", "--vehicle", "ice", "--json"])
    assert res.exit_code == 0, res.output
    s = json.loads(res.output)
    assert s["facets"] == 78 and s["vertices"] == 86
    out = tmp_path / "ams.png"
    res = runner.invoke(app, ["plot", "--vehicle", "harv", "--method", "cgi", "--samples", "500", "--out", str(out)])
    assert res.exit_code == 0, res.output
    assert out.stat().st_size > 10_000
    res = runner.invoke(app, ["coverage", "--vehicle", "harv", "--method", "pinv", "--json"])
    assert res.exit_code == 0, res.output
    assert json.loads(res.output)[0]["fraction"] == pytest.approx(0.5458, abs=1e-3)


def test_two_dimensional_picture(tmp_path):
    from alloc.ams.plot import plot_ams

    p = alloc.Problem(np.random.default_rng(1).standard_normal((2, 4)), -np.ones(4), np.ones(4))
    fig = plot_ams(p, "pinv", tmp_path / "k2.png")
    assert (tmp_path / "k2.png").exists() and len(fig.axes) == 1


def test_wilson_interval_when_nothing_fails():
    from alloc.ams.coverage import wilson95

    lo, hi = wilson95(1.0, 20_000)
    assert hi == pytest.approx(1.0) and 0.9997 < lo < 0.99985  # about 1 - 3.84/N
    lo, hi = wilson95(0.5, 10_000)
    assert lo == pytest.approx(0.5 - 1.96 * 0.005, abs=1e-4) and hi == pytest.approx(0.5 + 1.96 * 0.005, abs=1e-4)
