"""The C export reads declared capabilities: each method's kind of kernel, registered with the
method, and the kernel's public description (``Allocator.export_data``); the generated C of
every exportable method on every catalogue vehicle is pinned.

The digests are :func:`export_digests.rounded_digest`'s (test_export_golden.py's: literals
rounded to 1e-9, the library's version and the input's fingerprint masked), of the double
kernel with the default settings.
They were recorded when the generator stopped branching on method names; that change was
checked with tests/alloc/export/export_digests.py, which compared 281 exports and refusals
(187 kernels) byte for byte before and after it.
"""

from __future__ import annotations

import numpy as np
import pytest
from export_digests import rounded_digest

import alloc
import alloc.export
import alloc.registry
import alloc.vehicles
from alloc.export import ExportError, export_c
from alloc.export_data import KINDS, ActiveSetData, AffineData, ExportData

#: (vehicle, method) -> digest of the double kernel (defaults), or the field an export refuses
DIGESTS = {
    ('ice', 'pinv'): '65dc85efbaf9ae97',
    ('ice', 'pinv_clip'): '4913d63abd57517f',
    ('ice', 'ganging'): '9f712861da3ced65',
    ('ice', 'pinv_scale'): 'bd8a96e5a1ae703a',
    ('ice', 'cgi'): 'refused: table',
    ('ice', 'wls'): '733ed99a1566e7e4',
    ('ice', 'qp'): 'd9090548a4706d0d',
    ('ice', 'dynamic'): '5f294a03fb32615f',
    ('ice', 'lp'): '52c9c4f3f3960e9d',
    ('ice-design', 'pinv'): '6d92cdd01e7bfe56',
    ('ice-design', 'pinv_clip'): 'c71599ec1600a2ac',
    ('ice-design', 'ganging'): 'aa0918be3389d2a1',
    ('ice-design', 'pinv_scale'): '441f45fc8b28c24b',
    ('ice-design', 'cgi'): 'refused: table',
    ('ice-design', 'wls'): '0be7f2db87c8d165',
    ('ice-design', 'qp'): '7779b5adde5f07ee',
    ('ice-design', 'dynamic'): 'c85be194f0bb5185',
    ('ice-design', 'lp'): '3a2e510bc454f46f',
    ('ice-mid', 'pinv'): '54b923595e6c22ef',
    ('ice-mid', 'pinv_clip'): '3f276f664019b013',
    ('ice-mid', 'ganging'): '547d2db090b8584f',
    ('ice-mid', 'pinv_scale'): '0f180b00212959d9',
    ('ice-mid', 'cgi'): 'refused: table',
    ('ice-mid', 'wls'): 'a911627a14cf0e1b',
    ('ice-mid', 'qp'): 'ef86456951499b71',
    ('ice-mid', 'dynamic'): '3dd26761d39b1895',
    ('ice-mid', 'lp'): '79ed28576f5b7a2a',
    ('harv', 'pinv'): '8ff85145b2974d61',
    ('harv', 'pinv_clip'): 'b00b5bcc8ecd9877',
    ('harv', 'ganging'): '887c35424b016d25',
    ('harv', 'pinv_scale'): '6da84e36dd990f60',
    ('harv', 'cgi'): '0de06b3685e7597d',
    ('harv', 'wls'): 'b4e602bb701783f9',
    ('harv', 'qp'): '5c495095541b6eee',
    ('harv', 'dynamic'): '69a3c05dc98bcea6',
    ('harv', 'lp'): '4a9749364ccd33d7',
    ('hexa-x', 'pinv'): '7fb8eee462870fb7',
    ('hexa-x', 'pinv_clip'): '6b81253e77d2355c',
    ('hexa-x', 'ganging'): '4b3b9dd60316e5ee',
    ('hexa-x', 'pinv_scale'): '554acdd238dd2d35',
    ('hexa-x', 'cgi'): '9b51d4ad625a3df6',
    ('hexa-x', 'wls'): '21b7c9cc48f03190',
    ('hexa-x', 'qp'): '2ff990d249a40f29',
    ('hexa-x', 'dynamic'): 'cfba309fbc080b91',
    ('hexa-x', 'lp'): 'a41fa3b00d5fefec',
    ('tailless', 'pinv'): 'e614bb6ae4999969',
    ('tailless', 'pinv_clip'): '9789e823e97e4cd7',
    ('tailless', 'ganging'): '32171d2ab9c0930b',
    ('tailless', 'pinv_scale'): 'ca43915a4847cdf5',
    ('tailless', 'cgi'): 'b2bcdf5c9e4aa4f4',
    ('tailless', 'wls'): '00dd60e2540f3262',
    ('tailless', 'qp'): '8d95b146670c467f',
    ('tailless', 'dynamic'): '2e596a10ba42a8a3',
    ('tailless', 'lp'): 'f2d5cde5c8eb6328',
    ('x57-dep', 'pinv'): '84057b14fadb76fe',
    ('x57-dep', 'pinv_clip'): '29272b184ab291a6',
    ('x57-dep', 'ganging'): '380ea2e6741f85c0',
    ('x57-dep', 'pinv_scale'): '0ae1c0b8e659230e',
    ('x57-dep', 'cgi'): 'refused: table',
    ('x57-dep', 'wls'): '3f4f9145fa3156de',
    ('x57-dep', 'qp'): '0493220489e05e58',
    ('x57-dep', 'dynamic'): '4cc56253b5775ed0',
    ('x57-dep', 'lp'): '4caf275427a3f403',
}


