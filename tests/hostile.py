"""The standing adversarial suite: seeded hostile problems against the allocation contract.

``case(seed)`` draws one hostile case -- a problem (extreme and mixed scales, subnormals,
huge limits, all or some jammed, zero and duplicated columns, near-singular and
rank-deficient B, ill-conditioned and near-singular weights, k > m, zero rate limits), a
registry method with odd option values and types, and a few calls (demands from zero to the
domain's edge, ``u_prev`` outside the limits, tiny and huge ``dt``), sometimes with values
outside the valid input domain (NaN, 1e300, Python big integers, ragged arrays).  Drawn
from a second stream (so the classes above give the same cases as before), about one case
in ten also carries each of issue 22's classes: a non-real value (a Python big integer, a
complex number or array, a boolean or boolean array, a number as text, a numpy complex
scalar, a list nested up to 100,000 deep) in one field of the problem, one numeric option
or one call argument (``v``, ``u_prev``, ``dt``, a batch's ``V``), which must be refused
naming exactly that field; health-API abuse (failure events with hostile effectors, kinds
and parameters, health records with limits wider than the nominal ones and text for
booleans, their JSON form); and a pickle, copy or deep-copy round trip of the problem, the
allocator and its results.

``check(case)`` builds and calls it and returns the contract violations (empty when it
holds): only ``AllocError``/``TypeError`` may escape, with the field named; every ``u``
finite and within the call's bounds; ``v_achieved = B u`` finite; status ``exact`` iff
``B u = v`` within tolerance; the result owns read-only arrays; ``allocate_batch`` equals
the single calls; no call costs more than ``CALL_LIMIT`` CPU seconds (or its method's
declared call cost, if larger) and no build more than ``BUILD_LIMIT`` (CPU seconds of the
calling thread, the registry's unit; wall-clock limits, ``CALL_WALL_LIMIT`` and
``BUILD_WALL_LIMIT``, are only a backstop against waiting and hangs).  With issue 22's
classes: a non-real value is never accepted; the health API raises only ``AllocError``
naming a health field, a failed problem never leaves the nominal limits, rate limits or
effectiveness, and health round-trips through JSON; a round-tripped allocator answers every
call and the batch bit for bit as the original, and round-tripped results are read-only.

``run(seeds, workers)`` runs cases in watchdog subprocesses (a hang that holds the GIL
cannot be interrupted from a thread): a case that does not answer within its budget is a
hang, the worker is killed and restarted.  ``shrink(case)`` reduces a failing case to a
minimal one (fewer calls, effectors, axes, options; simpler numbers) that still fails.

Command line (the large run recorded in the docs; seeds ``S .. S + N - 1``)::

    python tests/hostile.py --cases 100000 --workers 2 [--seed 0] [--json report.json]
"""

from __future__ import annotations

import argparse
import json
import math
import multiprocessing as mp
import re
import sys
import time
import traceback
from collections import Counter
from typing import Any

import numpy as np

DEADLINE: float | None = None  # epoch seconds: the command line's --minutes stops taking cases
# Time is checked as the registry promises it: CPU seconds of the calling thread
# (``time.thread_time``: the case's own work, whatever else the machine runs; a single call
# and a build run on the caller's thread, and at these sizes BLAS does not start threads of
# its own; ``process_time`` would also count the solver libraries' idle pools and costs
# milliseconds a read in a process with many threads), with wall-clock limits only as a
# backstop for calls that wait instead of compute (a lock never released, a hang).
#: CPU seconds: a call costing more than this, or more than its method's declared
#: ``Method.call_cost`` where that is larger, is a failure (a case is at most 6 x 12, where
#: the declared costs are milliseconds; :data:`alloc.registry.CALL_LIMIT_SECONDS` bounds them
#: at the size caps)
CALL_LIMIT = 1.0
#: CPU seconds: a build costing more than this is a failure (the registry refuses or
#: redirects builds declared beyond :data:`alloc.registry.BUILD_LIMIT_SECONDS`, 20 s)
BUILD_LIMIT = 30.0
#: wall seconds: the backstops (a case's watchdog budget is built from them)
CALL_WALL_LIMIT, BUILD_WALL_LIMIT = 20.0, 120.0
PROBLEM_FIELDS = ("B", "umin", "umax", "up", "Wu", "Wv", "rate_min", "rate_max", "names", "axes")
DEMAND_FIELDS = ("v", "u_prev", "dt", "V")
#: batch row vs single call, relative to the moments' scale: vectorised arithmetic differs
#: from the compiled single call only in rounding order
BATCH_RTOL = 1e-9


# ----------------------------------------------------------------------------- generator
def _scale(rng: np.random.Generator) -> float:
    return float(rng.choice([1.0, 1.0, 1.0, 1e-3, 1e3, 1e-12, 1e12, 1e-40, 1e40, 1e48, 1e-300]))


def _matrix_B(rng: np.random.Generator, k: int, m: int) -> np.ndarray:
    kind = rng.integers(10)
    B = rng.standard_normal((k, m))
    if kind == 1:  # extreme scale
        B *= _scale(rng)
    elif kind == 2:  # mixed column scales, subnormals included
        B *= np.array([_scale(rng) for _ in range(m)])[None, :]
        B[:, rng.random(m) < 0.2] = 5e-324
    elif kind == 3:  # zero and duplicated columns
        B[:, rng.random(m) < 0.3] = 0.0
        if m > 1:
            B[:, -1] = B[:, 0]
    elif kind == 4:  # near-singular: rank r < k plus a tiny perturbation
        r = int(rng.integers(1, k + 1))
        B = rng.standard_normal((k, r)) @ rng.standard_normal((r, m)) + rng.choice([0, 1e-9, 1e-14]) * B
    elif kind == 5:  # singular values spread down to 1e-9 (the 6x6 case)
        U, _, Vt = np.linalg.svd(rng.standard_normal((k, m)), full_matrices=False)
        B = (U * np.logspace(0, -9, min(k, m))) @ Vt
    elif kind == 6:  # nearly rank-1 (coplanar beyond tolerance)
        B = np.outer(rng.standard_normal(k), rng.standard_normal(m)) + 1e-12 * B
    elif kind == 7:  # integer-valued, sparse (coplanar columns)
        B = rng.integers(-2, 3, size=(k, m)).astype(float)
    elif kind == 8:
        B *= np.array([_scale(rng) for _ in range(k)])[:, None]  # mixed row scales
    return B


