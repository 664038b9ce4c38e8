"""The constant tables of the generated kernels: ``cgi``'s free-set pseudo-inverses and the
active-set methods' level rows, factorisations and instances (:func:`alloc.export.export_c`
fills the templates with them)."""

from __future__ import annotations

from typing import Any

import numpy as np

from ..export_data import CascadeData, SimplexData
from ..problem import Problem
from . import templates, templates_active_set, templates_simplex
from .base import (CACHE_BUDGET, CGI_RTOL, FLOAT_CGI_RTOL, FLOAT_MU_EPS, FLOAT_SIGMA_RTOL, FLOAT_SIMPLEX_TOLS,
                   TABLE_BUDGET, WARM_COND_MAX, ExportError, _ints, _Real)
from .certify import Certificate, certify


def _cascade_table(data: CascadeData, problem: Problem, real: _Real, table: bool | None) -> str:
    """Every free set's weighted pseudo-inverse, computed by the library's ``cgi`` itself
    (so the kernel returns its bits): the C table of :data:`templates_closed_form.CASCADE`."""
    k, m = problem.k, problem.m
    _check_cascade_table(m, k, real, table)
    rows = []
    for bits in range(1 << m):
        free = np.array([bool(bits >> j & 1) for j in range(m)])
        P = np.zeros((m, k))
        if free.any():
            Pf = data.free_set_pinv(free)
            P[:Pf.shape[0]] = Pf
        rows.append(real.array(P.ravel(), "P"))
    return "{\n    " + ",\n    ".join(rows) + "\n}"


def _check_cascade_table(m: int, k: int, real: _Real, table: bool | None) -> None:
    """``cgi`` reads every free set's pseudo-inverse (``2^m x m x k`` values, by level or
    not) from a table: refused beyond :data:`TABLE_BUDGET` unless ``table=True`` (and then
    beyond the size caps, which :func:`alloc.export.export_c` prices first)."""
    size = (1 << min(m, 40)) * m * k * (8 if real.double else 4)
    if table is False:
        raise ExportError("table: cgi has no run-time form (its kernel reads every free set's pseudo-inverse "
                          "from a table); give table=None or True", field="table")
    if table is None and size > TABLE_BUDGET:
        raise ExportError(f"table: cgi needs the pseudo-inverse of every free set, {size:,} bytes for {m} effectors "
                          f"(over the {TABLE_BUDGET:,}-byte budget; table=True takes it up to the export's size "
                          "caps, alloc.export.cost: 16 effectors at 3 axes, 15 at 6)", field="table")


def _cascade_level_fields(data: CascadeData, problem: Problem, real: _Real, table: bool | None) -> dict[str, str]:
    """``cgi`` with priority levels: each level's axes and its table of the prioritised
    pseudo-inverse of every free set, from the library's own ``level_pinv`` (the columns of the
    level's own axes), so the kernel returns the library's bits."""
    k, m = problem.k, problem.m
    _check_cascade_table(m, k, real, table)
    starts, tables, names = [0], [], []
    groups = data.groups or ()
    for li, level in enumerate(groups):
        per_set = []
        for bits in range(1 << m):
            free = np.array([bool(bits >> j & 1) for j in range(m)])
            P = np.zeros((m, level.size))
            if free.any():
                F = np.flatnonzero(free)
                P[:F.size] = data.level_pinv(li, free)
            per_set.append(real.array(P.ravel(), f"P{li}"))
        names.append(f"TAB_{li}")
        tables.append(f"static const real TAB_{li}[1 << M][M * {level.size}] = {{\n    " + ",\n    ".join(per_set)
                      + "\n};")
        starts.append(starts[-1] + level.size)
    tables.append(f"static const real *const TAB[NL] = {{{', '.join(f'&{n}[0][0]' for n in names)}}};")
    return {"NL": str(len(groups)), "LEVEL_START": _ints(starts),
            "LEVEL_AXES": _ints(np.concatenate(groups)),
            "CGI_RTOL": real.literal(CGI_RTOL if real.double else FLOAT_CGI_RTOL, "rtol"),
            "CGI_REACH": real.literal(CGI_RTOL if real.double else FLOAT_CGI_RTOL, "reach"), "TABLES": "\n".join(tables)}


def _aset() -> Any:
    """The packed state's layout and the level iteration (_active_set) with the free sets'
    factorisation and its tolerances (_lsq_factor), read by one name."""
    from types import SimpleNamespace

    from .._engine import _active_set, _lsq_factor
    return SimpleNamespace(**{**vars(_lsq_factor), **vars(_active_set)})


