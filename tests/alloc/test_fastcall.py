"""The allocator's call path in C (alloc/_engine/_fastcall.c) against its Python twin (``Allocator._call_py``).

The C path must be invisible except in time: for every method and every argument form --
valid, odd or invalid -- ``allocator(...)`` returns what ``allocator._call_py(...)`` returns,
bit for bit, or raises the same error.  Generated: random problems (seeded), every method,
demands inside and outside the attainable set, with and without rate limits, and a catalogue
of argument forms the fast path must hand back to Python.
"""

from __future__ import annotations

import gc
import pickle
import sys

import numpy as np
import pytest

import alloc
from alloc.api import has_c_call_path
from alloc.testing import KINDS, random_problem

pytestmark = pytest.mark.skipif(not has_c_call_path(), reason="alloc._engine._fastcall is not built (no C compiler at install)")

FLAGS = ("C_CONTIGUOUS", "F_CONTIGUOUS", "OWNDATA", "WRITEABLE", "ALIGNED")


def same_result(a: alloc.Result, b: alloc.Result) -> None:
    assert type(a) is type(b) is alloc.Result
    for name, x, y in zip(a._fields, a, b):
        if name == "solve_time":
            assert isinstance(x, float) and isinstance(y, float) and x >= 0 and y >= 0
        elif isinstance(x, np.ndarray):
            assert type(y) is np.ndarray and x.dtype == y.dtype and x.shape == y.shape, name
            assert np.array_equal(x, y, equal_nan=True), name
            assert [x.flags[f] for f in FLAGS] == [y.flags[f] for f in FLAGS], name
        else:
            assert type(x) is type(y) and x == y, name


def outcome(call, *args, **kwargs):
    try:
        return call(*args, **kwargs), None
    except Exception as exc:  # noqa: BLE001 - compared below
        return None, (type(exc), str(exc))


def check_same(f: alloc.Allocator, *args, **kwargs) -> None:
    a, ea = outcome(f, *args, **kwargs)
    b, eb = outcome(f._call_py, *args, **kwargs)
    assert ea == eb
    if a is not None:
        same_result(a, b)


@pytest.mark.parametrize("method", alloc.methods())
def test_c_path_equals_python_path_on_generated_problems(method: str) -> None:
    rng = np.random.default_rng(20261130)
    built = 0
    for trial in range(2 * len(KINDS)):
        p = random_problem(rng, int(rng.integers(1, 5)), int(rng.integers(4, 10)), KINDS[trial % len(KINDS)],
                           weights=trial < len(KINDS))
        try:
            f = alloc.make_allocator(p, method)
        except alloc.AllocError:  # e.g. the L1 methods refuse non-diagonal weights
            continue
        built += 1
        for _ in range(25):
            u = rng.uniform(p.umin, p.umax)
            v = p.B @ u * rng.choice([0.3, 1.0, 2.5, 50.0])
            u_prev = rng.uniform(p.umin, p.umax)
            check_same(f, v)
            check_same(f, v, u_prev=u_prev, dt=float(rng.choice([1e-3, 0.02, 1.0])))
    assert built >= len(KINDS)


