"""No call compiles: every input form is normalised to the layout the kernels are compiled for.

numba compiles one machine-code version per argument type, and an array's type includes its
dtype, byte order, layout and writeability.  A strided demand (``v = X[:, j]``), a reversed or
unaligned one, a Fortran-ordered or transposed batch, a big-endian, float32, integer or
read-only array met for the first time in a process would compile a new kernel inside that
call (issue 22: 15.5 s for one ``qp`` call).  The allocator copies such inputs into a new
C-contiguous, aligned, native float64 array (alloc.api._compiled_layout).

For every method, after a warm-up with contiguous float64 inputs, a generator of input forms
(seeded) asserts (a) each answer equals the contiguous input's answer bit for bit and (b) no
numba dispatcher in the ``alloc`` modules gained a signature.
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Iterator

import numpy as np
import pytest
from numba.core.dispatcher import Dispatcher

import alloc
import alloc.vehicles
from alloc.testing import random_demands, random_problem


def dispatchers() -> dict[str, Dispatcher]:
    """Every numba dispatcher reachable as an attribute of a loaded ``alloc.*`` module."""
    found: dict[str, Dispatcher] = {}
    for name, module in list(sys.modules.items()):
        if module is None or not (name == "alloc" or name.startswith("alloc.")):
            continue
        for value in list(vars(module).values()):
            if isinstance(value, Dispatcher):
                found.setdefault(f"{value.py_func.__module__}.{value.py_func.__qualname__}", value)
    return found


def signatures() -> dict[str, int]:
    return {name: len(d.overloads) for name, d in dispatchers().items()}


def unaligned(a: np.ndarray) -> np.ndarray:
    """A copy of ``a`` (C order) in a buffer one byte off 8-byte alignment (np.frombuffer offset)."""
    raw = bytearray(a.nbytes + 1)
    out = np.frombuffer(raw, dtype=np.float64, count=a.size, offset=1).reshape(a.shape)
    out[...] = a
    assert not out.flags.aligned
    return out


def readonly(a: np.ndarray) -> np.ndarray:
    b = np.array(a)
    b.setflags(write=False)
    return b


def vector_forms(v: np.ndarray, rng: np.random.Generator, demand: bool = True) -> Iterator[tuple[str, object, np.ndarray]]:
    """``(name, form, values)``: ``form`` carries the float64 ``values`` in another layout or
    type (with ``demand``, also the shapes a demand may take: a column, a 0-d array)."""
    n = v.size
    X = rng.standard_normal((n, 5))
    X[:, 2] = v
    yield "strided column X[:, j]", X[:, 2], v
    yield "strided every other", np.repeat(v, 2)[::2], v
    yield "reversed [::-1]", v[::-1].copy()[::-1], v
    yield "unaligned frombuffer", unaligned(v), v
    yield "big-endian >f8", v.astype(">f8"), v
    yield "read-only", readonly(v), v
    yield "list", v.tolist(), v
    if demand:
        yield "Fortran column (n, 1)", np.asfortranarray(v.reshape(n, 1)), v
    v32 = v.astype(np.float32)
    yield "float32", v32, v32.astype(np.float64)
    vi = np.round(v * 3).astype(np.int64)
    yield "int64", vi, vi.astype(np.float64)
    yield "int32 list", vi.astype(np.int32).tolist(), vi.astype(np.float64)
    if n == 1 and demand:
        yield "0-d array", np.array(v[0]), v
        yield "numpy scalar", np.float64(v[0]), v
        yield "1x1 nested list", [[float(v[0])]], v


def matrix_forms(V: np.ndarray) -> Iterator[tuple[str, object, np.ndarray]]:
    N, k = V.shape
    yield "Fortran order", np.asfortranarray(V), V
    yield "transposed view", np.ascontiguousarray(V.T).T, V
    yield "strided rows", np.repeat(V, 2, axis=0)[::2], V
    yield "reversed columns", V[:, ::-1].copy()[:, ::-1], V
    yield "unaligned frombuffer", unaligned(V), V
    yield "big-endian >f8", V.astype(">f8"), V
    yield "read-only", readonly(V), V
    yield "nested lists", V.tolist(), V
    V32 = V.astype(np.float32)
    yield "float32", V32, V32.astype(np.float64)
    Vi = np.round(V * 3).astype(np.int64)
    yield "int64 Fortran", np.asfortranarray(Vi), Vi.astype(np.float64)


def same_bits(a: alloc.Result, b: alloc.Result, what: str) -> None:
    assert a.status == b.status, what
    for name in ("u", "v", "v_achieved"):
        x, y = getattr(a, name), getattr(b, name)
        assert x.dtype == y.dtype == np.float64 and np.array_equal(x, y), f"{what}: {name} differs"


PROBLEMS: dict[str, Callable[[], alloc.Problem]] = {
    "ice": lambda: alloc.vehicles.problem("ice"),
    "1x4": lambda: random_problem(np.random.default_rng(11), 1, 4),
}


def warm(f: alloc.Allocator, p: alloc.Problem, V: np.ndarray, U0: np.ndarray) -> None:
    """The contiguous float64 forms every later call is compared with (and compiled for)."""
    for v, u0 in zip(V, U0):
        f(np.ascontiguousarray(v))
        f._call_py(np.ascontiguousarray(v))
        f(np.ascontiguousarray(v), u_prev=np.ascontiguousarray(u0), dt=0.02)
        f._call_py(np.ascontiguousarray(v), u_prev=np.ascontiguousarray(u0), dt=0.02)
    f.batch(np.ascontiguousarray(V))


def grown(before: dict[str, int]) -> dict[str, tuple[int, int]]:
    return {name: (before.get(name, 0), n) for name, n in signatures().items() if n > before.get(name, 0)}


@pytest.mark.parametrize("pname", sorted(PROBLEMS))
@pytest.mark.parametrize("method", alloc.methods())
def test_every_input_form_gives_the_contiguous_answer_and_compiles_nothing(method: str, pname: str) -> None:
    """Each form is called right after the contiguous float64 call of the same values (which
    loads whatever that call's path needs, from numba's cache or by compiling); the form
    itself must add no signature to any dispatcher, and give the same bits."""
    rng = np.random.default_rng(2026_12_01)
    p = PROBLEMS[pname]()
    V = random_demands(rng, p, 2, attainable_fraction=0.5)
    U0 = rng.uniform(p.umin, p.umax, size=(len(V), p.m))
    f = alloc.make_allocator(p, method)
    warm(f, p, V, U0)
    assert signatures(), "no numba dispatcher found in the alloc modules"
    compiled: list[tuple[str, dict[str, tuple[int, int]]]] = []
    checked = 0
    for v, u0 in zip(V, U0):
        for name, form, values in vector_forms(v, rng):
            ref = f(np.array(values))
            before = signatures()
            for call in (f, f._call_py):
                same_bits(call(form), ref, f"{method} v {name}")
            compiled += [(f"v {name}", g) for g in [grown(before)] if g]
            checked += 1
        for name, form, values in vector_forms(u0, rng, demand=False):
            ref = f(np.array(v), u_prev=np.array(values), dt=0.02)
            before = signatures()
            for call in (f, f._call_py):
                same_bits(call(v, u_prev=form, dt=0.02), ref, f"{method} u_prev {name}")
            compiled += [(f"u_prev {name}", g) for g in [grown(before)] if g]
            checked += 1
        ref = f(np.array(v), u_prev=np.array(u0), dt=0.02)
        X = rng.standard_normal((p.k, 3))
        X[:, 1] = v
        before = signatures()
        same_bits(f(X[:, 1], u_prev=np.repeat(u0, 2)[::2], dt=0.02), ref, f"{method} strided v and u_prev")
        same_bits(f(v, u_prev=u0, dt=np.float32(0.02)), f(v, u_prev=u0, dt=float(np.float32(0.02))),
                  f"{method} dt numpy float32")
        compiled += [("strided v and u_prev, numpy dt", g) for g in [grown(before)] if g]
    for name, form, values in matrix_forms(V):
        ref_b = f.batch(np.array(values))
        before = signatures()
        got = f.batch(form)
        compiled += [(f"V {name}", g) for g in [grown(before)] if g]
        assert np.array_equal(got.u, ref_b.u) and np.array_equal(got.v_achieved, ref_b.v_achieved), f"{method} V {name}"
        assert list(got.status) == list(ref_b.status), f"{method} V {name}"
        checked += 1
    assert not compiled, f"{method}: kernels compiled on the call path (form, signatures before/after): {compiled}"
    assert checked >= 2 * (10 + 9) + 10


def test_a_strided_first_call_in_a_fresh_process_compiles_nothing() -> None:
    """The issue's reproducer: a process whose first ``qp``/``pinv_scale`` call gets ``X[:, j]``
    (and a strided ``u_prev``, a Fortran batch) adds no kernel signature beyond what the
    contiguous calls load."""
    import subprocess

    code = """