def _table_entry(states: list[tuple[np.ndarray, ...]], aset: Any) -> tuple[int, int]:
    """Numbers of one free set's row of the factorisation tables, and ``ml`` (1: every
    instance's L is diagonal, stored in column 0; else m)."""
    head = states[0][2][aset._HEAD]
    m, ncw, nlw = (int(head[i]) for i in (aset._M, aset._NCW, aset._NLW))
    ml = 1 if all(int(state[2][aset._HEAD, aset._DIAG]) for state in states) else m
    return m * ml + m * ncw + ncw * ncw + ncw + m * nlw + nlw * nlw + nlw, ml


def active_set_plan(states: list[tuple[np.ndarray, ...]], real: _Real, table: bool | None) -> tuple[bool, int, int, int]:
    """What an active-set kernel prints, before it is made: whether it tabulates (``table``, or
    by default when the tables fit :data:`TABLE_BUDGET`), its constants' numbers, its tables'
    numbers and the free sets it factorises for them (:mod:`alloc.export.cost` prices them)."""
    aset = _aset()
    head = states[0][2][aset._HEAD]
    n, m, k, nlev = (int(head[i]) for i in (aset._N, aset._M, aset._K, aset._NLEV))
    entry, _ = _table_entry(states, aset)
    rows = len(states) * len(_table_keys(states[0][2], aset)) << m
    tabulate = rows * entry * (8 if real.double else 4) <= TABLE_BUDGET if table is None else bool(table)
    consts = n * m + n * n + nlev
    for state in states:
        dyn = bool(state[2][aset._HEAD, aset._DYN])
        consts += 2 * m * m + m * k + m + (m * k + m * m if dyn else 0)
    return tabulate, consts, rows * entry if tabulate else 0, rows if tabulate else 0


def _active_set_fields(states: list[tuple[np.ndarray, ...]], problem: Problem, real: _Real, fields: dict[str, str],
                       maxit: int | None, table: bool | None, cache: int | None,
                       warm: bool = False) -> tuple[str, int, int]:
    """The active set's constants, read from the library's packed solver states
    (:func:`alloc._engine._active_set.pack`), so the C runs on exactly the library's data.  One
    instance for ``qp`` and ``wls``; ``dynamic`` has two (without and with ``u_prev``), which
    share every level row and differ in the preference weight, cold start and target."""
    aset = _aset()

    mats, vecs, ivecs = states[0][:3]
    head = ivecs[aset._HEAD]
    n, m, k, nlev = (int(head[i]) for i in (aset._N, aset._M, aset._K, aset._NLEV))
    final, ncw, nlw = (int(head[i]) for i in (aset._FINAL, aset._NCW, aset._NLW))
    cap = int(head[aset._MAXIT]) if maxit is None else maxit
    if not (isinstance(cap, (int, np.integer)) and not isinstance(cap, bool) and 1 <= cap <= 1_000_000):
        raise ExportError(f"maxit: expected an integer in [1, 1000000], got {maxit!r}", field="maxit")
    eps = 2.220446049250313e-16 if real.double else 2.0 ** -23
    if real.double:
        tiny = {"SIGMA_RTOL": aset.SIGMA_RTOL, "JACOBI_EPS": aset.JACOBI_EPS, "JACOBI_TOL_FLOOR": 1e-15,
                "JACOBI_SMALL": 1e-30, "SIGMA_TINY": 1e-290, "CHOL_TINY": 1e-300, "MU_EPS": aset.MU_EPS}
    else:  # the same roles at float's round-off and range
        tiny = {"SIGMA_RTOL": FLOAT_SIGMA_RTOL, "JACOBI_EPS": eps, "JACOBI_TOL_FLOOR": 4.0 * eps, "JACOBI_SMALL": 1e-12,
                "SIGMA_TINY": 1e-35, "CHOL_TINY": 1e-37, "MU_EPS": FLOAT_MU_EPS}
    fields.update({key: real.literal(value, key) for key, value in tiny.items()})
    if warm:
        _warm_conditioning(states, aset, n, m)
    entry, ml = _table_entry(states, aset)
    fields.update(
        N=str(n), NLEV=str(nlev), FINAL=str(final), NCW=str(ncw), NLW=str(nlw), ML="1" if ml == 1 else "M",
        NINST=str(len(states)),
        A=real.array(mats[aset._A, :n, :m], "A"), T=real.array(mats[aset._T, :n, :n], "T"),
        PERM=_ints(ivecs[aset._PERM, :n]), STARTS=_ints(ivecs[aset._STARTS, :nlev + 1]),
        GAM=real.array(vecs[aset._GAM, :nlev], "gamma"),
    )
    levels = nlev + final
    keys = _table_keys(ivecs, aset)
    table = active_set_plan(states, real, table)[0]
    if table and m > 20:
        raise ExportError(f"table: 2^{m} free sets a level is too many to tabulate", field="table")
    fields["TABLE"] = "1" if table else "0"
    slot_bytes = entry * (8 if real.double else 4) + 4 * (4 + m)
    slots = _cache_slots(cache, bool(table), slot_bytes, len(states) * len(keys) << min(m, 30))
    fields["CACHE"] = str(slots)
    cached = (f" *\n * Cache: the factorisations of the last free sets met, in static storage ({slots} slots of\n"
              f" * about {slot_bytes} bytes); a factorisation depends on the free set alone, so the cache\n"
              " * changes the time of a call, never its answer.\n") if slots else ""
    fields["INSTANCES"] = _instances(states, aset, keys, real, ml, bool(table))
    fields["HEALTH"] = (" *\n * Health at run time: PREFIX_set_limits(umin, umax) sets reduced limits or jams\n"
                        " * (umin[j] == umax[j]) within the nominal limits; an effectiveness change needs a new\n"
                        " * export.  The cold start and the safe answer keep the nominal Eq 1.23 matrix.\n" + cached
                        + (_WARM_TEXT if warm else ""))
    fields["HEALTH_DECL"] = templates.HEALTH_DECL + (templates.WARM_DECL if warm else "")
    fields["LIMITS_QUAL"] = ""
    fields["MAXIT_DEFINE"] = (f"/* iteration cap per level and per call (see the bound above) */\n"
                              f"#define PFX_MAXIT {cap}\n#define PFX_MAXIT_TOTAL {levels * cap}\n")
    return templates_active_set.ACTIVE_SET_WARM if warm else templates_active_set.ACTIVE_SET, levels, cap


