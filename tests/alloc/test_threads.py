"""Allocators shared by threads (issue 22): the same answers as alone, no poisoned cache, no crash.

The rule (alloc.api.Allocator): an allocator is safe to call from several threads; each
answer is what the same call on the allocator alone returns.  Here every registered method
and each explicit backend is hammered from 8 threads with a seeded mix of single calls,
rate-limited calls and small batches, with the interpreter's thread switch interval cut to
10 us so that threads interleave inside calls.  Every answer is compared bit for bit with the
serial answer of a fresh allocator, and after the threads finish the shared allocator is
asked every operation again (a cache written by two threads at once would now answer
differently).  Before the lock: ``lp`` 2 of 1,200 calls wrong, ``da`` on 6 x 16 88, ``qp`` on
DAQP 52, ``cgi`` on 6 x 30 13 during and 78 after; ``lp`` on HiGHS a SIGSEGV.

The default run keeps each case to a few hundred operations (about 20 s in all); the
``slow`` version runs every case on every problem with 600 operations.
"""

from __future__ import annotations

import subprocess
import sys
import threading
import time
import warnings
from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest

import alloc
import alloc.vehicles
from alloc.solvers import backends
from alloc.testing import random_demands, random_problem

THREADS = 8
SEED = 2026_12_22


def problem(name: str) -> alloc.Problem:
    if name == "ice":
        return alloc.vehicles.problem("ice")
    k, m = (int(x) for x in name.split("x"))
    return random_problem(np.random.default_rng(SEED + m), k, m)


def operations(p: alloc.Problem, n: int, rng: np.random.Generator) -> list[tuple[Any, ...]]:
    """A seeded mix: 70 % plain calls, 20 % rate-limited calls, 10 % batches of 3 rows."""
    V = random_demands(rng, p, n)
    ops: list[tuple[Any, ...]] = []
    for i in range(n):
        r = rng.random()
        if r < 0.7:
            ops.append(("call", V[i]))
        elif r < 0.9:
            ops.append(("rate", V[i], rng.uniform(p.umin, p.umax), float(rng.choice([0.005, 0.02, 0.1]))))
        else:
            ops.append(("batch", random_demands(rng, p, 3)))
    return ops


def run(f: alloc.Allocator, op: tuple[Any, ...]) -> tuple[np.ndarray, list[str]]:
    if op[0] == "call":
        r = f(op[1])
        return r.u, [r.status.value]
    if op[0] == "rate":
        r = f(op[1], u_prev=op[2], dt=op[3])
        return r.u, [r.status.value]
    b = f.batch(op[1])
    return b.u, [str(s) for s in b.status]


def hammer(pname: str, method: str, options: dict[str, Any], n: int) -> dict[str, int]:
    """Wrong answers during and after 8 threads share one allocator (0 and 0 expected)."""
    p = problem(pname)
    rng = np.random.default_rng(SEED)
    ops = operations(p, n, rng)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # qpsolvers' sparse-conversion and status warnings
        fresh = alloc.make_allocator(p, method, **options)
        serial = [run(fresh, op) for op in ops]
        shared = alloc.make_allocator(p, method, **options)
        got: list[Any] = [None] * n
        errors: list[BaseException] = []
        start = threading.Barrier(THREADS)

        def work(t: int) -> None:
            try:
                start.wait()
                for i in range(t, n, THREADS):
                    got[i] = run(shared, ops[i])
            except BaseException as exc:  # noqa: BLE001 - re-raised in the main thread
                errors.append(exc)

        interval = sys.getswitchinterval()
        sys.setswitchinterval(1e-5)
        try:
            threads = [threading.Thread(target=work, args=(t,)) for t in range(THREADS)]
            for t in threads:
                t.start()
            for t in threads:
                t.join()
        finally:
            sys.setswitchinterval(interval)
        assert not errors, errors[0]
        after = [run(shared, op) for op in ops]

    def differs(a: tuple[np.ndarray, list[str]], b: tuple[np.ndarray, list[str]]) -> bool:
        return not (a[0].shape == b[0].shape and np.array_equal(a[0], b[0]) and a[1] == b[1])

    return {"during": sum(differs(a, b) for a, b in zip(got, serial)),
            "after": sum(differs(a, b) for a, b in zip(after, serial))}


#: methods whose calls cost a millisecond or more get fewer operations in the default run
SLOW_CALLS = {"cgi", "da", "da_bisect", "da_facet", "da_table", "daisy", "lp", "wls"}


#: the issue's reproducers, with enough operations to show the race on the unlocked code
#: (measured there: cgi 13-46 wrong of 300, da 9-17 of 300, lp 4 of 300 and 0 of 300)
#: (da_facet on 6 x 30 is above the facet limit: the facet search runs da's LP)
REPRODUCERS = {("6x30", "cgi"): 300, ("6x16", "da"): 300, ("ice", "lp"): 900, ("6x30", "da_facet"): 300}


def default_n(pname: str, method: str, options: dict[str, Any]) -> int:
    if options.get("backend") in ("osqp", "clarabel", "scs", "highs"):
        return 40
    if not options and (pname, method) in REPRODUCERS:
        return REPRODUCERS[pname, method]
    return 64 if method in SLOW_CALLS or options else 240


def backend_cases() -> Iterator[tuple[str, dict[str, Any]]]:
    """Each explicit backend of the methods that take one (third-party ones where installed)."""
    for b in ("simplex", *backends(lp=True)):
        yield "lp", {"backend": b}
    for b in ("facet", *backends(lp=True)):
        yield "da", {"backend": b}
    for b in ("active_set", "daqp", "osqp", "clarabel"):
        if b in ("active_set", *backends()):
            yield "qp", {"backend": b}
            yield "wls", {"backend": b}