def test_argument_forms_the_c_path_hands_back() -> None:
    p = random_problem(np.random.default_rng(5), 3, 8)
    for method in ("pinv", "qp", "wls", "lp", "pinv_scale", "da"):
        f = alloc.make_allocator(p, method)
        v = p.B @ (0.5 * (p.umin + p.umax) + 0.05)
        up = 0.5 * (p.umin + p.umax)
        big_endian = v.astype(">f8")
        strided = np.repeat(v, 2)[::2]
        read_only, up_read_only = v.copy(), up.copy()
        read_only.setflags(write=False)
        up_read_only.setflags(write=False)
        forms = [
            ((v,), {}), ((v,), {"u_prev": None, "dt": None}), ((list(v),), {}), ((tuple(v),), {}),
            ((v.astype(np.float32),), {}), ((v.astype(int),), {}), ((big_endian,), {}), ((strided,), {}),
            ((v[:2],), {}), ((v.reshape(1, 3),), {}), ((np.r_[v, 1.0],), {}), ((np.full(3, np.nan),), {}),
            ((np.full(3, np.inf),), {}), ((np.full(3, 1e60),), {}), (("abc",), {}), ((None,), {}), ((), {}),
            ((v, v), {}), ((v,), {"w": 1}), ((v,), {"u_prev": up}), ((v,), {"dt": 0.01}),
            ((v,), {"u_prev": up, "dt": 1}), ((v,), {"u_prev": up, "dt": -0.01}), ((v,), {"u_prev": up, "dt": 0.0}),
            ((v,), {"u_prev": up, "dt": np.float64(0.01)}), ((v,), {"u_prev": up, "dt": float("nan")}),
            ((v,), {"u_prev": up, "dt": 1e60}), ((v,), {"u_prev": list(up), "dt": 0.01}),
            ((v,), {"u_prev": up[:3], "dt": 0.01}), ((v,), {"u_prev": up.astype(">f8"), "dt": 0.01}),
            ((v,), {"u_prev": np.full(8, np.nan), "dt": 0.01}), ((v,), {"u_prev": up, "dt": 0.01, "x": 1}),
            ((read_only,), {}), ((read_only,), {"u_prev": up_read_only, "dt": 0.01}),
            ((f(v).v,), {}),  # a result's own (read-only) demand, given back
        ]
        for args, kwargs in forms:
            check_same(f, *args, **kwargs)


def test_results_are_read_only_and_own_their_buffer() -> None:
    p = random_problem(np.random.default_rng(7), 3, 8)
    f = alloc.make_allocator(p, "qp")
    v = p.B @ p.umax * 3.0
    r = f(v)
    v[:] = 0.0  # the caller reuses its array: the result keeps the demand it was given
    assert not np.array_equal(r.v, v)
    for a in (r.u, r.v, r.v_achieved, r.unallocated):
        assert not a.flags.writeable
        with pytest.raises(ValueError):
            a[0] = 1.0
    assert r.u.base is r.v.base is r.v_achieved.base is r.unallocated.base


def test_no_reference_leaks() -> None:
    p = random_problem(np.random.default_rng(9), 3, 8)
    rng = np.random.default_rng(1)
    V = rng.normal(size=(200, 3))
    up = 0.5 * (p.umin + p.umax)
    for method in ("pinv", "qp"):
        f = alloc.make_allocator(p, method)
        watched = (alloc.Result, alloc.Status.EXACT, alloc.Status.UNATTAINABLE, f.method, up, "")

        def run() -> None:
            for v in V:
                f(v)
                f(v, u_prev=up, dt=0.01)
                outcome(f, v[:2])

        run()
        gc.collect()
        before = [sys.getrefcount(x) for x in watched]
        for _ in range(5):
            run()
        gc.collect()
        assert [sys.getrefcount(x) for x in watched] == before


def test_pickle_round_trip_keeps_the_c_path() -> None:
    import service.builds  # noqa: F401 - registers Problem's pickling, as the service does

    p = random_problem(np.random.default_rng(11), 3, 8)
    v = p.B @ p.umax * 0.4
    for method in ("pinv", "wls", "da"):
        f = alloc.make_allocator(p, method)
        g = pickle.loads(pickle.dumps(f))
        same_result(g(v), f(v))
        same_result(g(v), g._call_py(v))