import sys, numpy as np, alloc, alloc.vehicles
from numba.core.dispatcher import Dispatcher
def sigs():
    out = {}
    for name, mod in list(sys.modules.items()):
        if mod is not None and name.startswith("alloc"):
            for a, d in list(vars(mod).items()):
                if isinstance(d, Dispatcher):
                    out[d.py_func.__module__ + "." + d.py_func.__qualname__] = len(d.overloads)
    return out
p = alloc.vehicles.problem("ice")
X = np.random.default_rng(0).uniform(-0.2, 0.2, (3, 7))
for method in ("qp", "pinv", "pinv_scale", "wls", "dynamic"):
    f = alloc.make_allocator(p, method)
    f(np.zeros(3)); f(np.zeros(3), u_prev=np.zeros(p.m), dt=0.02); f.batch(np.zeros((4, 3)))
    before = sigs()
    a = f(X[:, 2]); b = f(X[:, 2], u_prev=np.repeat(np.zeros(p.m), 2)[::2], dt=0.02)
    c = f.batch(np.asfortranarray(np.tile(X[:, 2], (4, 1))))
    grown = {k: v for k, v in sigs().items() if v > before.get(k, 0)}
    assert not grown, (method, grown)
    assert np.array_equal(a.u, f(np.ascontiguousarray(X[:, 2])).u)
