"""The hostile-case generator of the standing adversarial suite (:mod:`hostile`).

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
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np


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
                 "max_rounds": [1, 2, 40, 1000], "resolution": [2, 3, 16, 64], "warm_start": [True, False],
                 "airmode": ["disabled", "roll_pitch", "roll_pitch_yaw"], "weak": [0.0, 0.2, 1.0],
                 "zero": [0.0, 1e-3, 0.5]}
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
    if name in ("incremental", "warm_start"):
        return rng.choice(np.array([True, False, "x"], dtype=object))
    if name == "airmode":
        return rng.choice(np.array(["disabled", "roll_pitch_yaw", "x", 2, None], dtype=object))
    if name in ("weak", "zero"):
        return rng.choice(np.array([0.0, 0.2, -1.0, math.nan, 1e300, "x"], dtype=object))
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