def _warm_conditioning(states: list[tuple[np.ndarray, ...]], aset: Any, n: int, m: int) -> None:
    """Refuse the warm start where the optimum is not determined beyond round-off
    (:data:`WARM_COND_MAX`): a singular value of the weighted effectiveness A, or of a pair of its
    columns (two nearly redundant effectors: the free sets' factorisations are of column
    subsets), between round-off (:data:`WARM_ROUND_OFF` of the largest) and 1 / WARM_COND_MAX of
    it, that is nearly but not exactly rank-deficient; rows of A (axes with their weights)
    scaled more than WARM_COND_MAX apart; or each instance's Wu conditioned beyond
    WARM_COND_MAX."""
    from .._engine._warm import warm_conditioning

    found = warm_conditioning(states[0][0][aset._A, :n, :m],
                              [state[0][aset._WU, :m, :m] for state in states])
    worst, what = found if found is not None else (None, "")
    if worst is not None:
        raise ExportError(f"warm_start: the problem's {what} has condition number {worst:.2g}, above "
                          f"{WARM_COND_MAX:g}: its optimum is determined only to round-off times that, so a "
                          "warm start would end elsewhere; export without warm_start", field="warm_start")


#: the header paragraph of a kernel exported with warm_start=True
_WARM_TEXT = """ *
 * Warm start (exported with warm_start=True): the kernel also keeps, in static storage, the
 * last answer and its working set, and starts the next call from them where the first level's
 * objective is not larger there than at the cold start.  An answer then depends on the calls
 * before it: it agrees with the library's (which has no warm start) to round-off where the
 * optimum is strictly determined, and where the optimality test cannot tell working sets
 * apart (a flat optimum) it may be another point the library's test accepts.
 * PREFIX_warm_reset() forgets the warm start, as PREFIX_set_limits does; the next call is
 * then the library's, bit for bit.
"""


