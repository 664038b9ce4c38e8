"""The build lanes (service.builds): what crosses back from the build process, and how."""

from __future__ import annotations

import json

import pickle

import numpy as np
import pytest

import alloc
from alloc.vehicles import ice
from service.builds import Call, build
from service.cost import build_seconds

COSTLY = [name for name in alloc.methods() if build_seconds(ice(), name, {}) > 0]


def test_costly_methods_exist():
    assert {"da_facet", "da_bisect", "da_table"} <= set(COSTLY)


@pytest.mark.parametrize("method", COSTLY)
def test_costly_allocators_cross_a_process_boundary_unchanged(method):
    """Every method built in the build process (a predicted cost) pickles, and answers the same."""
    p = ice()
    allocator = alloc.make_allocator(p, method)
    copy = pickle.loads(pickle.dumps(allocator))
    rng = np.random.default_rng(3)
    for v in rng.normal(size=(20, p.k)) * 0.5:
        a, b = allocator(v), copy(v)
        assert np.array_equal(a.u, b.u) and a.status == b.status
    assert copy.problem.to_dict() == p.to_dict()


def test_build_returns_the_allocator_only_when_it_may_be_kept():
    p = ice()
    v = np.array([0.1, 0.2, 0.0])
    kept = build(p, "da_facet", {}, 3.0, 1 << 30, Call(v))
    assert kept.allocator is not None and kept.result is None and kept.nbytes > 0
    call = Call(v)
    answered = build(p, "da_facet", {}, 3.0, 0, call)  # too large to keep: the answer comes back instead
    assert answered.allocator is None and answered.token == call.token
    assert np.array_equal(answered.result.u, kept.allocator(v).u)
    # a batch: always answered there, as the JSON bytes of its answer (serialised off the event loop)
    batch = build(p, "pinv", {}, 3.0, 1 << 30, Call(V=np.array([v, -v]), extra={"health_version": 3}))
    answer = json.loads(batch.result)
    assert batch.allocator is None and np.array(answer["u"]).shape == (2, p.m) and answer["health_version"] == 3
    assert answer["u"] == alloc.make_allocator(p, "pinv").batch(np.array([v, -v])).u.tolist()
    prebuilt = build(p, "da_facet", {}, 3.0, 0, None)  # a prebuild of one too large to keep: nothing
    assert prebuilt.allocator is None and prebuilt.result is None
