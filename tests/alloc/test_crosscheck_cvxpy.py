"""Every optimisation method against its independent cvxpy formulation (the table in
``tests/cvxpy_references.py``: one row per method, its formulation, check and tolerance)."""

from __future__ import annotations

import pytest

import cvxpy_references as refs

pytestmark = pytest.mark.filterwarnings("ignore:Solution may be inaccurate")


@pytest.mark.parametrize("method,options,name,p,v,rated", refs.params())
def test_method_matches_its_cvxpy_reference(method, options, name, p, v, rated):
    refs.REFERENCES[method].check(name, p, v, rated, options)


def test_every_optimisation_method_has_a_row():
    """The methods that solve an optimisation problem by a solver of their own have a reference;
    the closed forms and the searches are checked against these (da_*: test_methods, test_ams)."""
    assert set(refs.REFERENCES) == {"qp", "wls", "lp", "da"}
    for ref in refs.REFERENCES.values():
        assert ref.formulation and ref.tolerance and ref.cases and ref.options
