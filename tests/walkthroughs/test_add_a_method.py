"""docs/ARCHITECTURE.md "Add a method", performed: a toy method registered with its equation,
summary, typed options and capabilities, then used through every path a user has (single call,
rate-limited call, the registry's option checks, the safe answer on a backend failure, the
coverage tools), and removed again."""

from __future__ import annotations

import numpy as np
import pytest

import alloc
from alloc import method
from alloc.ams import coverage
from alloc.options import real
from alloc.registry import Method, register


@pytest.fixture
def scratch_registry(monkeypatch):
    """Registrations made in a test disappear after it (built-ins registered first)."""
    alloc.methods()
    monkeypatch.setattr(method, "_REGISTRY", dict(method._REGISTRY))


def _toy_method():
    # steps 1-2 of "Add a method": a class with equation, summary, a typed option spec,
    # a constructor that precomputes, solve(), and one decorator.
    @register("toy_lstsq", affine=True, supports_batch=False)
    class LeastSquares(Method):
        """Unweighted least squares about 0, scaled by ``gain``: ``u = gain * pinv(B) v``."""

        equation = "Eq 1.23 with Wu = I, up = 0"
        summary = "toy: unweighted pseudo-inverse times a gain"
        options = {"gain": real(1.0, "scale of the command", low=0.0, high=1.0)}

        def __init__(self, problem: alloc.Problem, *, gain: float = 1.0) -> None:
            super().__init__(problem)
            self.P = gain * np.linalg.pinv(problem.B)
            self.fused = (np.zeros(problem.m), self.P)  # affine: one compiled call

        def solve(self, v, lo, hi, u_prev):
            if not np.isfinite(v).all() or np.abs(v).max() > 1e6:
                raise alloc.SolverError("toy: demand too large")
            return self.P @ v, 0

    return LeastSquares


def test_add_a_method(scratch_registry):
    cls = _toy_method()
    assert "toy_lstsq" in alloc.methods()
    info = alloc.method_info("toy_lstsq")
    assert info["capabilities"]["affine"] and info["option_specs"]["gain"]["default"] == 1.0

    p = alloc.Problem([[1.0, 1.0, 0.0], [0.0, 1.0, 1.0]], [-1, -1, -1], [1, 1, 1])
    allocate = alloc.make_allocator(p, "toy_lstsq")
    r = allocate(np.array([0.6, 0.3]))  # fused path
    np.testing.assert_allclose(r.u, np.linalg.pinv(p.B) @ [0.6, 0.3], atol=1e-12)
    assert r.status is alloc.Status.EXACT
    r = allocate([0.6, 0.3], u_prev=np.zeros(3), dt=0.01)  # rate limits: solve() + allocator clip
    assert r.status is alloc.Status.EXACT
    r = allocate([5.0, -5.0])
    assert r.status is alloc.Status.UNATTAINABLE and (np.abs(r.u) <= 1).all()
    half = alloc.allocate(p, [0.6, 0.3], "toy_lstsq", gain=0.5)
    np.testing.assert_allclose(half.u, 0.5 * np.linalg.pinv(p.B) @ [0.6, 0.3], atol=1e-12)

    # the registry validates the option once and names it
    with pytest.raises(alloc.OptionError, match=r"gain: must be in \[0, 1\], got 2"):
        alloc.make_allocator(p, "toy_lstsq", gain=2)
    with pytest.raises(TypeError, match="accepted: gain"):
        alloc.make_allocator(p, "toy_lstsq", gane=0.5)

    # a backend failure gives the documented safe answer, flagged
    wide = alloc.Problem([[1.0, 1.0, 0.0], [0.0, 1.0, 1.0]], [-1e7] * 3, [1e7] * 3)
    r = alloc.make_allocator(wide, "toy_lstsq")([2e6, 0.0], u_prev=np.zeros(3), dt=1.0)
    assert r.status is alloc.Status.FALLBACK and "too large" in r.message

    # the coverage tools read the declared capability: exact polytope, no class check
    cov = coverage(p, "toy_lstsq")
    assert cov.estimator == "polytope" and 0.0 < cov.fraction <= 1.0
    assert cls.name == "toy_lstsq"


def test_the_walkthrough_registry_is_restored():
    assert "toy_lstsq" not in alloc.methods()


def test_add_a_method_with_its_cvxpy_row(scratch_registry, monkeypatch):
    """Step 3 of "Add a method": one row of tests/cvxpy_references.py (its formulation written
    out in cvxpy, a check, a tolerance), run by the same parametrisation as the built-ins."""
    import cvxpy as cp
    import cvxpy_references as refs

    _toy_method()

    def check_toy(name, p, v, rated, options):
        u = cp.Variable(p.m)
        cp.Problem(cp.Minimize(cp.sum_squares(u)), [p.B @ u == options["gain"] * v]).solve(**refs.SOLVER)
        r = alloc.allocate(p, v, "toy_lstsq", **options)
        np.testing.assert_allclose(r.u, np.clip(u.value, p.umin, p.umax), atol=1e-8, rtol=0)

    rng = np.random.default_rng(7)
    cases = [(f"toy-{i}", alloc.Problem(rng.normal(size=(2, 4)), [-1] * 4, [1] * 4), rng.normal(size=2) * 0.3, False)
             for i in range(6)]
    row = refs.Reference("min |u|^2 s.t. B u = gain v (Eq 1.23 with Wu = I, up = 0)", check_toy, "u 1e-8",
                         cases, options=({"gain": 1.0}, {"gain": 0.5}))
    monkeypatch.setitem(refs.REFERENCES, "toy_lstsq", row)
    params = refs.params({"toy_lstsq": row})
    assert len(params) == 12
    for param in params:
        method, options, name, p, v, rated = param.values
        refs.REFERENCES[method].check(name, p, v, rated, options)
