"""Flight-computer kernels: an allocator as dependency-free C99 (``alloc export``).

:func:`export_c` takes a :class:`~alloc.Problem` or a vehicle and a method and writes a
self-contained ``.h``/``.c`` pair: fixed sizes, no heap, no recursion, no library calls but
``sqrt`` and ``fabs``, ``float`` or ``double`` chosen at generation, every constant the
method can precompute (pseudo-inverses, the level rows of the active set) printed in the
source.  One entry point per kernel::

    int alloc_<method>_allocate(const T *v, const T *u_prev, T dt, T *u);

returning the status (0 exact, 1 unattainable, 2 fallback).  The ``double`` build transcribes
the library's compiled code in the same order of operations: it returns the library's
answers bit for bit and the same statuses (tests/alloc/export/test_export.py checks it); the ``float``
build agrees to :data:`FLOAT_TOLERANCE` (see there) and clamps its output to its bounds exactly.

Which methods: those that declare a kind of kernel (``@register(name, export=kind)``, read
through :meth:`alloc.Allocator.export_data`) whose kind has an exporter here
(:mod:`alloc.export.exporter`, one module per kind); :data:`EXPORTABLE` lists them.  Today:
``pinv``, ``pinv_clip``, ``ganging`` (``u = clip(c + P v)``), ``pinv_scale`` (the
increment scaled into the box), ``cgi`` (the cascaded generalized inverse over a table of every
free set's pseudo-inverse; without priority levels) and the active-set ``wls``, ``qp`` (with ``priorities``) and
``dynamic`` (its two solver instances, without and with ``u_prev``), whose iteration count per
level is capped at the library's own cap and per call at ``iteration_bound`` (by default the
levels' caps added; ``"certify"``: the largest count on a dense sample of the demand set,
:mod:`alloc.export.certify`), both stated and argued in the header and enforced: reaching
either returns the safe answer with status 2.  And ``lp`` (with ``priorities``): the library's
compiled lexicographic simplex (:mod:`alloc._engine._simplex`), its pivots capped at the library's cap
and per call at ``iteration_bound`` likewise (certified by counting the simplex's pivots).

Health at run time: the active-set and ``lp`` kernels take reduced limits and jams through
``alloc_<method>_set_limits``; the closed-form kernels bake the distribution matrix of the
problem's health into their constants, so a jam or an effectiveness change there means
generating again (``Problem.with_health``), as does an effectiveness change for any method.
"""

from __future__ import annotations

import hashlib
from typing import Any
from collections.abc import Mapping

import numpy as np

from ..exceptions import UnknownMethodError
from ..problem import Problem
from . import templates
# the kinds' exporters register themselves (alloc.export.exporter), one module per kind
from . import active_set, cascade, closed_form, simplex  # noqa: F401
from .base import (FLOAT_EXACT_RTOL, FLOAT_TOLERANCE, FLOAT_VMAX, GENERATOR_VERSION, PRECISIONS, ExportedKernel,
                   ExportError, _Real, _short, _version)
from .certify import Certificate
from .cost import ExportCost, check
from .exporter import Exporter, Settings, exportable, exporter_for
from .text import c_prefix, comment_text, fill

__all__ = ["export_c", "ExportedKernel", "ExportError", "EXPORTABLE", "exportable", "PRECISIONS",
           "GENERATOR_VERSION", "FLOAT_TOLERANCE", "FLOAT_EXACT_RTOL", "FLOAT_VMAX", "Certificate", "ExportCost"]


def __getattr__(name: str) -> Any:
    # EXPORTABLE is read from the registry when first asked for (after any user's registrations
    # made before), so importing alloc.export does not load every method
    if name == "EXPORTABLE":
        return exportable()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


# --------------------------------------------------------------------------- the generator

#: characters of the header's list of effector (or axis) names: 512 names of up to 200 each
_NAMES_CHARS = 512 * 204

def _resolve(problem_or_vehicle: Any, method: str, options: Mapping[str, Any] | None) -> tuple[Problem, str, dict]:
    if isinstance(problem_or_vehicle, Problem):
        return problem_or_vehicle, f"alloc.Problem {problem_or_vehicle.k} x {problem_or_vehicle.m}", dict(options or {})
    from .. import vehicles

    vehicle = vehicles.get_vehicle(problem_or_vehicle)
    merged = vehicles.method_options(vehicle, method, options)
    title = f"vehicle {vehicle.name!r}" + (f" ({vehicle.description})" if vehicle.description else "")
    return vehicle.problem(), title, merged


def _check_method(method: Any) -> str:
    names = exportable()
    if not isinstance(method, str) or method not in names:
        raise UnknownMethodError(f"method: {method!r} cannot be exported to C; exportable: {', '.join(names)}",
                                 field="method")
    return method


def _checksum(problem: Problem) -> str:
    h = hashlib.sha256()
    for a in (problem.B, problem.umin, problem.umax, problem.up, problem.Wu, problem.Wv, problem.rate_min,
              problem.rate_max):
        h.update(np.ascontiguousarray(a, dtype=float).tobytes())
    return h.hexdigest()[:16]