print("ok")
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600)
    assert out.returncode == 0 and out.stdout.strip().endswith("ok"), out.stderr[-3000:]


# ------------------------------------------------------------------ the first arguments
NOT_PROBLEMS = [({"B": [[1.0]], "umin": [-1.0], "umax": [1.0]}, "dict"), (None, "NoneType None"), ("ice", "str 'ice'"),
                (np.ones((3, 11)), "numpy.ndarray of shape (3, 11)"), (3.5, "float 3.5"), ([[1.0, 2.0]], "list"),
                (alloc.vehicles.problem("ice").B, "numpy.ndarray of shape (3, 11)")]
ENTRY_POINTS: dict[str, Callable[[object, object], object]] = {
    "make_allocator": lambda p, m: alloc.make_allocator(p, m),
    "Allocator": lambda p, m: alloc.Allocator(p, m),
    "allocate": lambda p, m: alloc.allocate(p, np.zeros(3), m),
    "allocate_batch": lambda p, m: alloc.allocate_batch(p, np.zeros((2, 3)), m),
}


@pytest.mark.parametrize("entry", sorted(ENTRY_POINTS))
@pytest.mark.parametrize(("value", "named"), NOT_PROBLEMS, ids=[n for _, n in NOT_PROBLEMS])
def test_a_problem_that_is_not_a_problem_is_a_named_type_error(entry: str, value: object, named: str) -> None:
    from alloc.exceptions import ProblemError, ProblemTypeError

    with pytest.raises(ProblemTypeError) as info:
        ENTRY_POINTS[entry](value, "pinv")
    err = info.value
    assert isinstance(err, TypeError) and isinstance(err, ProblemError) and isinstance(err, alloc.AllocError)
    assert err.field == "problem"
    assert str(err).startswith(f"problem: expected an alloc.Problem, got {named}")


@pytest.mark.parametrize("entry", sorted(ENTRY_POINTS))
@pytest.mark.parametrize("method", [3, None, b"qp", ["qp"], alloc.vehicles], ids=["int", "None", "bytes", "list", "module"])
def test_a_method_that_is_not_a_name_is_a_named_type_error(entry: str, method: object) -> None:
    from alloc.exceptions import MethodTypeError, UnknownMethodError

    with pytest.raises(MethodTypeError) as info:
        ENTRY_POINTS[entry](alloc.vehicles.problem("ice"), method)
    err = info.value
    assert isinstance(err, TypeError) and isinstance(err, UnknownMethodError)
    assert err.field == "method" and str(err).startswith(f"method: expected a method name (str), got {type(method).__name__}")