@pytest.mark.parametrize("method", ["qp", "wls", "dynamic", "pinv", "da"])
def test_threaded_batch_equals_single_calls(method: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """``allocate_batch`` on several threads (each on a private copy of the solver state) returns
    the single calls' answers bit for bit, whatever the split."""
    from alloc._engine import _threads

    rng = np.random.default_rng(31)
    p = random_problem(rng, 3, 9, "coplanar")
    V = p.B @ rng.uniform(p.umin, p.umax, size=(240, p.m)).T
    V = (V * rng.choice([0.5, 1.0, 3.0], size=240)).T.copy()
    single = alloc.make_allocator(p, method)
    expected = [single(v) for v in V]
    for threads, chunk in ((1, 256), (2, 256), (2, 7), (3, 1), (7, 13)):
        monkeypatch.setattr(_threads, "ROWS_PER_THREAD", 10)
        monkeypatch.setattr(_threads, "MAX_THREADS", threads)
        monkeypatch.setattr(_threads, "CHUNK_ROWS", chunk)  # threads pull chunks in any order
        assert _threads.threads_for(len(V)) == threads
        res = alloc.make_allocator(p, method).batch(V)
        assert np.array_equal(res.u, np.array([r.u for r in expected]))
        assert np.array_equal(res.v_achieved, np.array([r.v_achieved for r in expected]))
        assert list(res.status) == [r.status.value for r in expected]


@pytest.mark.parametrize("method", ["qp", "wls", "dynamic"])
def test_batch_rows_at_the_iteration_cap_are_the_single_calls(method: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """Rows the compiled batch cannot finish (a level's iteration cap) are redone by the single
    call: the batch still equals the single calls row by row, fallbacks included."""
    from alloc._engine import _threads

    rng = np.random.default_rng(32)
    p = random_problem(rng, 3, 10, "general")
    V = (p.B @ rng.uniform(p.umin, p.umax, size=(300, p.m)).T * 2.5).T.copy()  # many pivots each
    monkeypatch.setattr(_threads, "ROWS_PER_THREAD", 50)
    single, batch = alloc.make_allocator(p, method), alloc.make_allocator(p, method)
    for f in (single, batch):
        impl = f.impl._static if method == "dynamic" else f.impl._impl
        impl.maxit = 2
    expected = [single(v) for v in V]
    assert 0 < sum(r.status is alloc.Status.FALLBACK for r in expected) < len(V)
    res = batch.batch(V)
    assert np.array_equal(res.u, np.array([r.u for r in expected]))
    assert np.array_equal(res.v_achieved, np.array([r.v_achieved for r in expected]))
    assert list(res.status) == [r.status.value for r in expected]


@pytest.mark.parametrize("threads,chunk", [(1, 5), (2, 1), (2, 64), (3, 7), (5, 1000)])
def test_run_chunks_covers_every_row_once_and_raises(threads: int, chunk: int) -> None:
    from alloc._engine._threads import run_chunks

    n = 531
    seen = np.zeros(n, dtype=np.int64)
    contexts = []

    def worker():
        contexts.append(object())
        def work(a: int, b: int) -> None:
            seen[a:b] += 1
        return work

    run_chunks(worker, n, threads, chunk)
    assert (seen == 1).all() and 1 <= len(contexts) <= min(threads, -(-n // chunk))

    def failing():
        def work(a: int, b: int) -> None:
            if a <= 300 < b:
                raise RuntimeError("row 300")
        return work

    with pytest.raises(RuntimeError, match="row 300"):
        run_chunks(failing, n, threads, chunk)


def test_concurrent_batches_on_one_allocator(monkeypatch: pytest.MonkeyPatch) -> None:
    """Several Python threads batching on one allocator at once (as service workers may) share the
    thread pool and the allocator; every batch still equals the single calls."""
    import threading

    from alloc._engine import _threads

    rng = np.random.default_rng(33)
    p = random_problem(rng, 3, 9, "general")
    V = (p.B @ rng.uniform(p.umin, p.umax, size=(400, p.m)).T * rng.choice([0.5, 2.0], size=400)).T.copy()
    expected = alloc.make_allocator(p, "qp").batch(V)  # one thread (400 rows)
    monkeypatch.setattr(_threads, "ROWS_PER_THREAD", 20)
    monkeypatch.setattr(_threads, "MAX_THREADS", 3)
    monkeypatch.setattr(_threads, "CHUNK_ROWS", 9)
    f = alloc.make_allocator(p, "qp")
    results: list = []

    def run() -> None:
        for _ in range(5):
            results.append(f.batch(V))

    workers = [threading.Thread(target=run) for _ in range(4)]
    for w in workers:
        w.start()
    for w in workers:
        w.join()
    assert len(results) == 20
    for r in results:
        assert np.array_equal(r.u, expected.u) and np.array_equal(r.v_achieved, expected.v_achieved)
        assert list(r.status) == list(expected.status)