def case_id(method: str, options: dict[str, Any]) -> str:
    return method + "".join(f"-{v}" for v in options.values())


DEFAULT_CASES = ([(pname, m, {}) for m in alloc.methods() for pname in ("ice", "6x16")]
                 + [("6x30", "cgi", {}), ("6x30", "da_facet", {})]
                 + [("ice", m, o) for m, o in backend_cases()
                    if o.get("backend") not in ("osqp", "clarabel", "highs")])


@pytest.mark.parametrize(("pname", "method", "options"), DEFAULT_CASES,
                         ids=[f"{p}-{case_id(m, o)}" for p, m, o in DEFAULT_CASES])
def test_threads_get_the_serial_answers(pname: str, method: str, options: dict[str, Any]) -> None:
    assert hammer(pname, method, options, default_n(pname, method, options)) == {"during": 0, "after": 0}


THIRD_PARTY = [(m, o) for m, o in backend_cases() if o.get("backend") in ("osqp", "clarabel")]


@pytest.mark.parametrize(("method", "options"), THIRD_PARTY, ids=[case_id(m, o) for m, o in THIRD_PARTY])
def test_threads_on_qpsolvers_backends(method: str, options: dict[str, Any]) -> None:
    assert hammer("ice", method, options, 24) == {"during": 0, "after": 0}


def test_highs_shared_by_threads_does_not_crash_the_process() -> None:
    """HiGHS is not re-entrant: one model run from two threads crashed the process (SIGSEGV)
    every time.  In a subprocess, so that a crash fails this test, not the run."""
    code = f"""
import sys
sys.path.insert(0, {str(__file__.rsplit('/', 1)[0])!r})
from test_threads import hammer
for method in ("lp", "da"):
    print(method, hammer("ice", method, {{"backend": "highs"}}, 160))
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=900)
    assert out.returncode == 0, f"exit {out.returncode}: {out.stderr[-2000:]}"
    lines = [line for line in out.stdout.splitlines() if line.startswith(("lp ", "da "))]
    assert lines == ["lp {'during': 0, 'after': 0}", "da {'during': 0, 'after': 0}"], out.stdout


def test_the_lock_is_reentrant_and_owned() -> None:
    """The allocator's lock: re-entrant in its owner (a batch calls the single call), and
    another thread's release is refused."""
    f = alloc.make_allocator(alloc.vehicles.problem("ice"), "qp")
    f._acquire()
    f._acquire()
    r = f(np.zeros(3))  # takes the lock a third time on the C path
    assert r.status.value == "exact"
    f._release()
    outcome: list[BaseException] = []

    def other() -> None:
        try:
            f._release()
        except RuntimeError as exc:
            outcome.append(exc)

    t = threading.Thread(target=other)
    t.start()
    t.join()
    assert len(outcome) == 1
    f._release()
    with pytest.raises(RuntimeError, match="not held"):
        f._release()


def test_a_waiting_thread_gets_the_lock_when_it_is_released() -> None:
    f = alloc.make_allocator(alloc.vehicles.problem("ice"), "qp")
    done = threading.Event()
    f._acquire()

    def call() -> None:
        f(np.array([0.1, 0.0, 0.0]))
        done.set()

    t = threading.Thread(target=call)
    t.start()
    assert not done.wait(0.2)  # blocked on the lock (without the GIL: this thread runs)
    f._release()
    assert done.wait(30)
    t.join()


def test_the_lock_excludes_and_wakes_every_waiter() -> None:
    """8 threads increment a counter inside the lock with the GIL released in the middle
    (time.sleep(0)): mutual exclusion keeps every increment; a lost wake-up would leave a
    thread waiting (the joins time out)."""
    f = alloc.make_allocator(alloc.vehicles.problem("ice"), "qp")
    count = [0]
    rounds = 300

    def work() -> None:
        for _ in range(rounds):
            f._acquire()
            try:
                seen = count[0]
                time.sleep(0)  # another thread runs here: it must wait for the lock
                count[0] = seen + 1
            finally:
                f._release()

    threads = [threading.Thread(target=work, daemon=True) for _ in range(THREADS)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(120)
    assert not any(t.is_alive() for t in threads), "a thread never got the lock"
    assert count[0] == THREADS * rounds


ALL_CASES = ([(pname, m, {}) for m in alloc.methods() for pname in ("ice", "6x16", "6x30")]
             + [(pname, m, o) for m, o in backend_cases() for pname in ("ice", "6x16", "6x30")])


@pytest.mark.slow
@pytest.mark.parametrize(("pname", "method", "options"), ALL_CASES,
                         ids=[f"{p}-{case_id(m, o)}" for p, m, o in ALL_CASES])
def test_threads_get_the_serial_answers_at_length(pname: str, method: str, options: dict[str, Any]) -> None:
    n = 120 if options.get("backend") in ("osqp", "clarabel") else 600
    try:
        alloc.make_allocator(problem(pname), method, **options)
    except alloc.AllocError as exc:  # e.g. lp's simplex above its size cap: nothing to share
        pytest.skip(f"{method} {options} not built on {pname}: {exc}")
    assert hammer(pname, method, options, n) == {"during": 0, "after": 0}


def test_a_copy_shares_no_mutable_state_with_its_original() -> None:
    """A copy has its own lock, so it gets its own method state (caches, backend models)."""
    import copy

    p = alloc.vehicles.problem("ice")
    for method in ("qp", "lp", "cgi", "da"):
        f = alloc.make_allocator(p, method)
        for g in (copy.copy(f), copy.deepcopy(f)):
            assert g.impl is not f.impl and g._safe is not f._safe
            v = np.array([0.1, 0.05, -0.02])
            assert np.array_equal(g(v).u, f(v).u)
