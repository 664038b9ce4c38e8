"""The C export reads declared capabilities: each method's kind of kernel, registered with the
method, and the kernel's public description (``Allocator.export_data``); the generated C of
every exportable method on every catalogue vehicle is pinned.

The digests are :func:`export_digests.rounded_digest`'s (test_golden.py's: literals
rounded to 1e-9, the library's version and the input's fingerprint masked), of the double
kernel with the default settings.
They were recorded when the generator stopped branching on method names; that change was
checked with tests/alloc/export/export_digests.py, which compared 281 exports and refusals
(187 kernels) byte for byte before and after it.  Re-recorded for generator 4 (the warm kernel's
entry at the step, alloc/export/templates_active_set.py): these default kernels changed only in
the generator number their header names (checked by hashing them with the number set back to 3).
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
    ('ice', 'pinv'): '0b8bb346a3eaee87',
    ('ice', 'pinv_clip'): '5fe87fd5bf98a080',
    ('ice', 'ganging'): '77647228c68f4dc8',
    ('ice', 'pinv_scale'): 'dd854e03c25bcf95',
    ('ice', 'cgi'): 'refused: table',
    ('ice', 'wls'): '881d7ba1bf794513',
    ('ice', 'qp'): '876ac44bf4debf06',
    ('ice', 'dynamic'): 'c4ce3a5e60a880c7',
    ('ice', 'lp'): '08db69db2749d2d0',
    ('ice-design', 'pinv'): '9d2b58b79db839ea',
    ('ice-design', 'pinv_clip'): '8b346722b93b7031',
    ('ice-design', 'ganging'): '1f95f5838fdfa11e',
    ('ice-design', 'pinv_scale'): '3dd4bc42d6c92957',
    ('ice-design', 'cgi'): 'refused: table',
    ('ice-design', 'wls'): '8863696b6b734bf8',
    ('ice-design', 'qp'): '00e86939c7c1fe2f',
    ('ice-design', 'dynamic'): '5838c1cd64b26ccd',
    ('ice-design', 'lp'): '8bee31a3357c6937',
    ('ice-mid', 'pinv'): '47db3b7863499010',
    ('ice-mid', 'pinv_clip'): '6e2bafc89c8b5868',
    ('ice-mid', 'ganging'): '35e775e25e4e610c',
    ('ice-mid', 'pinv_scale'): '2ccd3cd4e256b721',
    ('ice-mid', 'cgi'): 'refused: table',
    ('ice-mid', 'wls'): '67e48ad16a2c25b1',
    ('ice-mid', 'qp'): '803973fa6f9886fc',
    ('ice-mid', 'dynamic'): '85907dc16ceb5597',
    ('ice-mid', 'lp'): '8d7513585d2df852',
    ('harv', 'pinv'): '16c66c1857e81349',
    ('harv', 'pinv_clip'): '337098afda2b3ff8',
    ('harv', 'ganging'): '83d1aa98c3c31cca',
    ('harv', 'pinv_scale'): '6c258789aa54cc4a',
    ('harv', 'cgi'): '7d1435d25f4623d2',
    ('harv', 'wls'): '6e70f2305e53450c',
    ('harv', 'qp'): '04c4f3db70ea3fbc',
    ('harv', 'dynamic'): 'c425c39c24ab6062',
    ('harv', 'lp'): '1db7f75b04d0e576',
    ('hexa-x', 'pinv'): 'bedb29aab41e8116',
    ('hexa-x', 'pinv_clip'): 'bc3020841d7e64b4',
    ('hexa-x', 'ganging'): '3c1de7e0052e9483',
    ('hexa-x', 'pinv_scale'): '889d91e4ab524c90',
    ('hexa-x', 'cgi'): '1f5eb09beb2388b6',
    ('hexa-x', 'wls'): 'c0a150c5ebe08725',
    ('hexa-x', 'qp'): 'be386b4dbcdf8f0e',
    ('hexa-x', 'dynamic'): '0b746452a94d407a',
    ('hexa-x', 'lp'): '6dd105dc72dd05c9',
    ('tailless', 'pinv'): '263bf3625cba8a9e',
    ('tailless', 'pinv_clip'): '10f318c446508422',
    ('tailless', 'ganging'): '03e88302c418cac9',
    ('tailless', 'pinv_scale'): '07724efcf5475cce',
    ('tailless', 'cgi'): 'eea5cf86a79ee835',
    ('tailless', 'wls'): '5c9335d4c3795e2c',
    ('tailless', 'qp'): '4fa029e9f406ff20',
    ('tailless', 'dynamic'): 'ab8565d052f3d4dc',
    ('tailless', 'lp'): '60f6f3ea1c1e26d6',
    ('x57-dep', 'pinv'): 'b14453b1ab93e6d3',
    ('x57-dep', 'pinv_clip'): 'a0e134509854d23a',
    ('x57-dep', 'ganging'): '73bfec261db6e54e',
    ('x57-dep', 'pinv_scale'): '1068650d87a7a80f',
    ('x57-dep', 'cgi'): 'refused: table',
    ('x57-dep', 'wls'): '9ebcd4f293364436',
    ('x57-dep', 'qp'): 'ac19e450d39eb77b',
    ('x57-dep', 'dynamic'): '0c2f6b34b11f72bf',
    ('x57-dep', 'lp'): '0d457eca5d386d7e',
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
