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


# ----------------------------------------------------------------------------- batch answers
def _hostile_batch(rng: np.random.Generator) -> alloc.BatchResult:
    """A batch result of random shape (0 rows included) whose values span the float64 range:
    subnormals, -0.0, 1e150 (the library caps magnitudes at 1e50), integers, values whose shortest form needs 17 digits."""
    n, k, m = int(rng.integers(0, 40)), int(rng.integers(1, 7)), int(rng.integers(1, 70))
    pool = np.array([0.0, -0.0, 5e-324, -2.2250738585072014e-308, 1e150, -1.7976931348623157e150, 1.0, -3.0,
                     0.1, 1 / 3, 2.0**53 + 2, 1e-7, 123456789.0])

    def draw(shape: tuple[int, int]) -> np.ndarray:
        a = rng.normal(size=shape) * 10.0 ** rng.integers(-320, 150, size=shape)
        mask = rng.random(shape) < 0.3
        a[mask] = rng.choice(pool, size=int(mask.sum()))
        return a

    status = rng.choice([s.value for s in alloc.Status], size=n)
    return alloc.BatchResult(draw((n, m)), draw((n, k)), draw((n, k)), status, "qp", float(rng.random()))


@pytest.mark.parametrize("seed", range(6))
def test_batch_answers_written_in_pieces_are_the_models_document(seed, monkeypatch):
    """The batch answer is written in pieces so that its build thread lets the event loop run
    (one pydantic call over an 8,000 x 64 answer held the GIL 130-170 ms): the pieces must make
    the very document the response model writes, every float round-tripping bit for bit, at
    any piece size."""
    from service import responses
    from service.schemas import BatchOut

    rng = np.random.default_rng(seed)
    for trial in range(30):
        b = _hostile_batch(rng)
        extra = [{}, {"vehicle_id": "v-1", "health_version": int(rng.integers(0, 2**62))}][trial % 2]
        monkeypatch.setattr(responses, "NUMBERS_PER_CALL", int(rng.choice([1, 7, 64, 8192])))
        ours = responses.batch_json(b, **extra)
        model = BatchOut.of(b, **extra).model_dump_json().encode()
        assert ours == model
        back = json.loads(ours)
        for name in ("u", "v_achieved", "unallocated"):
            got = np.array(back[name], dtype=float).reshape(getattr(b, name).shape)
            assert np.array_equal(got.view(np.int64), np.asarray(getattr(b, name)).view(np.int64))
