"""History independence: a long-lived allocator returns what a fresh one returns.

For every registry method (and every backend of ``lp`` and ``da``), 1,000 mixed demands
(attainable and not, half of them with rate limits from a random previous command) are
allocated twice: by one allocator in sequence, and each by a fresh allocator (a deep copy
of one that was never called, which is a fresh build's state; built anew where the state
cannot be copied).  The answers agree to 1e-12.
"""

from __future__ import annotations

import copy
import zlib

import numpy as np
import pytest

import alloc
from alloc.testing import random_problem
from alloc.vehicles import ice

N_DEMANDS = 1000

VARIANTS = [(m, {}) for m in alloc.methods()]
VARIANTS += [("lp", {"backend": "highs"}), ("lp", {"backend": "daqp"}), ("da", {"backend": "daqp"}), ("da", {"backend": "highs"})]
VARIANTS += [("qp", {"backend": "daqp"}), ("wls", {"backend": "daqp"})]


def mixed_calls(p: alloc.Problem, n: int, seed: int):
    rng = np.random.default_rng(seed)
    U = rng.uniform(p.umin, p.umax, size=(n, p.m))
    V = U @ p.B.T
    V[n // 3:] *= rng.uniform(1.0, 3.0, size=(n - n // 3, 1))
    calls = []
    for i, v in enumerate(V):
        if i % 2:
            calls.append((v, dict(u_prev=rng.uniform(p.umin, p.umax), dt=float(rng.choice([0.005, 0.02, 0.1])))))
        else:
            calls.append((v, {}))
    return calls


def _fresh_factory(p, method, options):
    template = alloc.make_allocator(p, method, **options)
    try:  # the Problem is immutable: shared, not copied
        copy.deepcopy(template, {id(p): p})
    except (TypeError, ValueError, AttributeError, copy.Error):
        return lambda: alloc.make_allocator(p, method, **options)
    return lambda: copy.deepcopy(template, {id(p): p})


@pytest.mark.parametrize("method,options", VARIANTS, ids=[f"{m}-{o.get('backend', 'default')}" for m, o in VARIANTS])
def test_long_lived_equals_fresh(method, options):
    p = ice()
    if method == "lp":
        p = p.replace(Wv=np.diagonal(p.Wv))
    calls = mixed_calls(p, N_DEMANDS, seed=17)
    long_lived = alloc.make_allocator(p, method, **options)
    fresh = _fresh_factory(p, method, options)
    worst = 0.0
    for v, kw in calls:
        a = long_lived(v, **kw)
        b = fresh()(v, **kw)
        assert a.status == b.status
        worst = max(worst, float(np.abs(a.u - b.u).max()))
    assert worst <= 1e-12, f"{method} {options}: long-lived and fresh differ by {worst:.3g}"


@pytest.mark.parametrize("method", ["lp", "qp", "wls", "da"])
def test_long_lived_equals_fresh_random_problem(method):
    """The same on a random 4 x 10 problem with rate limits and weights (200 calls)."""
    p = random_problem(np.random.default_rng(4), 4, 10, "coplanar")
    p = p.replace(Wv=np.diagonal(p.Wv))
    calls = mixed_calls(p, 200, seed=5)
    long_lived = alloc.make_allocator(p, method)
    fresh = _fresh_factory(p, method, {})
    for v, kw in calls:
        np.testing.assert_allclose(long_lived(v, **kw).u, fresh()(v, **kw).u, rtol=0, atol=1e-12)


# ------------------------------------------------------------------ bit for bit, any layout
#: options beyond the defaults whose call paths differ (LP backends, the incremental
#: pseudo-inverse, cgi's level-by-level cascade)
LAYOUT_VARIANTS = VARIANTS + [("da", {"backend": "facet"}), ("pinv", {"incremental": True}),
                              ("pinv_scale", {"incremental": True}), ("cgi", {"priorities": "by axis"}),
                              ("qp", {"priorities": "by axis"}), ("lp", {"priorities": "by axis"})]
#: problems per variant, calls per problem
N_LAYOUT_PROBLEMS, N_LAYOUT_CALLS = 6, 4


def _misaligned(a: np.ndarray, offset: int) -> np.ndarray:
    """A copy of ``a`` that starts ``offset`` floats into a larger buffer (8-byte aligned only)."""
    buf = np.empty(a.size + offset + 1)
    out = buf[offset:offset + a.size]
    out[...] = a
    return out


def _strided(a: np.ndarray) -> np.ndarray:
    buf = np.empty(2 * a.size)
    buf[::2] = a
    return buf[::2]


def layout_problems(seed: int, n: int) -> list[alloc.Problem]:
    """Seeded problems that take every call path of the methods: full-rank and flat sets
    (k > m, rank-deficient B), jammed and one-sided effectors, ``up`` off zero, rate limits."""
    rng = np.random.default_rng(seed)
    out = []
    kinds = ["general", "rank_deficient", "jammed", "coplanar", "duplicate", "zero_column"]
    for i in range(n):
        k = int(rng.choice([1, 2, 3, 3, 4]))
        m = int(rng.integers(max(1, k - 1), 8))
        p = random_problem(rng, k, m, kinds[i % len(kinds)])
        if i % 3 == 0 and k > 1:  # k > rank: a flat attainable set
            B = np.array(p.B)
            B[-1] = 0.3 * B[0]
            p = p.replace(B=B)
        out.append(p)
    return out


def _layout_calls(p: alloc.Problem, rng: np.random.Generator, n: int):
    U = rng.uniform(p.umin, p.umax, size=(n, p.m))
    V = U @ p.B.T * rng.choice([0.5, 1.0, 3.0], size=(n, 1)) + 0.01 * rng.standard_normal((n, p.k))
    calls = []
    for i, v in enumerate(V):
        kw = {} if i % 2 == 0 else {"u_prev": rng.uniform(p.umin, p.umax), "dt": 0.02}
        calls.append((v, kw))
    return calls


def _answer(f, v, kw):
    r = f(v, **kw)
    return r.u.tobytes(), r.v_achieved.tobytes(), r.status


def _layouts(v: np.ndarray, kw: dict):
    """The same call with its arrays as given, misaligned by one float and strided."""
    yield "as given", v, kw
    for name, make in (("offset by one float", lambda a: _misaligned(a, 1)), ("strided", _strided)):
        yield name, make(v), {x: make(y) if isinstance(y, np.ndarray) else y for x, y in kw.items()}


@pytest.mark.parametrize("method,options", LAYOUT_VARIANTS,
                         ids=[f"{m}-{'-'.join(f'{a}={b}' for a, b in o.items()) or 'default'}" for m, o in LAYOUT_VARIANTS])
def test_answers_do_not_depend_on_memory_layout(method, options):
    """The original allocator, two deep copies, a copy and a pickle round trip (their arrays at
    other addresses) answer every call -- demand and ``u_prev`` as given, offset by one float
    in a larger buffer, and strided -- bit for bit, status included; the batch as well."""
    import pickle

    rng = np.random.default_rng(2212)
    for p in layout_problems(zlib.crc32(f"{method}{options}".encode()), N_LAYOUT_PROBLEMS):
        opts = {x: list(range(p.k, 0, -1)) if y == "by axis" else y for x, y in options.items()}
        try:
            f = alloc.make_allocator(p, method, **opts)
        except alloc.AllocError:
            continue  # an option this problem refuses (a backend, a size)
        twins = {"deepcopy": copy.deepcopy(f), "deepcopy 2": copy.deepcopy(f), "copy": copy.copy(f),
                 "pickle": pickle.loads(pickle.dumps(f))}
        calls = _layout_calls(p, rng, N_LAYOUT_CALLS)
        for v, kw in calls:
            want = _answer(f, v, kw)
            for name, vv, kk in _layouts(v, kw):
                assert _answer(f, vv, kk) == want, f"{method} {options}: {name} input differs on {p!r}"
            for name, twin in twins.items():
                assert _answer(twin, v, kw) == want, f"{method} {options}: {name} answers differ on {p!r}"
        V = np.array([v for v, _ in calls])
        want_b = f.batch(V)
        for name, twin in twins.items():
            got = twin.batch(_misaligned(V.ravel(), 1).reshape(V.shape))
            assert got.u.tobytes() == want_b.u.tobytes() and list(got.status) == list(want_b.status), \
                f"{method} {options}: {name} batch differs on {p!r}"


def test_da_table_deepcopy_answers_bit_for_bit_on_a_flat_set():
    """Hostile seed 30000408: on a flat set (k = 4 > m = 3) the search ran numpy products over
    the set's basis, a strided view in the original and a contiguous array in its deep copy,
    which round differently; the compiled flat search answers both bit for bit."""
    B = [[-2.005300279472917, -1.2441694943889845, 1.752706010801285],
         [-2.5568999761759126, -1.9995305738226383, 2.2351792790739173],
         [-1.980911506057848, -1.3408990484891268, 1.731485422915185],
         [1.2842195245986237, 1.6150645662880676, -1.1231579256306097]]
    umin = [-1.3562687775164036e48, -1.2103896882114235e47, -1.1041135561204125e47]
    umax = [1.493372969772889e48, 6.9068285472364255e47, 4.960878082633313e47]
    v = np.array([-3.252012546471413e48, -4.198935484037509e48, -3.226646326946874e48, 2.186397103164009e48])
    original = alloc.make_allocator(alloc.Problem(B, umin, umax), "da_table")
    for _ in range(4):  # copies land at other addresses
        twin = copy.deepcopy(original)
        assert original(v).u.tobytes() == twin(v).u.tobytes()


@pytest.mark.parametrize("method", ["da_facet", "da_bisect", "da_table"])
def test_flat_compiled_search_agrees_with_the_reference(method):
    """The compiled flat-set search (:func:`alloc.methods._facet_kernels.flat_ray_exit_solve`,
    in its own basis of the set's hull) against the numpy reference (``AttainableSet.ray_exit``
    in the set's basis), nominal and rate-limited, on seeded flat problems: the same status,
    ``u`` within 1e-9 of the box's span, ``B u`` within 1e-9 of its scale."""
    rng = np.random.default_rng(30000408)
    checked = 0
    for p in layout_problems(99, 30):
        f = alloc.make_allocator(p, method)
        impl = f.impl
        if getattr(impl, "_lp", None) is not None or not impl._flat:
            continue
        for v, kw in _layout_calls(p, rng, 8):
            lo, hi = p.effective_bounds(kw.get("u_prev"), kw.get("dt")) if kw else (p.umin, p.umax)
            u, it = impl.solve(v, lo, hi, None)
            ur, itr = impl._solve_reference(v, lo, hi, None)
            span = float(np.abs(hi - lo).max()) + 1e-300
            scale = float(np.abs(p.B).sum(axis=1).max()) * max(span, float(np.abs(u).max()))
            assert it == itr
            assert np.abs(u - ur).max() <= 1e-9 * span, (p, v, kw)
            assert np.abs(p.B @ (u - ur)).max() <= 1e-9 * scale
            checked += 1
    assert checked >= 40


def _kernel_signatures() -> dict[str, int]:
    """Compiled versions of every numba kernel loaded from the library."""
    import sys

    from numba.core.registry import CPUDispatcher

    out = {}
    for name, module in list(sys.modules.items()):
        if name.startswith("alloc") and module is not None:
            for attr, obj in vars(module).items():
                if isinstance(obj, CPUDispatcher):
                    out[f"{name}.{attr}"] = len(obj.signatures)
    return out


def test_a_round_tripped_allocator_compiles_nothing():
    """A deep copy's or a pickled allocator's arrays keep the types the kernels were compiled
    for (layout, dtype, writeability): after the original's calls, theirs compile no new
    version of any kernel (a compile is seconds inside a call).  Full-rank, flat and rank-0
    sets, nominal, rate-limited and batch calls, every method."""
    import pickle

    B = [[1.0, 0.5, -0.3, 0.2], [0.2, 1.0, 0.7, -0.5], [0.1, -0.4, 1.0, 0.3]]
    problems = [alloc.Problem(B, [-1] * 4, [1] * 4, rate_min=[-1] * 4, rate_max=[1] * 4),
                alloc.Problem(B + [[0.3, 0.15, -0.09, 0.06]], [-1] * 4, [1] * 4, rate_min=[-1] * 4, rate_max=[1] * 4),
                alloc.Problem(B, [0.5] * 4, [0.5] * 4, rate_min=[0.0] * 4, rate_max=[0.0] * 4)]

    def exercise(f, p):
        v = np.array([0.3, -0.2, 0.4, 0.1][:p.k])
        f(v)
        f(v, u_prev=np.full(p.m, 0.5), dt=0.01)
        f.batch(np.array([v, 2 * v]))

    for method in alloc.methods():
        for p in problems:
            f = alloc.make_allocator(p, method)
            exercise(f, p)
            exercise(f, p)
            before = _kernel_signatures()
            for twin in (copy.deepcopy(f), pickle.loads(pickle.dumps(f))):
                exercise(twin, p)
            after = _kernel_signatures()
            grown = {k: (before.get(k, 0), n) for k, n in after.items() if n > before.get(k, 0)}
            assert not grown, f"{method} on {p!r}: a round-tripped allocator compiled {grown}"


#: hostile seeds whose calls compiled a kernel the warm-up had not: the active set's own
#: solve after the fast path could not finish (dynamic 50002140, qp by priorities 50087490);
#: da's LP on a rank-deficient B (50000021) and its facet polish (50000077, 50000385)
COMPILED_IN_A_CALL = (50002140, 50087490, 50000021, 50000077, 50000385)


def test_no_call_compiles_after_the_warm_up():
    """After :func:`alloc._engine._jit_warm.warm` (what an install runs), the hostile suite's calls --
    the seeds above and 300 seeded cases of every method, input form and class -- compile no
    new version of any kernel (a compile is seconds inside a call)."""
    import os
    import sys
    import warnings

    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    import hostile
    from alloc._engine._jit_warm import warm

    warm()
    before = _kernel_signatures()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for seed in (*COMPILED_IN_A_CALL, *range(61_000_000, 61_000_300)):
            hostile.check(hostile.case(seed))
            after = _kernel_signatures()
            grown = {k: (before.get(k, 0), n) for k, n in after.items() if n > before.get(k, 0)}
            assert not grown, f"hostile seed {seed}: a call compiled {grown}"
