"""The generated C is pinned: the same input gives the same source, byte for byte, until
``alloc.export.GENERATOR_VERSION`` changes.

A refactoring of the generator or its templates (alloc/export/templates*.py) must leave these
hashes alone; a change of the generated code on purpose bumps ``GENERATOR_VERSION`` and
records the new hashes here.  The library's version string, which the header names, is
masked so that a release does not move them.  No compiler needed: this hashes text.
"""

from __future__ import annotations

import hashlib

import pytest

import alloc
import alloc.vehicles
from alloc.export import GENERATOR_VERSION, export_c

#: sha256 (first 16 hex digits) of header + source, per (vehicle, method, precision, table)
GOLDEN = {
    "3": {
        ("ice", "qp", "double", None): "ea8f35609dc1737c",
        ("ice", "wls", "float", None): "b445a8d34f4d10c7",
        ("ice", "pinv_scale", "float", None): "becd21469df98cd2",
        ("hexa-x", "qp", "double", None): "802ab33b73bccce1",
        ("hexa-x", "dynamic", "float", False): "6908ae344c95986f",
        ("hexa-x", "cgi", "double", None): "a07ab16c8231bb4b",
        ("hexa-x", "ganging", "double", None): "a9f234c81bd3bfaf",
    },
}


def digest(vehicle: str, method: str, precision: str, table: bool | None) -> str:
    kernel = export_c(alloc.vehicles.problem(vehicle), method, precision=precision, table=table)
    text = (kernel.header + kernel.source).replace(alloc.__version__, "@VERSION@")
    return hashlib.sha256(text.encode()).hexdigest()[:16]


@pytest.mark.parametrize("case", sorted(GOLDEN[GENERATOR_VERSION], key=str), ids=lambda c: "-".join(map(str, c)))
def test_generated_source_is_pinned_for_this_generator_version(case):
    assert digest(*case) == GOLDEN[GENERATOR_VERSION][case]