def test_every_catalogue_vehicle_is_pinned():
    assert {v for v, _ in DIGESTS} == set(alloc.vehicles.names())
    assert {m for _, m in DIGESTS} == set(alloc.export.EXPORTABLE)


@pytest.mark.parametrize("case", sorted(DIGESTS), ids="-".join)
def test_generated_source_of_every_vehicle_and_method(case):
    vehicle, method = case
    try:
        got = rounded_digest(vehicle, method)
    except ExportError as exc:
        got = f"refused: {exc.field}"
    assert got == DIGESTS[case]


def test_exportable_is_the_registry_s_declared_kinds():
    # closed forms first, then the iterative kernels: the order the docs list them
    assert alloc.export.EXPORTABLE == ("pinv", "pinv_clip", "ganging", "pinv_scale", "cgi", "wls", "qp", "dynamic",
                                       "lp")
    assert list(alloc.export.EXPORTABLE) == alloc.registry.exportable()
    for name in alloc.methods():
        kind = alloc.registry.get_method(name).export
        assert (kind is not None) == (name in alloc.export.EXPORTABLE)
        assert kind is None or kind in KINDS
        assert alloc.method_info(name)["export"] == kind


@pytest.mark.parametrize("method", ["pinv", "pinv_clip", "ganging", "pinv_scale", "cgi", "wls", "qp", "dynamic", "lp"])
def test_export_data_is_of_the_declared_kind(method):
    p = alloc.vehicles.problem("hexa-x")
    data = alloc.make_allocator(p, method).export_data()
    assert isinstance(data, ExportData) and data.method == method
    assert data.kernel.kind == alloc.registry.get_method(method).export
    assert isinstance(data.safe, AffineData) and data.safe.P.shape == (p.m, p.k)
    if isinstance(data.kernel, ActiveSetData):
        assert len(data.kernel.states) == (2 if method == "dynamic" else 1)


def test_export_data_is_none_where_there_is_no_kernel():
    p = alloc.vehicles.problem("hexa-x")
    assert alloc.make_allocator(p, "da").export_data() is None  # declares no kind
    assert alloc.make_allocator(p, "qp", backend="daqp").export_data() is None  # a cross-check backend
    assert alloc.make_allocator(p, "lp", backend="highs").export_data() is None


def test_the_affine_kind_prints_the_method_s_map():
    p = alloc.vehicles.problem("harv")
    for method in ("pinv", "ganging"):
        data = alloc.make_allocator(p, method).export_data()
        source = export_c(p, method).source
        assert repr(float(data.kernel.P[0, 0])) in source and repr(float(data.kernel.c[0])) in source


def test_a_registration_names_a_known_kind():
    with pytest.raises(TypeError, match="unknown export kind 'gpu'"):
        alloc.registry.register("toy_unknown_kind", export="gpu")


def test_families_are_declared():
    families = alloc.registry.families()
    assert families["da"] == ["da", "da_bisect", "da_facet", "da_table"]
    assert all(alloc.registry.get_method(m).family == f for f, members in families.items() for m in members)


def test_option_caps_are_on_the_specs():
    opts = alloc.registry.get_method("da_bisect").options
    assert (opts["angles"].call_cap, opts["max_rounds"].call_cap) == (1024, 1000)
    capped = {(n, o) for n in alloc.methods() for o, s in alloc.registry.get_method(n).options.items()
              if s.call_cap is not None}
    assert capped == {("da_bisect", "angles"), ("da_bisect", "max_rounds")}


def test_the_gang_is_a_declared_option():
    assert [n for n in alloc.methods() if alloc.registry.get_method(n).distribution_option] == ["ganging"]
    assert alloc.registry.get_method("ganging").distribution_option in alloc.registry.get_method("ganging").options
    assert np.isfinite(alloc.make_allocator(alloc.vehicles.problem("harv"), "ganging")([0.1, 0.0, 0.0]).u).all()