def _cache_slots(cache: int | None, table: bool, slot_bytes: int, free_sets: int) -> int:
    """Slots of the factorisation cache: ``cache``, or as many as :data:`CACHE_BUDGET` holds
    (at most one per free set); none beside a table."""
    if cache is not None and (isinstance(cache, bool) or not isinstance(cache, (int, np.integer))
                              or not 0 <= cache <= 1 << 16):
        raise ExportError(f"cache: expected an integer in [0, 65536], got {cache!r}", field="cache")
    if table:
        if cache:
            raise ExportError("cache: a kernel with tables looks every factorisation up (give cache=None or 0)",
                              field="cache")
        return 0
    return int(min(CACHE_BUDGET // slot_bytes, free_sets)) if cache is None else int(cache)


def _iteration_budget(bound: int | str | None, allocator: Any, problem: Problem, precision: str,
                      total: int, **counting: Any) -> tuple[int, Certificate | None]:
    """The per-call iteration budget of an active-set or ``lp`` kernel, and the certification
    behind it (``counting``: :func:`alloc.export.certify.certify`'s ``count`` and ``unit``)."""
    if bound is None:
        return total, None
    if bound == "certify":
        if precision != "double":
            raise ExportError("iteration_bound: the certification runs the library in double; a float kernel's "
                              "counts can differ (give an integer)", field="iteration_bound")
        cert = certify(allocator, problem, **counting)
        return min(cert.bound, total), cert
    if isinstance(bound, bool) or not isinstance(bound, (int, np.integer)) or not 1 <= bound <= total:
        raise ExportError(f"iteration_bound: expected \"certify\" or an integer in [1, {total}], got {bound!r}",
                          field="iteration_bound")
    return int(bound), None


_TABLE_NAMES = ("L", "YC", "VC", "SC", "YA", "VA", "SA")


def _instances(states: list[tuple[np.ndarray, ...]], aset: Any, keys: list[tuple[int, int]], real: _Real, ml: int,
               table: bool) -> str:
    """Each instance's constants and tables, and the ``INSTANCES`` array of the C source."""
    parts, inits = [], []
    for i, state in enumerate(states):
        mats, vecs, ivecs = state[:3]
        head = ivecs[aset._HEAD]
        m, k = int(head[aset._M]), int(head[aset._K])
        dyn, diag = bool(head[aset._DYN]), int(head[aset._DIAG])
        parts.append(f"static const real WU_{i}[M][M] = {real.array(mats[aset._WU, :m, :m], 'Wu')};")
        parts.append(f"static const real P0_{i}[M][K] = {real.array(mats[aset._P0, :m, :k], 'P0')};")
        parts.append(f"static const real UPT_{i}[M] = {real.array(vecs[aset._UP, :m], 'up')};")
        if dyn:
            parts.append(f"static const real KV_{i}[M][K] = {real.array(mats[aset._KV, :m, :k], 'Kv')};")
            parts.append(f"static const real KU_{i}[M][M] = {real.array(mats[aset._KU, :m, :m], 'Ku')};")
        if table:
            parts.append("/* the factorisations of every free set of every level, computed by the generator with\n"
                         "   the library's own code (alloc._engine._lsq_factor._factor): row [key][free-set bits] */")
            parts.append(_tables(mats, ivecs, aset, keys, real, ml, suffix=f"_{i}"))
        kv, ku = (f"KV_{i}", f"KU_{i}") if dyn else ("NULL", "NULL")
        tabs = "".join(f", TAB_{name}_{i}" for name in _TABLE_NAMES) if table else ""
        inits.append(f"    {{{diag}, WU_{i}, P0_{i}, UPT_{i}, {kv}, {ku}{tabs}}}")
    parts.append("static const struct instance INSTANCES[NINST] = {\n" + ",\n".join(inits) + "\n};")
    return "\n".join(parts)


def _table_keys(ivecs: np.ndarray, aset: Any) -> list[tuple[int, int]]:
    """``(r0, r1)`` of each factorisation a level looks up: level ``l`` its rows, the final
    level of a multi-level problem every row as held rows (a one-level problem's final level
    reads level 0's)."""
    head = ivecs[aset._HEAD]
    n, nlev, final = int(head[aset._N]), int(head[aset._NLEV]), int(head[aset._FINAL])
    starts = ivecs[aset._STARTS]
    keys = [(int(starts[lv]), int(starts[lv + 1])) for lv in range(nlev)]
    share = nlev == 1 and int(starts[0]) == 0
    if final and not share:
        keys.append((n, n))
    return keys


def _float_cut(blocks: tuple[np.ndarray, ...], A: np.ndarray, r0: int, r1: int, F: np.ndarray,
               rtol: float) -> None:
    """Drop, in a table made in double for a float kernel, the singular values a float
    factorisation would drop (below ``rtol`` of the scale, as :func:`alloc._engine._lsq_factor._jacobi`
    does at double's round-off): kept, they would divide float noise by a tiny number."""
    L, _, _, sc, Ya, _, sa = blocks
    if len(sc) and sc.max() > 0.0:
        sc[sc <= rtol * sc.max()] = 0.0
    if r1 > r0 and len(F):
        cols = A[r0:r1][:, F].T  # the level's rows on the free set, scaled as Ya before projection
        scaled = cols / (L[:len(F), :1] if L.shape[1] == 1 else np.diag(L[:len(F), :len(F)])[:, None])
        ref = max(float(np.abs(scaled).max()), float(sa.max()))
        sa[sa <= rtol * ref] = 0.0


def _tables(mats: np.ndarray, ivecs: np.ndarray, aset: Any, keys: list[tuple[int, int]], real: _Real, ml: int,
            suffix: str) -> str:
    """The C tables of every free set's factorisation, computed by the library's own compiled
    ``_factor`` (so a table lookup gives the bits a run-time factorisation gives)."""
    head = ivecs[aset._HEAD]
    m, diag, ncw, nlw = (int(head[i]) for i in (aset._M, aset._DIAG, aset._NCW, aset._NLW))
    own = 1 if diag else m  # the library's L width; padded to the source's ml (column 0 holds a diagonal)
    A, Wu = np.ascontiguousarray(mats[aset._A]), np.ascontiguousarray(mats[aset._WU])
    names = tuple(f"TAB_{name}{suffix}" for name in _TABLE_NAMES)
    widths = (m * ml, m * ncw, ncw * ncw, ncw, m * nlw, nlw * nlw, nlw)
    rows: dict[str, list[str]] = {name: [] for name in names}
    for r0, r1 in keys:
        per_key: dict[str, list[str]] = {name: [] for name in names}
        for bits in range(1 << m):
            free = np.array([j for j in range(m) if bits >> j & 1] + [0] * m, dtype=np.int64)[:m]
            nf = bin(bits).count("1")
            blocks = (np.zeros((m, own)), np.zeros((m, ncw)), np.zeros((ncw, ncw)), np.zeros(ncw),
                      np.zeros((m, nlw)), np.zeros((nlw, nlw)), np.zeros(nlw))
            aset._factor(A, r0, r1, Wu, bool(diag), free, nf, *blocks)
            if not real.double:
                _float_cut(blocks, A, r0, r1, free[:nf], FLOAT_SIGMA_RTOL)
            L = np.zeros((m, ml))
            L[:, :own] = blocks[0]
            for name, block in zip(names, (L,) + blocks[1:]):
                per_key[name].append(real.array(block.ravel(), name))
        for name in names:
            rows[name].append("{\n    " + ",\n    ".join(per_key[name]) + "\n}")
    return "\n".join(f"static const real {name}[{len(keys)}][{1 << m}][{width}] = {{\n" + ",\n".join(rows[name])
                     + "\n};" for name, width in zip(names, widths))


def _simplex_fields(lex: SimplexData, real: _Real, fields: dict[str, str]) -> tuple[str, int]:
    """The ``lp`` kernel's constants, read from the library's own scaled problem
    (:class:`alloc._engine._simplex.LexicographicL1`: the tableau ``F``, the row scales, the half-widths
    and the stages' normalised costs), so the C runs on exactly the library's data; and the
    library's pivot cap ``50 (N + k)``."""
    from .._engine import _simplex

    F, costs = lex.F, lex.costs
    k, n = F.shape
    if real.double:
        tol = {name: getattr(_simplex, name) for name in FLOAT_SIMPLEX_TOLS}
    else:
        tol = FLOAT_SIMPLEX_TOLS
    fields.update({key: real.literal(value, key) for key, value in tol.items()})
    fields.update(NV=str(n), NSTAGE=str(costs.shape[0]), INF=real.literal(np.inf, "inf"),
                  F=real.array(F, "F"), RHO=real.array(lex.rho, "rho"), D=real.array(lex.D, "D"),
                  COSTS=real.array(costs, "costs"))
    fields["HEALTH"] = (" *\n * Health at run time: PREFIX_set_limits(umin, umax) sets reduced limits or jams\n"
                        " * (umin[j] == umax[j]) within the nominal limits: they enter the tableau's bounds and\n"
                        " * right-hand side only; an effectiveness change needs a new export.  The scaling\n"
                        " * (D, rho) and the safe answer keep the nominal problem's.\n")
    fields["HEALTH_DECL"] = templates.HEALTH_DECL
    fields["LIMITS_QUAL"] = ""
    cap = int(lex.max_iter)
    fields["MAXIT_DEFINE"] = ("/* the library's pivot cap, 50 (N + k): a call succeeds within PFX_MAXIT - 1 pivots */\n"
                              f"#define PFX_MAXIT {cap}\n")
    return templates_simplex.SIMPLEX, cap


def _simplex_pivots(lex: SimplexData, problem: Problem) -> Any:
    """``count(v)``: the library simplex's pivots on ``v`` with the nominal limits (what the
    allocator's call runs), also where it stops at its cap (the allocator then reports a
    fallback of 0 iterations)."""
    lo, hi = problem.umin, problem.umax

    def count(v: np.ndarray) -> int:
        return lex.pivots(np.ascontiguousarray(v, dtype=float), lo, hi)

    return count