def _weight(rng: np.random.Generator, n: int) -> Any:
    kind = rng.integers(6)
    if kind <= 1:
        return None
    if kind == 2:  # diagonal over a wide range
        return (10.0 ** rng.uniform(-40, 40, n)).tolist()
    if kind == 3:  # ill-conditioned full SPD
        Q, _ = np.linalg.qr(rng.standard_normal((n, n)))
        W = (Q * 10.0 ** rng.uniform(-6, 6, n)) @ Q.T
        return ((W + W.T) / 2).tolist()
    if kind == 4:  # near-singular full (eigenvalue at the domain's edge or below)
        Q, _ = np.linalg.qr(rng.standard_normal((n, n)))
        lam = np.ones(n)
        lam[0] = float(rng.choice([1e-8, 1e-12, 1e-60]))
        W = (Q * lam) @ Q.T
        return ((W + W.T) / 2).tolist()
    return rng.uniform(0.1, 10.0, n).tolist()


def _limits(rng: np.random.Generator, m: int) -> tuple[np.ndarray, np.ndarray]:
    kind = rng.integers(6)
    lo = -rng.uniform(0.1, 2.0, m)
    hi = rng.uniform(0.1, 2.0, m)
    if kind == 1:
        s = float(rng.choice([1e10, 1e30, 1e48]))
        lo, hi = lo * s, hi * s
    elif kind == 2:  # all jammed
        lo = hi = rng.uniform(-1, 1, m)
    elif kind == 3:  # some jammed
        j = rng.random(m) < 0.4
        hi = np.where(j, lo, hi)
    elif kind == 4:  # one-sided
        lo = np.where(rng.random(m) < 0.5, 0.0, lo)
    elif kind == 5:  # tiny
        lo, hi = lo * 1e-30, hi * 1e-30
    return lo, np.maximum(lo, hi)


def _option(rng: np.random.Generator, name: str, k: int, m: int, backends: list[str], lp: list[str],
            method: str = "") -> Any:
    """A value for option ``name``: usually valid (80 %), otherwise of the wrong value or type."""
    if rng.random() < 0.8:
        valid = {"rcond": [0.0, 1e-12, 1e-6, 0.5, 0.999999], "incremental": [True, False],
                 "gamma": [1e-8, 1e-4, 1.0, 1e6], "angles": [1, 2, 3, 16, 100],
                 "max_rounds": [1, 2, 40, 1000], "resolution": [2, 3, 16, 64]}
        if name in valid:
            return valid[name][int(rng.integers(len(valid[name])))]
        if name == "priorities":
            return [[float(x) for x in rng.uniform(-1e6, 1e6, k)], [int(x) for x in rng.integers(0, 3, k)],
                    [[1e20, 2**63, 2**70, -1e300, 1, 0.5][int(i)] for i in rng.integers(0, 6, k)]][int(rng.integers(3))]
        if name == "backend":
            ok = {"da": lp + ["auto", "facet"], "lp": lp}.get(method, [b for b in backends if b != "highs"])
            return str(rng.choice(ok))
    if name == "rcond":
        return rng.choice(np.array([0.0, 1e-12, 1e-6, 0.5, 0.999999, 2.0, -5, "x", math.nan, True], dtype=object))
    if name == "incremental":
        return rng.choice(np.array([True, False, "x"], dtype=object))
    if name == "priorities":
        kind = rng.integers(7)
        if kind == 0:
            return [float(x) for x in rng.uniform(-1e6, 1e6, k)]
        if kind == 1:
            return [int(x) for x in rng.integers(0, 3, k)]
        if kind == 2:
            return [[1e20, 2**63, 2**70, -1e300, 1, 0.5][int(i)] for i in rng.integers(0, 6, k)]
        if kind == 3:
            return [1.0] * (k + 1)
        if kind == 4:
            return [math.nan] * k
        if kind == 5:
            return "ab"
        return list(range(k))
    if name == "groups":
        perm = [int(x) for x in rng.permutation(m)]
        n = int(rng.integers(1, m + 1))
        cuts = sorted(set(int(x) for x in rng.integers(1, m + 1, n - 1))) if n > 1 else []
        groups: list[Any] = [perm[a:b] for a, b in zip([0] + cuts, cuts + [m]) if b > a]
        kind = rng.integers(8)
        if kind == 0:
            groups[0] = groups[0] + [1.7]
        elif kind == 1:
            groups = [[math.nan]]
        elif kind == 2:
            groups = [[f"u{j}" for j in g] for g in groups]
        elif kind == 3:
            groups = groups + [[perm[0]]]
        elif kind == 4:
            groups = [[]]
        return groups
    if name == "G":
        kind = rng.integers(4)
        if kind == 0:
            return rng.standard_normal((m, k)).tolist()
        if kind == 1:
            return (rng.standard_normal((m, k)) * 1e300).tolist()
        if kind == 2:
            return rng.standard_normal((k, m)).tolist()
        return None
    if name == "backend":
        return str(rng.choice(backends + lp + ["auto", "facet", "nope"]))
    if name == "gamma":
        return rng.choice(np.array([1e-8, 1e-4, 1.0, 1e6, 0.0, -1.0, "x", math.nan, 1e300], dtype=object))
    if name in ("angles", "max_rounds", "resolution"):
        return rng.choice(np.array([1, 2, 3, 16, 100, 0, True, 2.5, 10**9], dtype=object))
    return None