def _price(method: str, exporter: Exporter, data: Any, problem: Problem, real: _Real,
           settings: Settings) -> ExportCost:
    """The export's cost (:mod:`alloc.export.cost`), refused beyond its caps before the tables
    are made: the common constants and the kind's own (:meth:`Exporter.price`)."""
    from .certify import sample_size

    k, m = problem.k, problem.m
    common = 2 * m * k + 6 * m  # B, SAFE_P; UP, limits, rates, SAFE_C
    priced = exporter.price(data, problem, real, settings)
    calls = 0
    if isinstance(settings.iteration_bound, str) and settings.iteration_bound == "certify":
        calls = sample_size(k, m, exporter.certify_random)
    return check(ExportCost(numbers=common + priced.numbers + priced.table_numbers, table_numbers=priced.table_numbers,
                            free_sets=priced.free_sets, certify_calls=calls, k=k, m=m, method=method,
                            template_bytes=priced.template_bytes, fixed=exporter.fixed,
                            table_hint=exporter.table_hint))


def export_c(problem_or_vehicle: Any, method: str = "qp", *, precision: str = "double",
             options: Mapping[str, Any] | None = None, prefix: str | None = None,
             maxit: int | None = None, table: bool | None = None,
             iteration_bound: int | str | None = None, cache: int | None = None,
             warm_start: bool = False) -> ExportedKernel:
    """Generate the C99 kernel of ``method`` on a problem or vehicle.

    Parameters
    ----------
    problem_or_vehicle : Problem, str, path or Vehicle
        The problem, or a vehicle (catalogue name or file: its ``[methods.<method>]``
        defaults apply under ``options``, as everywhere).
    method : str
        One of :data:`EXPORTABLE`.
    precision : {"double", "float"}
        The scalar type ``T`` of the kernel.
    options : mapping, optional
        The method's options, validated as :func:`alloc.make_allocator` does.  ``wls`` and
        ``qp`` export the compiled active set (``backend="active_set"``, the default);
        ``incremental`` pseudo-inverses are not exported.
    prefix : str, optional
        C prefix of the public names and file names; default ``alloc_<method>``.  A C
        identifier of at most 31 characters, not a keyword or a standard header's name
        (:func:`alloc.export.text.c_prefix`).  Every other user text (names, the vehicle's
        title, option values) reaches the C as comment text, escaped by
        :func:`alloc.export.text.comment_text`.
    maxit : int, optional
        Iteration cap per level of the active set; default the library's
        ``50 + 10 (m + k)``.  Lower only to exercise the cap (tests).  ``lp`` keeps the library's
        cap (refused: give ``iteration_bound``).
    table : bool, optional
        Active set: precompute the factorisation of every free set (2^m per level, the library's
        own ``_factor``, so the answers stay bit for bit) instead of factorising at run time;
        default: when the tables fit :data:`TABLE_BUDGET` bytes.  ``cgi`` always tabulates the
        pseudo-inverse of every free set: refused (ExportError naming ``table``) beyond the
        budget unless ``table=True``.  Every export is priced first (:mod:`alloc.export.cost`)
        and refused above 64 MiB of C, 60 s or 1 GiB of generation, naming ``table``,
        ``iteration_bound`` or ``m``.

    iteration_bound : int or "certify", optional
        Active set: the iterations a call with the nominal limits and no rate window may take
        (reaching it returns the safe answer with status 2); default ``levels * maxit``.
        ``lp``: the pivots such a call may take (the pivot beyond is not taken); default the
        library's ``50 (N + k) - 1``.
        ``"certify"`` sets it to the largest count the library needs on the deterministic
        sample of :func:`alloc.export.certify.certification_demands` (a sampled certification,
        not a proof: see :mod:`alloc.export.certify`; ``double`` only, since the sample is run
        in the library's double arithmetic).
    cache : int, optional
        Active set without tables: slots of the static, direct-mapped cache of the free sets'
        factorisations met last (0: none; a cached factorisation has the bits of a fresh one,
        so the cache changes the time, never the answer); default as many as fit
        :data:`CACHE_BUDGET` bytes, at most one per free set.
    warm_start : bool, optional
        Active set: keep the last answer's working set in static storage and start the next call
        from it when the first level's objective is not larger there than at the cold start
        (a smooth demand sequence then takes one iteration a level where the cold start takes
        several).  The answers then agree with the library's cold ones to round-off where the
        optimum is unique (bit for bit with its ``warm_start=True`` allocator's, double), and
        depend on the calls before (``PREFIX_warm_reset`` forgets them; ``PREFIX_set_limits``
        does too).  A warm run that reaches the budget is redone
        from the cold start under the same budget, so a call takes at most twice
        ``iteration_bound``.  Default False: every answer a function of the call alone, as the
        library's.

    Returns
    -------
    ExportedKernel
        The header and source text (:meth:`ExportedKernel.write` saves them).

    Raises
    ------
    UnknownMethodError
        for a method that is not exportable (listing those that are).
    OptionError
        naming an option the export does not support, or one the method refuses.
    ExportError
        naming the field for a precision, prefix or constant the export cannot take.
    """
    from ..api import make_allocator
    from ..registry import get_method

    method = _check_method(method)
    if precision not in PRECISIONS:
        raise ExportError(f"precision: expected one of {', '.join(PRECISIONS)}, got {precision!r}", field="precision")
    problem, title, opts = _resolve(problem_or_vehicle, method, options)
    exporter = exporter_for(method)
    exporter.check_options(method, opts)
    prefix = c_prefix(f"alloc_{method}" if prefix is None else prefix)
    allocator = make_allocator(problem, method, **opts)
    if allocator.impl is None:
        raise ExportError(f"method: {method} could not be built for this problem ({allocator.build_error})",
                          field="method")
    data = allocator.export_data()
    if data is None or data.kernel.kind != exporter.kind:
        raise ExportError(f"method: {method} with options {_short(opts)} has no {exporter.kind} kernel to export",
                          field="method")
    cls = get_method(method)
    real = _Real(precision)
    k, m = problem.k, problem.m
    umin, umax = real.inward(np.asarray(problem.umin, dtype=float), np.asarray(problem.umax, dtype=float))
    up = np.minimum(np.maximum(np.asarray(problem.up, dtype=float), umin), umax)
    safe_c, safe_p = (problem.up, np.zeros((m, k))) if data.safe is None else (data.safe.c, data.safe.P)
    c = real.consts
    shown = {key: value for key, value in opts.items()}
    # user text (names, the vehicle's title, option values) enters the C as comment text only
    fields = {
        "TITLE": comment_text(f"{method} allocation kernel, {k} axes x {m} effectors, {real.ctype}"),
        "VERSION": comment_text(_version()), "GENERATOR": GENERATOR_VERSION,
        "PROBLEM": comment_text(f"{title}, {k} x {m}, data sha256 {_checksum(problem)}"),
        "METHOD": comment_text(f"{method}: {cls.summary}"),
        "EQUATION": comment_text(cls.equation),
        "OPTIONS": "" if not shown else ("\n * Options : ", comment_text(", ".join(f"{a}={_short(b)}"
                                                                               for a, b in shown.items()))),
        "REAL": real.ctype, "K": str(k), "M": str(m),
        "AXES": comment_text(", ".join(map(comment_text, problem.axes)), _NAMES_CHARS),
        "EFFECTORS": comment_text(", ".join(map(comment_text, problem.names)), _NAMES_CHARS),
        "VMAX": c["VMAX"], "RTOL": c["RTOL"], "FABS": c["FABS"], "SQRT": c["SQRT"], "REAL_MAX": c["REAL_MAX"],
        "HEADER_NAME": f"{prefix}.h", "SOURCE_NAME": f"{prefix}.c",
        "ROUND_GAMMA": real.literal((m + 2) * (2.220446049250313e-16 if real.double else 2.0 ** -23), "gamma"),
        "B": real.array(problem.B, "B"), "UMIN": real.array(umin, "umin"), "UMAX": real.array(umax, "umax"),
        "UP": real.array(up, "up"), "RATE_MIN": real.array(problem.rate_min, "rate_min"),
        "RATE_MAX": real.array(problem.rate_max, "rate_max"),
        "SAFE_C": real.array(safe_c, "SafeCommand.c"), "SAFE_P": real.array(safe_p, "SafeCommand.P"),
        "BOUND": "", "HEALTH": "", "LIMITS_QUAL": "const ", "HEALTH_DECL": "", "MAXIT_DEFINE": "",
    }
    settings = Settings(precision=precision, maxit=maxit, table=table, iteration_bound=iteration_bound, cache=cache,
                        warm_start=bool(warm_start) if isinstance(warm_start, (bool, np.bool_)) else False)
    exporter.check_counts(method, settings)
    if not isinstance(warm_start, (bool, np.bool_)):
        raise ExportError(f"warm_start: expected True or False, got {warm_start!r}", field="warm_start")
    exporter.check_warm_start(method, bool(warm_start))
    exporter.check_table(method, table)
    cost = _price(method, exporter, data.kernel, problem, real, settings)
    filled = exporter.fill(data, allocator, problem, real, fields, settings)
    levels = filled.levels
    source = fill(templates.COMMON + filled.body, fields, prefix)
    header = fill(templates.HEADER, fields, prefix)
    return ExportedKernel(prefix=prefix, method=method, precision=precision, header=header, source=source,
                          header_name=f"{prefix}.h", source_name=f"{prefix}.c", k=k, m=m,
                          maxit=filled.cap, levels=levels, options=shown,
                          iteration_bound=filled.budget if levels else None,
                          certificate=filled.certificate if levels else None,
                          warm_start=bool(warm_start), cost=cost)
