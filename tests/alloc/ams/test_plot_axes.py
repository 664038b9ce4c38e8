"""Pictures of vehicles with more than three axes: exact slices and projections (issue 42)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import linprog
from typer.testing import CliRunner

import alloc
from alloc.ams.cli import app
from alloc.ams.geometry import AttainableSet
from alloc.ams.plot import plot_ams
from alloc.exceptions import AllocError

pytest.importorskip("matplotlib")


def _attainable(problem: alloc.Problem, v: np.ndarray) -> bool:
    """Independent of the zonotope code: is ``B u = v`` feasible in the box (an LP)?"""
    res = linprog(np.zeros(problem.m), A_eq=problem.B, b_eq=v, bounds=list(zip(problem.umin, problem.umax)),
                  method="highs")
    return res.status == 0


def _random_problem(rng: np.random.Generator, k: int, m: int) -> alloc.Problem:
    B = rng.normal(size=(k, m))
    lo = -rng.uniform(0.2, 1.0, m)
    return alloc.Problem(B, lo, rng.uniform(0.2, 1.0, m), axes=[f"a{i}" for i in range(k)])


@pytest.mark.parametrize("seed", range(4))
def test_slice_corners_are_attainable_and_the_slice_is_tight(seed: int) -> None:
    rng = np.random.default_rng(seed)
    k = int(rng.integers(4, 6))
    p = _random_problem(rng, k, k + int(rng.integers(1, 4)))
    drawn = list(p.axes[:3])
    v_fixed = 0.3 * AttainableSet(p).vertices[int(rng.integers(len(AttainableSet(p).vertices)))][3:]
    fig = plot_ams(p, "qp", None, axes=drawn, at=dict(zip(p.axes[3:], v_fixed)), samples=200, seed=seed)
    assert "slice at" in fig.axes[0].get_title()
    from alloc.ams.plot import _slice_view

    view = _slice_view(p, [0, 1, 2], dict(zip(p.axes[3:], v_fixed)), None, 0, 0, {})
    centre = view.vertices.mean(axis=0)
    for corner in view.vertices:
        assert _attainable(p, np.r_[corner, v_fixed])
        # a step beyond a corner, away from the slice's centre, leaves the AMS: the slice is not too small
        beyond = corner + 0.02 * (corner - centre)
        assert not _attainable(p, np.r_[beyond, v_fixed])


def test_projection_holds_every_attainable_demand_and_its_corners_are_reached() -> None:
    rng = np.random.default_rng(7)
    p = _random_problem(rng, 4, 7)
    fig = plot_ams(p, "pinv", None, axes=["a0", "a2"], samples=300)
    assert "projection onto a0, a2" in fig.axes[0].get_title()
    sub = AttainableSet(alloc.Problem(p.B[[0, 2]], p.umin, p.umax))
    U = rng.uniform(p.umin, p.umax, size=(500, p.m))
    assert sub.contains((U @ p.B.T)[:, [0, 2]], tol=1e-9).all()
    for corner in sub.vertices:  # each corner is some u's image: feasible with the other rows free
        res = linprog(np.zeros(p.m), A_eq=p.B[[0, 2]], b_eq=corner, bounds=list(zip(p.umin, p.umax)),
                      method="highs")
        assert res.status == 0


def test_hexa_hover_slice_and_refusals() -> None:
    hexa = alloc.load_vehicle("hexa-x").problem()
    fig = plot_ams(hexa, "da", None, axes=["roll", "pitch", "yaw"], at={"thrust": -19.6}, samples=200)
    assert fig.axes[0].get_title().startswith("slice at thrust = -19.6")
    for kwargs, field in [({}, "axes"), ({"axes": ["roll", "nope"]}, "axes"), ({"axes": ["roll", "roll"]}, "axes"),
                          ({"axes": ["roll", "pitch"], "at": {"thrust": -19.6}}, "at"),
                          ({"axes": ["roll", "pitch", "yaw"], "at": {"thrust": -100.0}}, "at")]:
        with pytest.raises(AllocError) as info:
            plot_ams(hexa, None, None, **kwargs)
        assert info.value.field == field


def test_cli_draws_a_four_axis_vehicle(tmp_path) -> None:
    runner = CliRunner()
    out = tmp_path / "hexa.png"
    res = runner.invoke(app, ["plot", "--vehicle", "hexa-x", "--axes", "roll,pitch,yaw", "--samples", "200",
                              "--out", str(out)])
    assert res.exit_code == 0, res.output
    assert out.stat().st_size > 10_000
    res = runner.invoke(app, ["plot", "--vehicle", "hexa-x", "--axes", "roll,pitch,yaw", "--at", "thrust=-19.6",
                              "--samples", "200", "--out", str(tmp_path / "slice.png")])
    assert res.exit_code == 0, res.output
    res = runner.invoke(app, ["plot", "--vehicle", "hexa-x", "--out", str(tmp_path / "no.png")])
    assert res.exit_code == 2 and "axes" in res.output