def _demand(rng: np.random.Generator, B: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> Any:
    k = B.shape[0]
    kind = rng.integers(12)
    if kind <= 3:  # attainable
        return (B @ rng.uniform(lo, hi)).tolist()
    if kind == 4:
        return [0.0] * k
    if kind == 5:
        return (rng.standard_normal(k) * float(rng.choice([1e-300, 1e-12, 1e12, 1e45, 1e49]))).tolist()
    if kind == 6:
        return (B @ rng.uniform(lo, hi) * float(rng.choice([2.5, 100.0, 1e10]))).tolist()
    if kind == 7:  # outside the valid domain
        bad = [math.nan, math.inf, 1e300, 10**400, "x"]
        v = rng.standard_normal(k).tolist()
        v[int(rng.integers(k))] = bad[int(rng.integers(len(bad)))]
        return v
    if kind == 8:  # wrong shape or ragged
        return [[1.0], [2.0, 3.0]] if rng.random() < 0.5 else [1.0] * (k + 1)
    if kind == 9:  # Python big integers inside the domain
        return [int(x) * 10**20 for x in rng.integers(-3, 4, k)]
    return rng.standard_normal(k).tolist()


def case(seed: int) -> dict[str, Any]:
    """One hostile case (pure data: lists, numbers, strings), reproducible from ``seed``."""
    import alloc
    from alloc.solvers import backends

    rng = np.random.default_rng(seed)
    methods = alloc.methods()
    method = methods[seed % len(methods)]
    k = int(rng.choice([1, 2, 3, 3, 3, 4, 5, 6]))
    m = int(rng.integers(1, 13))
    B = _matrix_B(rng, k, m)
    lo, hi = _limits(rng, m)
    fields: dict[str, Any] = {"B": B.tolist(), "umin": lo.tolist(), "umax": hi.tolist()}
    if rng.random() < 0.3:
        fields["up"] = rng.uniform(lo, hi).tolist()
    if rng.random() < 0.5:
        fields["Wu"] = _weight(rng, m)
    if rng.random() < 0.4:
        fields["Wv"] = _weight(rng, k)
    if rng.random() < 0.4:
        kind = rng.integers(4)
        rmin = -rng.uniform(0, 5, m)
        rmax = rng.uniform(0, 5, m)
        if kind == 0:
            rmin = rmax = np.zeros(m)
        rmin_l: list[Any] = rmin.tolist()
        rmax_l: list[Any] = rmax.tolist()
        if kind == 1:
            rmin_l[0], rmax_l[-1] = None, None  # JSON null: no limit
        fields["rate_min"], fields["rate_max"] = rmin_l, rmax_l
    if rng.random() < 0.05:  # outside the domain: one hostile number or structure
        field = str(rng.choice(["B", "umin", "umax", "Wu"]))
        bad = [1e300, 10**400, math.nan, "x", [[1.0], [1.0, 2.0]]][int(rng.integers(5))]
        if field == "B":
            fields["B"] = [list(r) for r in fields["B"]]
            fields["B"][0][0] = bad
        elif field == "Wu":
            fields["Wu"] = bad if isinstance(bad, list) else [bad] + [1.0] * (m - 1)
        else:
            fields[field] = [bad] + list(fields[field][1:])
    info = alloc.method_info(method)
    options = {}
    for name in info["options"]:
        if rng.random() < 0.6:
            options[name] = _option(rng, name, k, m, backends(), backends(lp=True), method)
            if isinstance(options[name], np.generic):
                options[name] = options[name].item()
    calls = []
    for _ in range(int(rng.integers(1, 5))):
        call: dict[str, Any] = {"v": _demand(rng, B, lo, hi)}
        if rng.random() < 0.35:
            span = np.maximum(hi - lo, 1.0)
            call["u_prev"] = (rng.uniform(lo, hi) + rng.choice([0.0, 0.0, 3.0]) * span).tolist()
            call["dt"] = float(rng.choice([0.01, 1e-300, 1e-9, 1.0, 1e40, 0.0, -1.0]))
        calls.append(call)
    c = {"seed": seed, "method": method, "fields": fields, "options": options, "calls": calls}
    _boundary_classes(np.random.default_rng([seed, 22]), c, B, lo, hi)
    return c


# ------------------------------------------------------------------ issue 22's classes
#: what a non-real value is, by kind, as case data (``$array``/``$scalar`` are decoded by
#: :func:`decode` into numpy objects when the case runs, so a case stays comparable data)
NON_REAL = ("big int", "complex", "complex array", "bool", "bool array", "text", "numpy complex", "deeply nested")
#: share of cases carrying each class
P_NON_REAL, P_HEALTH, P_ROUND_TRIP = 0.10, 0.10, 0.10
HEALTH_FIELDS = ("effector", "kind", "position", "fraction", "lo", "hi", "rate_min", "rate_max", "limits",
                 "rate_limits", "jam_position", "floating", "effectiveness", "health", "event")


def _non_real(rng: np.random.Generator, kind: str, like: Any) -> Any:
    """``like`` (a number or a nested list) made non-real in the way ``kind`` says."""
    def first(x: Any, value: Any) -> Any:  # replace the first scalar of a nested list
        if isinstance(x, list):
            return [first(x[0], value)] + x[1:] if x else [value]
        return value

    def num(x: Any) -> float:
        while isinstance(x, list):
            x = x[0] if x else 0.0
        return 0.0 if x is None else float(x)

    base = like if like is not None else 0.0
    if kind == "big int":
        return first(base, int(rng.choice([1, -1])) * 10 ** int(rng.choice([309, 400, 4000])))
    if kind == "complex":
        return first(base, complex(num(base), float(rng.choice([0.0, 1e-300, 1.0]))))
    if kind == "bool":
        return first(base, bool(rng.random() < 0.5))
    if kind == "text":
        return first(base, str(num(base)))
    if kind == "numpy complex":
        return {"$scalar": "complex128", "value": num(base)}
    if kind == "deeply nested":  # built when the case runs (pickle and repr recurse on it)
        return {"$deep": int(rng.choice([100, 10_000, 100_000])), "value": num(base)}
    dtype = "complex128" if kind == "complex array" else "bool"
    return {"$array": dtype, "data": base if isinstance(base, list) else [base]}


def decode(x: Any) -> Any:
    """A case value with its ``$array``/``$scalar`` markers turned into numpy objects."""
    if isinstance(x, dict) and "$array" in x:
        return np.array(x["data"], dtype=x["$array"])
    if isinstance(x, dict) and "$scalar" in x:
        return np.dtype(x["$scalar"]).type(x["value"])
    if isinstance(x, dict) and "$deep" in x:
        nested: Any = [x["value"]]
        for _ in range(x["$deep"]):
            nested = [nested]
        return nested
    if isinstance(x, dict):
        return {key: decode(val) for key, val in x.items()}
    if isinstance(x, list):
        return [decode(v) for v in x]
    return x


def _boundary_classes(rng: np.random.Generator, c: dict[str, Any], B: np.ndarray, lo: np.ndarray,
                      hi: np.ndarray) -> None:
    """Add issue 22's classes to case ``c``: a non-real value in one field (which must be
    refused naming that field), health-API abuse, a pickle/copy round trip."""
    import alloc.registry

    k, m = B.shape
    if rng.random() < P_NON_REAL:
        kind = str(rng.choice(NON_REAL))
        spec = alloc.registry.get_method(c["method"]).options
        numeric = [n for n, o in spec.items() if o.type in ("float", "int", "matrix", "weight")]
        where = str(rng.choice(["problem", "option", "call"] if numeric else ["problem", "call"]))
        clean = {"B": B.tolist(), "umin": lo.tolist(), "umax": hi.tolist()}  # within the domain by construction
        if where == "problem":
            field = str(rng.choice(["B", "umin", "umax", "up", "Wu", "Wv", "rate_min", "rate_max"]))
            base = {"up": np.clip(0.0, lo, hi).tolist(), "Wu": [1.0] * m, "Wv": [1.0] * k,
                    "rate_min": [-1.0] * m, "rate_max": [1.0] * m, **clean}[field]
            if kind == "numpy complex":
                kind = "complex array"
            c["fields"] = {**clean, field: _non_real(rng, kind, base)}
            if field in ("rate_min", "rate_max"):
                other = "rate_max" if field == "rate_min" else "rate_min"
                c["fields"][other] = [1.0 if other == "rate_max" else -1.0] * m
            c["hostile"] = {"where": "problem", "field": field, "kind": kind}
        elif where == "option":
            name = str(rng.choice(numeric))
            typ = spec[name].type
            base: Any = {"float": 0.5, "int": 4, "matrix": np.zeros((m, k)).tolist(), "weight": 1.0}[typ]
            if kind in ("complex array", "bool array") and typ in ("float", "int"):
                kind = "numpy complex"
            c["fields"], c["options"] = clean, {name: _non_real(rng, kind, base)}
            c["hostile"] = {"where": "option", "field": name, "kind": kind}
        else:
            field = str(rng.choice(["v", "u_prev", "dt", "V"]))
            v0 = B @ rng.uniform(lo, hi)
            v0 = (v0 if np.abs(v0).max() <= 1e49 else np.zeros(k)).tolist()  # the other fields stay valid
            call: dict[str, Any] = {"v": v0}
            if field in ("u_prev", "dt"):
                call["u_prev"], call["dt"] = np.clip(0.0, lo, hi).tolist(), 0.01
            if field == "V":
                c["batch_V"] = _non_real(rng, kind, [v0, v0])
            else:
                if field == "dt" and kind in ("complex array", "bool array"):
                    kind = "numpy complex"
                call[field] = _non_real(rng, kind, call[field])
                call["hostile"] = field
                c["calls"] = c["calls"] + [call]
            c["fields"] = clean
            c["hostile"] = {"where": "call", "field": field, "kind": kind}
    if rng.random() < P_HEALTH:
        c["health"] = _health_abuse(rng, lo, hi, m)
    if rng.random() < P_ROUND_TRIP:
        c["round_trip"] = str(rng.choice(["pickle", "copy", "deepcopy"]))


def case_classes(c: dict[str, Any]) -> list[str]:
    """Issue 22's classes case ``c`` carries (for the report's counts)."""
    out = [f"non-real {c['hostile']['where']}"] if "hostile" in c else []
    return out + [name for key, name in (("health", "health API"), ("round_trip", "round trip")) if key in c]


def _health_value(rng: np.random.Generator, good: float) -> Any:
    """A health parameter: usually ``good``, otherwise a hostile number or type."""
    if rng.random() < 0.75:
        return good
    return [10**400, -(10**400), 1j, "abc", math.nan, math.inf, True, None, [good], 1e300][int(rng.integers(10))]


def _health_abuse(rng: np.random.Generator, lo: np.ndarray, hi: np.ndarray, m: int) -> dict[str, Any]:
    """Failure events (some hostile), direct health records (wider limits, strings for
    booleans) and a JSON health document for :func:`alloc.health.health_from_dict`."""
    kinds = ["jam", "hardover", "float", "effectiveness", "limits", "rate_limits", "repair"]
    events = []
    for _ in range(int(rng.integers(1, 5))):
        j = int(rng.integers(m))
        kind = str(rng.choice(kinds + ["melted"])) if rng.random() < 0.95 else "melted"
        effector: Any = j if rng.random() < 0.8 else [f"u{j}", 10**400, True, [j], m + 3, -1][int(rng.integers(6))]
        a, b = sorted(rng.uniform(lo[j], hi[j], 2).tolist())
        span = max(float(hi[j] - lo[j]), 1.0)
        if rng.random() < 0.2:  # outside the nominal limits: refused by apply_event
            a, b = a - 2 * span, b + 2 * span
        ev: dict[str, Any] = {"effector": effector, "kind": kind}
        if kind in ("jam", "hardover"):
            ev["position"] = _health_value(rng, float(rng.uniform(lo[j], hi[j])))
        elif kind == "effectiveness":
            ev["fraction"] = _health_value(rng, float(rng.choice([0.0, 0.3, 1.0, 1.5])))
        elif kind == "limits":
            ev["lo"], ev["hi"] = _health_value(rng, a), _health_value(rng, b)
        elif kind == "rate_limits":
            ev["rate_min"], ev["rate_max"] = _health_value(rng, -float(rng.uniform(0, 2))), _health_value(rng, 1.0)
        events.append(ev)
    j = int(rng.integers(m))
    span = max(float(hi[j] - lo[j]), 1.0)
    record = {"effectiveness": _health_value(rng, float(rng.uniform(0, 1))),
              "limits": [float(lo[j] - span * rng.choice([0, 0.5, 3])), float(hi[j] + span * rng.choice([0, 0.5, 3]))],
              "rate_limits": [-float(rng.uniform(0, 3)), float(rng.uniform(0, 3))],
              "floating": [False, False, "false", "true", 0, 1, None][int(rng.integers(7))]}
    if rng.random() < 0.3:
        record["jam_position"] = _health_value(rng, float(rng.uniform(lo[j], hi[j])))
    if rng.random() < 0.1:
        record["colour"] = "red"
    if record["floating"] is None:
        del record["floating"]
    return {"events": events, "record_effector": j, "record": record}


# ----------------------------------------------------------------------------- contract
def _names_field(exc: BaseException, fields: tuple[str, ...]) -> bool:
    msg = str(exc)
    return any(re.search(rf"(^|[\s:(\[]){re.escape(f)}([\s:\[\]/=(]|$)", msg) for f in fields)


def _honest(B: np.ndarray, r: Any, v: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> list[str]:
    """Violations of the result contract for one call (empty when it holds)."""
    from alloc.result import EXACT_RTOL

    bad = []
    u, va = r.u, r.v_achieved
    if u.shape != lo.shape or not np.isfinite(u).all():
        return [f"non-finite or misshapen u {u!r}"]
    if (u < lo).any() or (u > hi).any():
        return [f"inadmissible u: violation {max((lo - u).max(), (u - hi).max()):g}"]
    if not (np.isfinite(va).all() and np.isfinite(r.unallocated).all()):
        return ["non-finite v_achieved or unallocated"]
    Bu = B @ u
    scale = np.abs(B) @ np.abs(u) + 1e-300
    if (np.abs(Bu - va) > 1e-9 * scale + 1e-300).any():
        bad.append("v_achieved != B u")
    if not np.array_equal(r.v, v):
        bad.append("result's v is not the demand")
    for a in (r.u, r.v, r.v_achieved):
        if a.flags.writeable:
            bad.append("result array is writeable")
            break
    err = float(np.abs(Bu - v).max())
    tol = EXACT_RTOL * max(1.0, float(np.abs(v).max()))
    # round-off margin: B u evaluated by BLAS here and by the compiled kernel there
    margin = 1e-9 * float(scale.max()) + 1e-12 * tol
    if r.status.value == "exact" and not err <= tol + margin:
        bad.append(f"dishonest exact: |Bu - v| = {err:g} > {tol:g}")
    if r.status.value == "unattainable" and not err > tol - margin:
        bad.append(f"dishonest unattainable: |Bu - v| = {err:g} <= {tol:g}")
    return bad


def check(c: dict[str, Any]) -> dict[str, Any]:
    """Run case ``c``; ``{"fail": [...], "status": {...}, "refused": str}``."""
    import alloc
    from alloc.exceptions import AllocError

    out: dict[str, Any] = {"fail": [], "status": Counter(), "refused": ""}
    fail = out["fail"]
    hostile = c.get("hostile")

    def refused_right(stage: str, exc: BaseException, fields: tuple[str, ...]) -> None:
        """A refusal at ``stage``: it must name the case's non-real field when it has one there."""
        if hostile is not None and hostile["where"] == stage:
            fields = (hostile["field"],)
        if not _names_field(exc, fields):
            fail.append(f"{stage} error names no field: {type(exc).__name__}: {exc}")

    try:
        p = alloc.Problem(**decode(c["fields"]))
    except (AllocError, TypeError) as exc:
        refused_right("problem", exc, PROBLEM_FIELDS + ("umin/umax",))
        out["refused"] = "problem"
        return out
    except Exception as exc:  # noqa: BLE001 - the contract under test
        fail.append(f"escaped at Problem: {type(exc).__name__}: {exc}")
        return out
    if hostile is not None and hostile["where"] == "problem":
        fail.append(f"accepted a {hostile['kind']} value in {hostile['field']}")
        return out
    d = p.to_dict()
    if alloc.Problem(**d).to_dict() != d:
        fail.append("to_dict -> Problem(**d) does not round-trip")
    if "round_trip" in c:
        fail.extend(_problem_round_trip(p, c["round_trip"]))
    if "health" in c:
        p = _apply_health(p, c["health"], fail)
        if p is None:
            return out
    t0, c0 = time.perf_counter(), time.thread_time()
    try:
        f = alloc.make_allocator(p, c["method"], **decode(c["options"]))
    except (AllocError, TypeError) as exc:
        refused_right("option", exc, tuple(c["options"]) + PROBLEM_FIELDS)
        out["refused"] = "options"
        return out
    except Exception as exc:  # noqa: BLE001
        fail.append(f"escaped at build: {type(exc).__name__}: {exc}\n{traceback.format_exc(limit=-3)}")
        return out
    build_cpu, build_wall = time.thread_time() - c0, time.perf_counter() - t0
    if build_cpu > BUILD_LIMIT or build_wall > BUILD_WALL_LIMIT:
        fail.append(f"slow build: {build_cpu:.2f} CPU s, {build_wall:.2f} s wall")
    if hostile is not None and hostile["where"] == "option":
        fail.append(f"accepted a {hostile['kind']} value in option {hostile['field']}")
        return out
    call_limit = max(CALL_LIMIT, _declared_call_cost(p, c["method"], decode(c["options"])))
    twin = None
    if "round_trip" in c:
        twin = _allocator_round_trip(f, c["round_trip"], fail)
    singles = []
    for call in c["calls"]:
        kw = {x: decode(call[x]) for x in ("u_prev", "dt") if x in call}
        if "hostile" in call:
            v_in = decode(call["v"])
        else:
            v_in = np.array(call["v"], dtype=float) if _plain(call["v"]) else call["v"]
        t0, c0 = time.perf_counter(), time.thread_time()
        try:
            r = f(v_in, **kw)
        except (AllocError, TypeError) as exc:
            fields = (call["hostile"],) if "hostile" in call else DEMAND_FIELDS + ("u_prev/dt",)
            if not _names_field(exc, fields):
                fail.append(f"call error names no field: {type(exc).__name__}: {exc}")
            continue
        except Exception as exc:  # noqa: BLE001
            fail.append(f"escaped at call: {type(exc).__name__}: {exc}\n{traceback.format_exc(limit=-3)}")
            continue
        cpu, wall = time.thread_time() - c0, time.perf_counter() - t0
        if cpu > call_limit or wall > CALL_WALL_LIMIT:
            fail.append(f"slow call: {cpu:.2f} CPU s (limit {call_limit:.2g}), {wall:.2f} s wall")
        if "hostile" in call:
            fail.append(f"accepted a non-real value in {call['hostile']}: {str(call[call['hostile']])[:80]}")
            continue
        if twin is not None:
            fail.extend(_twin_agrees(twin, r, v_in, kw, c["round_trip"]))
        v = np.asarray(r.v)
        lo, hi = p.effective_bounds(kw.get("u_prev"), kw.get("dt")) if kw else (p.umin, p.umax)
        snapshot = (r.u.copy(), r.v.copy())
        if isinstance(v_in, np.ndarray):
            v_in[...] = 99.0  # the caller reuses its array: the result must not change
            if not (np.array_equal(r.u, snapshot[0]) and np.array_equal(r.v, snapshot[1])):
                fail.append("result changed when the caller's demand array changed")
        fail.extend(_honest(p.B, r, v, lo, hi))
        out["status"][r.status.value] += 1
        if r.status.value == "fallback":
            out.setdefault("messages", []).append(r.message[:120])
        if not kw:
            singles.append(r)
    if "batch_V" in c:
        try:
            f.batch(decode(c["batch_V"]))
        except (AllocError, TypeError) as exc:
            if not _names_field(exc, ("V",)):
                fail.append(f"batch error names no field: {type(exc).__name__}: {exc}")
        except Exception as exc:  # noqa: BLE001
            fail.append(f"escaped at batch: {type(exc).__name__}: {exc}")
        else:
            fail.append(f"accepted a non-real value in V: {str(c['batch_V'])[:80]}")
    if singles:
        # Batch equals single, on the same long-lived allocator after its single calls (so
        # this also checks that answers do not depend on call history).
        V = np.array([r.v for r in singles])
        try:
            br = f.batch(V)
        except Exception as exc:  # noqa: BLE001 - valid demands: batch must not raise
            fail.append(f"escaped at batch: {type(exc).__name__}: {exc}")
        else:
            fail.extend(_batch_equals_single(p.B, br, singles))
            if twin is not None:
                tb = twin.batch(V)
                if not (tb.u.tobytes() == br.u.tobytes() and list(tb.status) == list(br.status)):
                    fail.append(f"round trip ({c['round_trip']}): batch differs from the original's")
    return out


def _declared_call_cost(p: Any, method: str, options: dict[str, Any]) -> float:
    """The method's declared worst-case CPU seconds per call (:meth:`alloc.registry.Method.call_cost`)."""
    import alloc.registry

    return float(alloc.registry.get_method(method).call_cost(p, **options))


def _trip(how: str) -> Any:
    import copy
    import pickle

    return {"pickle": lambda x: pickle.loads(pickle.dumps(x)), "copy": copy.copy, "deepcopy": copy.deepcopy}[how]


def _problem_round_trip(p: Any, how: str) -> list[str]:
    q = _trip(how)(p)
    arrays = ("B", "umin", "umax", "up", "Wu", "Wv", "rate_min", "rate_max")
    bad = [f"round trip ({how}): Problem.{a} differs" for a in arrays
           if getattr(p, a).tobytes() != getattr(q, a).tobytes()]
    bad += [f"round trip ({how}): Problem.{a} writeable" for a in arrays if getattr(q, a).flags.writeable]
    if (q.names, q.axes) != (p.names, p.axes):
        bad.append(f"round trip ({how}): Problem names differ")
    return bad


def _allocator_round_trip(f: Any, how: str, fail: list[str]) -> Any:
    """``f`` after ``how`` (``None`` when that fails: a failure of the case)."""
    try:
        return _trip(how)(f)
    except Exception as exc:  # noqa: BLE001 - every allocator pickles (protocol >= 2)
        fail.append(f"round trip ({how}) of the allocator failed: {type(exc).__name__}: {exc}\n"
                    f"{traceback.format_exc(limit=-3)}")
        return None


def _twin_agrees(twin: Any, r: Any, v_in: Any, kw: dict[str, Any], how: str) -> list[str]:
    """The round-tripped allocator answers ``v_in`` bit for bit as the original did; the
    result itself round-trips with read-only arrays."""
    try:
        t = twin(v_in, **kw)
    except Exception as exc:  # noqa: BLE001
        return [f"round trip ({how}): the copy raised {type(exc).__name__}: {exc}"]
    bad = []
    if not (t.u.tobytes() == r.u.tobytes() and t.v_achieved.tobytes() == r.v_achieved.tobytes()
            and t.status is r.status):
        bad.append(f"round trip ({how}): answer differs from the original's ({r.status.value} -> {t.status.value})")
    rr = _trip(how)(r)
    if any(a.flags.writeable for a in (rr.u, rr.v, rr.v_achieved, rr.unallocated)):
        bad.append(f"round trip ({how}): result array writeable")
    if rr.u.tobytes() != r.u.tobytes() or rr.status is not r.status:
        bad.append(f"round trip ({how}): result differs")
    return bad


def _apply_health(p: Any, h: dict[str, Any], fail: list[str]) -> Any:
    """Apply case ``h``'s events and records to ``p``; the failed problem, or ``None``.

    Every refusal is a ProblemError naming a health field; the failed problem keeps within
    the nominal one (limits, rate limits, effectiveness <= 1) and its health round-trips
    through JSON."""
    from alloc.exceptions import AllocError
    from alloc.health import EffectorHealth, FailureEvent, apply_event, health_from_dict, health_to_dict

    def refused(stage: str, exc: BaseException) -> None:
        if stage == "record" and type(exc) is TypeError and "unexpected keyword argument" in str(exc):
            return  # a constructor given an unknown field: Python's own TypeError names it
        if not isinstance(exc, AllocError):
            fail.append(f"health {stage} escaped: {type(exc).__name__}: {exc}")
        elif not _names_field(exc, HEALTH_FIELDS):
            fail.append(f"health {stage} error names no field: {exc}")

    health: dict[str, Any] = {}
    for ev in h["events"]:
        try:
            _, health = apply_event(p, health, FailureEvent(**ev))
        except Exception as exc:  # noqa: BLE001 - the contract under test
            refused("event", exc)
    name = p.names[h["record_effector"]]
    for stage, make in (("record", lambda: EffectorHealth(**h["record"])),
                        ("from_dict", lambda: health_from_dict({name: h["record"]})[name])):
        try:
            rec = make()
        except Exception as exc:  # noqa: BLE001
            refused(stage, exc)
            continue
        if not isinstance(h["record"].get("floating", False), bool):
            fail.append(f"health {stage} accepted floating = {h['record'].get('floating')!r}")
        health = {**health, name: rec}
    try:
        if health_from_dict(health_to_dict(health)) != health:
            fail.append("health does not round-trip through health_to_dict/health_from_dict")
        q = p.with_health(health)
    except Exception as exc:  # noqa: BLE001
        refused("with_health", exc)
        return None
    tol = 0.0
    if ((q.umin < p.umin - tol).any() or (q.umax > p.umax + tol).any() or (q.rate_min < p.rate_min).any()
            or (q.rate_max > p.rate_max).any() or (np.abs(q.B) > np.abs(p.B)).any()):
        fail.append("with_health widened a limit or raised an effectiveness")
    if (q.up < q.umin).any() or (q.up > q.umax).any():
        fail.append("with_health left up outside the limits")
    return q


def _plain(v: Any) -> bool:
    try:
        a = np.array(v, dtype=float)
    except (TypeError, ValueError, OverflowError):
        return False
    return a.ndim == 1


def _batch_equals_single(B: np.ndarray, br: Any, singles: list[Any]) -> list[str]:
    from alloc.result import EXACT_RTOL

    bad = []
    for i, r in enumerate(singles):
        scale = max(1.0, float(np.abs(r.v).max()), float((np.abs(B) @ np.abs(r.u)).max()))
        if np.abs(br.v_achieved[i] - r.v_achieved).max() > BATCH_RTOL * scale:
            bad.append(f"batch row {i}: B u {br.v_achieved[i]} != single {r.v_achieved} ({r.status.value})")
            continue
        if br.status[i] != r.status.value:
            err = float(np.abs(B @ r.u - r.v).max())
            tol = EXACT_RTOL * max(1.0, float(np.abs(r.v).max()))
            if abs(err - tol) > 1e-3 * tol and "fallback" not in (br.status[i], r.status.value):
                bad.append(f"batch row {i}: status {br.status[i]} != single {r.status.value}")
    return bad


# ----------------------------------------------------------------------------- watchdog
def _worker(conn: Any) -> None:  # pragma: no cover - runs in a subprocess
    import os
    import warnings

    import alloc

    null = os.open(os.devnull, os.O_WRONLY)  # solver banners and C-level warnings
    os.dup2(null, 1)
    os.dup2(null, 2)
    warnings.simplefilter("ignore")

    from alloc.solvers import backends

    B = [[1.0, 0.5, -0.3], [0.2, 1.0, 0.7], [0.1, -0.4, 1.0]]
    W = [[2.0, 0.5, 0.0], [0.5, 1.0, 0.0], [0.0, 0.0, 1.0]]
    problems = [alloc.Problem(B, [-1] * 3, [1] * 3),
                alloc.Problem(B, [-1] * 3, [1] * 3, Wu=W, Wv=W, rate_min=[-1] * 3, rate_max=[1] * 3)]
    # a flat attainable set (k = 4 > m = 3): the facet searches' flat-set kernel
    flat = alloc.Problem([[1.0, 0.5, -0.3], [0.2, 1.0, 0.7], [0.1, -0.4, 1.0], [0.3, 0.15, -0.09]], [-1] * 3, [1] * 3,
                         rate_min=[-1] * 3, rate_max=[1] * 3)
    pairs = [(p, name) for p in problems for name in alloc.methods()]
    pairs += [(flat, name) for name in alloc.methods() if alloc.method_info(name)["capabilities"]["needs_ams"] or name == "da"]
    for p, name in pairs:  # load the compiled kernels and solvers before the clock starts
        opts = [{}] + ([{"backend": b} for b in backends()] if "backend" in alloc.method_info(name)["options"]
                       and name not in ("da", "lp") else [{"backend": b} for b in backends(lp=True)]
                       if name in ("da", "lp") else [])
        extra = {"incremental": True, "priorities": [1, 2, 2]}
        opts += [{x: extra[x]} for x in extra if x in alloc.method_info(name)["options"]]
        for o in opts:
            try:
                f = alloc.make_allocator(p, name, **o)
            except alloc.AllocError:
                continue  # a backend this method does not take
            v = np.array([0.1, 0.2, 0.3, 0.06][:p.k])
            f(v)
            f(v, u_prev=np.zeros(3), dt=0.01)
            f.batch(v[None, :])
            f(v.tolist(), u_prev=[0.0, 0.1, 0.2], dt=0.01)
    from alloc._jit_cache import warm

    warm()  # every kernel signature an install compiles, loaded (the rest would compile in a call: a failure)
    conn.send("ready")
    while True:
        c = conn.recv()
        if c is None:
            return
        try:
            res = check(c)
        except Exception as exc:  # noqa: BLE001 - a checker bug is reported, not hidden
            res = {"fail": [f"checker error: {type(exc).__name__}: {exc}"], "status": Counter(), "refused": ""}
        conn.send(res)


class Watchdog:
    """A worker subprocess with a deadline per case; a hang kills and restarts it."""

    def __init__(self) -> None:
        self._ctx = mp.get_context("fork" if sys.platform != "win32" else "spawn")
        self._start()

    def _start(self) -> None:
        self.conn, child = self._ctx.Pipe()
        self.proc = self._ctx.Process(target=_worker, args=(child,), daemon=True)
        self.proc.start()
        t0 = time.time()
        while not self.conn.poll(1.0):
            if not self.proc.is_alive() or time.time() - t0 > 300:
                raise RuntimeError("hostile worker did not start")
        assert self.conn.recv() == "ready"

    def run(self, c: dict[str, Any]) -> dict[str, Any]:
        budget = BUILD_WALL_LIMIT + CALL_WALL_LIMIT * (5 + 3 * len(c["calls"]))
        self.conn.send(c)
        if self.conn.poll(budget):
            return self.conn.recv()
        self.proc.kill()
        self.proc.join()
        self._start()
        return {"fail": [f"hang: no answer within {budget:.0f} s"], "status": Counter(), "refused": ""}

    def close(self) -> None:
        try:
            self.conn.send(None)
        except OSError:
            pass
        self.proc.join(5)
        if self.proc.is_alive():
            self.proc.kill()


# ----------------------------------------------------------------------------- shrinking
def _variants(c: dict[str, Any]):
    """Smaller versions of case ``c``, most aggressive first."""
    f, calls, opts = c["fields"], c["calls"], c["options"]
    for i in range(len(calls)):
        if len(calls) > 1:
            yield {**c, "calls": calls[:i] + calls[i + 1:]}
    for name in list(opts):
        yield {**c, "options": {k: v for k, v in opts.items() if k != name}}
    for name in ("up", "Wu", "Wv", "rate_min", "rate_max"):
        if name in f:
            yield {**c, "fields": {k: v for k, v in f.items() if k not in (name, "rate_min", "rate_max")
                                   or (name not in ("rate_min", "rate_max") and k != name)}}
    for i, call in enumerate(calls):
        if "u_prev" in call:
            yield {**c, "calls": calls[:i] + [{"v": call["v"]}] + calls[i + 1:]}
    try:
        B = np.array(f["B"], dtype=float)
    except (TypeError, ValueError, OverflowError):
        return
    k, m = B.shape if B.ndim == 2 else (0, 0)
    for j in range(m if m > 1 else 0):  # drop effector j
        def drop(x: Any, j: int = j) -> Any:
            return x[:j] + x[j + 1:] if isinstance(x, list) and len(x) == m else x
        nf = {}
        for key, val in f.items():
            if key == "B":
                nf[key] = [drop(list(r)) for r in val]
            elif key == "Wu" and isinstance(val, list) and val and isinstance(val[0], list):
                nf[key] = [drop(list(r)) for r in drop(val)]
            else:
                nf[key] = drop(val)
        ncalls = [{**cl, **({"u_prev": drop(cl["u_prev"])} if "u_prev" in cl else {})} for cl in calls]
        yield {**c, "fields": nf, "calls": ncalls, "options": {}}
    for i in range(k if k > 1 else 0):  # drop axis i
        nf = dict(f)
        nf["B"] = [list(r) for q, r in enumerate(f["B"]) if q != i]
        if isinstance(f.get("Wv"), list):
            Wv = f["Wv"]
            nf["Wv"] = ([[x for q, x in enumerate(r) if q != i] for p_, r in enumerate(Wv) if p_ != i]
                        if Wv and isinstance(Wv[0], list) else [x for q, x in enumerate(Wv) if q != i])
        ncalls = [{**cl, "v": [x for q, x in enumerate(cl["v"]) if q != i]}
                  for cl in calls if isinstance(cl["v"], list) and len(cl["v"]) == k]
        if ncalls:
            yield {**c, "fields": nf, "calls": ncalls, "options": {}}


def shrink(c: dict[str, Any], fails, dog: Watchdog | None = None, budget: int = 300) -> dict[str, Any]:
    """Greedy reduction of a failing case: keep any smaller variant with the same kind of failure."""
    def kind(res: dict[str, Any]) -> set[str]:
        return {s.split(":")[0] for s in res["fail"]}

    want = {s.split(":")[0] for s in fails}
    tries = 0
    improved = True
    while improved and tries < budget:
        improved = False
        for cand in _variants(c):
            tries += 1
            res = dog.run(cand) if dog is not None else check(cand)
            if want & kind(res):
                c, improved = cand, True
                break
            if tries >= budget:
                break
    return c


# ----------------------------------------------------------------------------- driver
def run(seeds: range, workers: int = 1, shrink_failures: bool = True, log: Any = None) -> dict[str, Any]:
    """Run the cases ``seeds``; totals, per-method status counts and (shrunk) failures."""
    import alloc

    report: dict[str, Any] = {"cases": 0, "refused": Counter(), "classes": Counter(), "fail": [], "by_method": {},
                              "fallback_reasons": {}}
    for name in alloc.methods():
        report["by_method"][name] = Counter()
        report["fallback_reasons"][name] = Counter()
    if workers <= 1:
        _run_chunk(list(seeds), report, shrink_failures, log)
        return report
    from concurrent.futures import ThreadPoolExecutor

    chunks = [list(seeds)[i::workers] for i in range(workers)]
    with ThreadPoolExecutor(workers) as pool:  # each thread drives its own watchdog subprocess
        parts = list(pool.map(lambda ch: _run_part(ch, shrink_failures, log), chunks))
    for part in parts:
        _merge(report, part)
    return report


def _run_part(seeds: list[int], shrink_failures: bool, log: Any = None) -> dict[str, Any]:
    import alloc

    rep: dict[str, Any] = {"cases": 0, "refused": Counter(), "classes": Counter(), "fail": [], "by_method": {},
                           "fallback_reasons": {}}
    for name in alloc.methods():
        rep["by_method"][name] = Counter()
        rep["fallback_reasons"][name] = Counter()
    _run_chunk(seeds, rep, shrink_failures, log)
    return rep


def _merge(report: dict[str, Any], part: dict[str, Any]) -> None:
    report["cases"] += part["cases"]
    report["stopped_at_deadline"] = report.get("stopped_at_deadline", False) or part.get("stopped_at_deadline", False)
    report["refused"].update(part["refused"])
    report["classes"].update(part["classes"])
    report["fail"].extend(part["fail"])
    for name, cnt in part["by_method"].items():
        report["by_method"][name].update(cnt)
    for name, cnt in part["fallback_reasons"].items():
        report["fallback_reasons"][name].update(cnt)


def _run_chunk(seeds: list[int], report: dict[str, Any], shrink_failures: bool, log: Any) -> None:
    dog = Watchdog()
    try:
        for n, seed in enumerate(seeds):
            if DEADLINE is not None and time.time() > DEADLINE:
                report["stopped_at_deadline"] = True
                break
            c = case(seed)
            res = dog.run(c)
            report["cases"] += 1
            if res["refused"]:
                report["refused"][res["refused"]] += 1
            report["classes"].update(case_classes(c))
            report["by_method"][c["method"]].update(res["status"])
            for msg in res.get("messages", []):
                report["fallback_reasons"][c["method"]][re.sub(r"[-+]?\d[\d.e+-]*", "#", msg)[:80]] += 1
            if res["fail"]:
                slow_only = all(s.startswith("slow call") for s in res["fail"])
                small = shrink(c, res["fail"], dog) if shrink_failures and not slow_only else c
                report["fail"].append({"seed": seed, "fail": res["fail"][:3], "minimal": small})
                if log is not None:
                    print("FAIL " + json.dumps(report["fail"][-1], default=str), file=log, flush=True)
            if log is not None and n % 1000 == 999:
                print(f"{n + 1} cases, {len(report['fail'])} failing", file=log, flush=True)
    finally:
        dog.close()


def markdown_rows(report: dict[str, Any], note: str = "") -> str:
    """The docs' hostile-run table rows for a ``--json`` report: the run (cases, seeds, breaks,
    rate) and its calls and fallbacks by method, generated rather than typed."""
    seeds = report.get("seeds") or [None, None]
    fails = report["fail"]
    kinds = Counter(f["fail"][0].split(":")[0] for f in fails)
    breaks = f"{len(fails)}" + (" (" + ", ".join(f"{n} {k}" for k, n in kinds.most_common()) + ")" if fails else "")
    rate = report["cases"] / report["seconds"] if report.get("seconds") else 0.0
    stopped = " (stopped at its time limit)" if report.get("stopped_at_deadline") else ""
    run = (f"| {report['cases']:,}{stopped} | {seeds[0]:,}-{seeds[0] + report['cases'] - 1:,} | {breaks} | "
           f"{report.get('seconds', 0):,.0f} s ({rate:.1f} cases/s){note} |")
    lines = [run, "", "| method | calls | exact | unattainable | fallback |", "|---|---:|---:|---:|---:|"]
    for name, cnt in sorted(report["by_method"].items()):
        total = sum(cnt.values())
        lines.append(f"| `{name}` | {total:,} | {cnt.get('exact', 0):,} | {cnt.get('unattainable', 0):,} | "
                     f"{cnt.get('fallback', 0):,} |")
    return "\n".join(lines)


def main() -> None:  # pragma: no cover - command line
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=int, default=100_000)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--json", help="write the report here")
    ap.add_argument("--minutes", type=float, help="stop taking new cases after this long (report what ran)")
    ap.add_argument("--table", metavar="JSON", help="print the docs' table rows for a --json report and exit")
    a = ap.parse_args()
    if a.table:
        with open(a.table) as fh:
            print(markdown_rows(json.load(fh)))
        return
    t0 = time.time()
    global DEADLINE
    DEADLINE = None if a.minutes is None else t0 + 60 * a.minutes
    rep = run(range(a.seed, a.seed + a.cases), a.workers, log=sys.stderr)
    rep["seconds"] = round(time.time() - t0, 1)
    calls = {m: dict(c) for m, c in rep["by_method"].items()}
    rate = rep["cases"] / rep["seconds"] if rep["seconds"] else 0.0
    print(json.dumps({"cases": rep["cases"], "seeds": [a.seed, a.seed + a.cases - 1], "seconds": rep["seconds"],
                      "cases_per_second": round(rate, 1),
                      "stopped_at_deadline": rep.get("stopped_at_deadline", False), "refused": dict(rep["refused"]),
                      "classes": dict(rep["classes"]), "failures": len(rep["fail"]), "calls_by_method": calls},
                     indent=1))
    for f in rep["fail"][:20]:
        print(json.dumps(f, default=str)[:2000])
    for m, cnt in rep["fallback_reasons"].items():
        for msg, n in cnt.most_common(5):
            print(f"fallback {m}: {n} x {msg}")
    if a.json:
        with open(a.json, "w") as fh:
            json.dump({**rep, "seeds": [a.seed, a.seed + a.cases - 1], "refused": dict(rep["refused"]),
                       "classes": dict(rep["classes"]),
                       "by_method": calls, "fallback_reasons": {m: dict(c) for m, c in rep["fallback_reasons"].items()}},
                      fh, indent=1, default=str)


if __name__ == "__main__":
    main()
