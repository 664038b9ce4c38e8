"""The generated C is pinned: the same input gives the same source, byte for byte, until
``alloc.export.GENERATOR_VERSION`` changes.

A refactoring of the generator or its templates (alloc/export/templates*.py) must leave these
hashes alone; a change of the generated code on purpose bumps ``GENERATOR_VERSION`` and
records the new hashes here.  The library's version string, which the header names, is
masked so that a release does not move them.  No compiler needed: this hashes text.
"""

from __future__ import annotations

import hashlib
import re

import numpy as np
import pytest

import alloc
import alloc.vehicles
from alloc.export import GENERATOR_VERSION, export_c

#: sha256 (first 16 hex digits) of header + source, literals rounded (see _rounded), per (vehicle, method, precision, table)
GOLDEN = {
    "3": {
        ("ice", "qp", "double", None): "d9090548a4706d0d",
        ("ice", "wls", "float", None): "fb3c90499f64cbdd",
        ("ice", "pinv_scale", "float", None): "5f0843adfa8ee5bc",
        # hexa-x's input changed on 2026-12-05 (up = the hover trim command, 0.503 per rotor, where it
        # was 0): the generator did not, and with up = 0 the former digests (e458750e..., 7ed18a8b...,
        # b2c5a4c8..., ae2d6057..., 594875a7...) are still what it writes
        ("hexa-x", "qp", "double", None): "2ff990d249a40f29",
        ("hexa-x", "dynamic", "float", False): "adf761db8b348344",
        ("hexa-x", "cgi", "double", None): "9b51d4ad625a3df6",
        ("hexa-x", "ganging", "double", None): "4b3b9dd60316e5ee",
        # lp joined generator 3 without changing the other methods' sources
        ("ice", "lp", "double", None): "52c9c4f3f3960e9d",
        ("hexa-x", "lp", "float", None): "16f2bbfed913c025",
    },
    "4": {
        # the warm kernels changed (they enter the final level at level 0's step); the cold ones
        # differ from generator 3's only in the generator number the header names
        ("ice", "qp", "double", None): "876ac44bf4debf06",
        ("ice", "wls", "float", None): "c82613fbf1979abb",
        ("ice", "pinv_scale", "float", None): "a079e3677d0abe00",
        ("hexa-x", "qp", "double", None): "be386b4dbcdf8f0e",
        ("hexa-x", "dynamic", "float", False): "e2fe85229d863a18",
        ("hexa-x", "cgi", "double", None): "1f5eb09beb2388b6",
        ("hexa-x", "ganging", "double", None): "3c1de7e0052e9483",
        ("ice", "lp", "double", None): "08db69db2749d2d0",
        ("hexa-x", "lp", "float", None): "bdd990f819ab00b0",
    },
    "5": {
        # the engine modules moved into alloc/_engine/: the comments that cite them and the generator
        # number changed, nothing else (compared line by line on ice qp and lp, hexa-x cgi and dynamic)
        ('ice', 'qp', 'double', None): "fad56fea4bbe0f41",
        ('ice', 'wls', 'float', None): "7483a88e2bf86076",
        ('ice', 'pinv_scale', 'float', None): "e59c0aa08cbfc1cb",
        ('hexa-x', 'qp', 'double', None): "8c9ba2dacd3bcf5b",
        ('hexa-x', 'dynamic', 'float', False): "e8ebcaf3b0c078b0",
        ('hexa-x', 'cgi', 'double', None): "7f126128a5822947",
        ('hexa-x', 'ganging', 'double', None): "dea8a358b700006d",
        ('ice', 'lp', 'double', None): "1ddc75f93c316b96",
        ('hexa-x', 'lp', 'float', None): "a83238e98392d3c6",
    },
}

#: the same digest of the double kernel exported with ``warm_start=True``, per (vehicle, method)
GOLDEN_WARM = {
    "4": {
        ("ice", "qp"): "023d65cdfbe563cc",
        ("ice", "wls"): "8b5af1a3bb95d994",
        ("hexa-x", "dynamic"): "bf86dfd5c5dfac57",
    },
    "5": {
        ('ice', 'qp'): "3d2df68503183cb2",
        ('ice', 'wls'): "67f6cf48c95bf586",
        ('hexa-x', 'dynamic'): "ac53367dc25bf496",
    },
}


#: a floating literal of the generated source (not part of an identifier)
_LITERAL = re.compile(r"(?<![\w.])-?\d+\.\d*(?:e[-+]?\d+)?")


def _rounded(match: re.Match[str]) -> str:
    # Tables are computed by LAPACK (pinv, factorisations), whose last bits differ between
    # numpy/OpenBLAS builds: a numpy upgrade changed 5 of 7 double-precision digests with an
    # unchanged generator.  Literals are hashed rounded to 1e-9 (absolute, so a computed zero
    # of +-3e-17 hashes as 0.0); the C-versus-Python tests check the values themselves.
    return repr(round(float(match.group()), 9) + 0.0)


def digest(vehicle: str, method: str, precision: str, table: bool | None, problem: alloc.Problem | None = None,
           warm_start: bool = False) -> str:
    problem = alloc.vehicles.problem(vehicle) if problem is None else problem
    kernel = export_c(problem, method, precision=precision, table=table, warm_start=warm_start)
    text = (kernel.header + kernel.source).replace(alloc.__version__, "@VERSION@")
    text = _LITERAL.sub(_rounded, text)
    # the header's fingerprint of the input problem: masked so that the round-off test below
    # can nudge B (it hashes the input, which no library version changes)
    text = re.sub(r"data sha256 [0-9a-f]+", "data sha256 @DATA@", text)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


@pytest.mark.parametrize("case", sorted(GOLDEN[GENERATOR_VERSION], key=str), ids=lambda c: "-".join(map(str, c)))
def test_generated_source_is_pinned_for_this_generator_version(case):
    assert digest(*case) == GOLDEN[GENERATOR_VERSION][case]


@pytest.mark.parametrize("case", sorted(GOLDEN[GENERATOR_VERSION], key=str), ids=lambda c: "-".join(map(str, c)))
def test_the_digest_ignores_round_off_in_the_tables(case):
    """A few ulps in B (what another LAPACK build does to the computed tables) leave the digest."""
    vehicle, method, precision, table = case
    problem = alloc.vehicles.problem(vehicle)
    rng = np.random.default_rng(sum(map(ord, vehicle + method)))
    nudged = problem.replace(B=problem.B * (1.0 + 4e-16 * rng.standard_normal(problem.B.shape)))
    assert not np.array_equal(nudged.B, problem.B)
    assert digest(vehicle, method, precision, table, nudged) == GOLDEN[GENERATOR_VERSION][case]


@pytest.mark.parametrize("case", sorted(GOLDEN_WARM[GENERATOR_VERSION]), ids=lambda c: "-".join(c))
def test_warm_source_is_pinned_for_this_generator_version(case):
    assert digest(*case, "double", None, warm_start=True) == GOLDEN_WARM[GENERATOR_VERSION][case]
