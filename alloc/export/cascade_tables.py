"""The tables of the exported ``cgi`` (:mod:`alloc.export`): every free set's weighted
pseudo-inverse, or with priority levels every level's prioritised one, computed by the
library's own code so that the kernels return its bits."""

from __future__ import annotations

from typing import Any

import numpy as np

from ..problem import Problem
from . import CGI_RTOL, FLOAT_CGI_RTOL, TABLE_BUDGET, ExportError, _ints, _Real


def free_set_table(impl: Any, problem: Problem, real: _Real, table: bool | None) -> str:
    """Every free set's weighted pseudo-inverse, computed as the library's ``cgi`` computes it
    (so the kernel returns its bits): the C table of :data:`templates_closed_form.CASCADE`."""
    from .._kernels import free_set_pinv
    from .._linalg import ABS_FLOOR

    k, m = problem.k, problem.m
    check_table(m, k, real, table)
    rows = []
    for bits in range(1 << m):
        free = np.array([bool(bits >> j & 1) for j in range(m)])
        P = np.zeros((m, k))
        if free.any():
            if impl._diagonal_Wu:
                Pf = free_set_pinv(impl._SB, impl._rdiag, impl._S, free, impl.rcond, ABS_FLOOR)
            else:
                Pf = impl._pinv(free)
            P[:Pf.shape[0]] = Pf
        rows.append(real.array(P.ravel(), "P"))
    return "{\n    " + ",\n    ".join(rows) + "\n}"


def check_table(m: int, k: int, real: _Real, table: bool | None) -> None:
    """``cgi`` reads every free set's pseudo-inverse (``2^m x m x k`` values, by level or
    not) from a table: refused beyond :data:`TABLE_BUDGET` unless ``table=True``."""
    size = (1 << min(m, 40)) * m * k * (8 if real.double else 4)
    if table is False:
        raise ExportError("table: cgi has no run-time form (its kernel reads every free set's pseudo-inverse "
                          "from a table); give table=None or True", field="table")
    if (table is None and size > TABLE_BUDGET) or m > 20:
        raise ExportError(f"table: cgi needs the pseudo-inverse of every free set, {size:,} bytes for {m} effectors "
                          f"(over the {TABLE_BUDGET:,}-byte budget; table=True takes it up to 20 effectors)",
                          field="table")


def level_fields(impl: Any, problem: Problem, real: _Real, table: bool | None) -> dict[str, str]:
    """``cgi`` with priority levels: each level's axes and its table of the prioritised
    pseudo-inverse of every free set, from the library's own ``_level_pinv`` (the columns of the
    level's own axes), so the kernel returns the library's bits."""
    k, m = problem.k, problem.m
    check_table(m, k, real, table)
    starts, tables, names = [0], [], []
    done = np.zeros(0, dtype=np.intp)
    for li, level in enumerate(impl.groups):
        rows = np.concatenate([done, level])
        sub = [np.arange(done.size), np.arange(done.size, rows.size)]
        Wv = problem.Wv[np.ix_(rows, rows)]
        per_set = []
        for bits in range(1 << m):
            free = np.array([bool(bits >> j & 1) for j in range(m)])
            P = np.zeros((m, level.size))
            if free.any():
                F = np.flatnonzero(free)
                P[:F.size] = impl._level_pinv(li, free, rows, F, Wv, sub)[:, done.size:]
            per_set.append(real.array(P.ravel(), f"P{li}"))
        names.append(f"TAB_{li}")
        tables.append(f"static const real TAB_{li}[1 << M][M * {level.size}] = {{\n    " + ",\n    ".join(per_set)
                      + "\n};")
        starts.append(starts[-1] + level.size)
        done = rows
    tables.append(f"static const real *const TAB[NL] = {{{', '.join(f'&{n}[0][0]' for n in names)}}};")
    return {"NL": str(len(impl.groups)), "LEVEL_START": _ints(starts),
            "LEVEL_AXES": _ints(np.concatenate(impl.groups)),
            "CGI_RTOL": real.literal(CGI_RTOL if real.double else FLOAT_CGI_RTOL, "rtol"),
            "CGI_REACH": real.literal(CGI_RTOL if real.double else FLOAT_CGI_RTOL, "reach"), "TABLES": "\n".join(tables)}
