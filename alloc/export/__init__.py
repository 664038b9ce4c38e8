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

Methods: ``pinv``, ``pinv_clip``, ``ganging`` (``u = clip(c + P v)``), ``pinv_scale`` (the
increment scaled into the box), ``cgi`` (the cascaded generalized inverse over a table of every
free set's pseudo-inverse; without priority levels) and the active-set ``wls``, ``qp`` (with ``priorities``) and
``dynamic`` (its two solver instances, without and with ``u_prev``), whose iteration count per
level is capped at the library's own cap and per call at ``iteration_bound`` (by default the
levels' caps added; ``"certify"``: the largest count on a dense sample of the demand set,
:mod:`alloc.export.certify`), both stated and argued in the header and enforced: reaching
either returns the safe answer with status 2.

Health at run time: the active-set kernels take reduced limits and jams through
``alloc_<method>_set_limits``; the closed-form kernels bake the distribution matrix of the
problem's health into their constants, so a jam or an effectiveness change there means
generating again (``Problem.with_health``), as does an effectiveness change for any method.
"""

from __future__ import annotations

import hashlib
import os
import unicodedata
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from ..exceptions import AllocError, OptionError, UnknownMethodError
from ..problem import MAX_MAGNITUDE, Problem
from ..result import EXACT_RTOL
from . import templates, templates_active_set, templates_cascade, templates_closed_form
from .certify import Certificate, bound_text, certify

__all__ = ["export_c", "ExportedKernel", "ExportError", "EXPORTABLE", "PRECISIONS", "GENERATOR_VERSION",
           "FLOAT_TOLERANCE", "FLOAT_EXACT_RTOL", "FLOAT_VMAX", "Certificate"]

#: bumped whenever the generated code changes for the same input
GENERATOR_VERSION = "3"
#: the methods :func:`export_c` generates, in the order the docs list them
EXPORTABLE = ("pinv", "pinv_clip", "ganging", "pinv_scale", "cgi", "wls", "qp", "dynamic")
PRECISIONS = ("double", "float")
#: ``float`` builds: the status ``exact`` tolerance (the library's 1e-6 is 8 float ulps at 1,
#: below what a float residual with its rounding bound can certify)
FLOAT_EXACT_RTOL = 1e-4
#: ``float`` builds: the valid input domain (the library's 1e50 is beyond float's range)
FLOAT_VMAX = 1e30
#: ``float`` builds agree with the library within ``FLOAT_TOLERANCE * max(1, limit span)`` on the
#: commands: every call of the closed forms, 99 % of ``qp`` calls (demands on the attainable set's
#: boundary can differ more: rounding to float changes what is attainable); ``wls`` where
#: ``gamma^2`` is above float's resolution (``gamma >= 1e-2``).  Measured in tests/alloc/export/test_export.py.
FLOAT_TOLERANCE = 1e-5
#: ``float`` active set: singular values below this fraction of the largest are round-off
#: (about 80 float ulps, as the library's 1e-12 is about 4,500 double ulps)
FLOAT_SIGMA_RTOL = 1e-5
#: ``float`` active set: the multiplier tolerance in units of the round-off of its computation.
#: The library's 1e3 ulps, at float's ulp (1.2e-4 relative), stopped stage 1 of ICE qp short of
#: its optimum on 8 % of random demands (multipliers of a few 1e-5 read as zero); 8 ulps:
#: 0.3 %, and no cycling to the cap on the random suite, ICE or either hexacopter.
FLOAT_MU_EPS = 8 * 2.0 ** -23
#: ``cgi`` by level: the library's tolerances of a level met (its residual relative to
#: ``max(1, |v|)``) and of an effector saturated (the room left, as a fraction of the step)
CGI_RTOL = 1e-12
#: ``float`` builds: the same at float's round-off (1e-12 is below it: a level whose residual
#: float cannot bring under it takes steps the library does not)
FLOAT_CGI_RTOL = 1e-5
#: bytes of factorisation tables an active-set kernel precomputes by default (``table=None``):
#: every free set of every level (2^m rows a level); beyond it the kernel factorises at run time
TABLE_BUDGET = 256 * 1024
#: bytes of static storage an active-set kernel without tables keeps for its cache of the free
#: sets' factorisations met last (``cache=None``): the library's cache in a fixed size, no
#: heap.  16 KiB is under a tenth of an STM32F4's 192 KB of RAM; ICE qp keeps 26 free sets in
#: its 612-byte slots (the 4 x 6 hexacopter's kernels are tabulated and keep none)
CACHE_BUDGET = 16 * 1024

_ACTIVE_SET_METHODS = ("wls", "qp", "dynamic")


class ExportError(AllocError, ValueError):
    """A problem, method or option the C generator cannot export (naming the field)."""


@dataclass(frozen=True)
class ExportedKernel:
    """A generated kernel: the C sources and what they were made from."""

    #: the C prefix of every public name (``alloc_qp``)
    prefix: str
    method: str
    precision: str
    header: str
    source: str
    #: file names of the pair (``alloc_qp.h``, ``alloc_qp.c``)
    header_name: str
    source_name: str
    k: int
    m: int
    #: iteration cap per level (active-set methods), else None
    maxit: int | None = None
    #: levels of the active set (its total cap is ``levels * maxit``)
    levels: int = 0
    #: iterations a call with the nominal limits and no rate window may take (active set)
    iteration_bound: int | None = None
    #: the sampled certification behind ``iteration_bound`` (``iteration_bound="certify"``)
    certificate: Certificate | None = None
    options: dict[str, Any] = field(default_factory=dict)

    def write(self, out: str | os.PathLike[str]) -> tuple[Path, Path]:
        """Write the pair into folder ``out`` (created); returns the two paths."""
        folder = Path(out)
        folder.mkdir(parents=True, exist_ok=True)
        h, c = folder / self.header_name, folder / self.source_name
        h.write_text(self.header)
        c.write_text(self.source)
        return h, c


# --------------------------------------------------------------------------- formatting

class _Real:
    """How constants of one precision are printed and what the precision's limits are."""

    def __init__(self, precision: str) -> None:
        self.double = precision == "double"
        self.ctype = "double" if self.double else "float"

    def value(self, x: float, what: str) -> float:
        """``x`` in this precision (a float64 holding it); non-finite only if ``x`` is infinite."""
        x = float(x)
        if self.double or np.isinf(x):
            return x
        with np.errstate(over="ignore"):
            y = float(np.float32(x))
        if not np.isfinite(y):
            raise ExportError(f"{what}: {x:g} does not fit a float build (|x| > {np.finfo(np.float32).max:g})",
                              field=what.split("[")[0])
        return y

    def literal(self, x: float, what: str) -> str:
        y = self.value(x, what)
        if np.isinf(y):
            inf = "HUGE_VAL" if self.double else "HUGE_VALF"
            return inf if y > 0 else f"-{inf}"
        text = repr(y)
        return text if self.double else text + "f"

    def array(self, a: Any, what: str) -> str:
        arr = np.asarray(a, dtype=float)
        if arr.ndim == 1:
            return "{" + ", ".join(self.literal(x, f"{what}[{i}]") for i, x in enumerate(arr)) + "}"
        rows = ",\n    ".join(self.array(row, f"{what}[{i}]") for i, row in enumerate(arr))
        return "{\n    " + rows + "\n}"

    def inward(self, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Limits in this precision rounded inward (a float output within them is within the
        true limits); a jam (``lo == hi``) keeps its nearest float."""
        if self.double:
            return lo, hi
        l32, h32 = lo.astype(np.float32), hi.astype(np.float32)
        up = l32.astype(float) < lo
        l32[up] = np.nextafter(l32[up], np.float32(np.inf))
        down = h32.astype(float) > hi
        h32[down] = np.nextafter(h32[down], np.float32(-np.inf))
        crossed = l32 > h32
        l32[crossed] = h32[crossed] = lo[crossed].astype(np.float32)
        return l32.astype(float), h32.astype(float)

    @property
    def consts(self) -> dict[str, str]:
        if self.double:
            return {"FABS": "fabs", "SQRT": "sqrt", "REAL_MAX": "DBL_MAX", "VMAX": repr(MAX_MAGNITUDE),
                    "RTOL": repr(EXACT_RTOL)}
        return {"FABS": "fabsf", "SQRT": "sqrtf", "REAL_MAX": "FLT_MAX", "VMAX": f"{FLOAT_VMAX!r}f",
                "RTOL": f"{FLOAT_EXACT_RTOL!r}f"}


def _ints(a: Any) -> str:
    return "{" + ", ".join(str(int(x)) for x in a) + "}"


def _fill(text: str, fields: Mapping[str, str], prefix: str) -> str:
    for key, value in fields.items():
        text = text.replace(f"@{key}@", value)
    text = text.replace("PREFIX_", prefix + "_").replace("PFX_", prefix.upper() + "_")
    # ASCII only (names and titles reach the comments): C99's source character set, and what
    # every embedded toolchain reads; accents are dropped ("Härkegård" -> "Harkegard")
    plain = unicodedata.normalize("NFKD", text)
    return plain.encode("ascii", "ignore").decode("ascii")


# --------------------------------------------------------------------------- the generator

def _resolve(problem_or_vehicle: Any, method: str, options: Mapping[str, Any] | None) -> tuple[Problem, str, dict]:
    if isinstance(problem_or_vehicle, Problem):
        return problem_or_vehicle, f"alloc.Problem {problem_or_vehicle.k} x {problem_or_vehicle.m}", dict(options or {})
    from .. import vehicles

    vehicle = vehicles.get_vehicle(problem_or_vehicle)
    merged = vehicles.method_options(vehicle, method, options)
    title = f"vehicle {vehicle.name!r}" + (f" ({vehicle.description})" if vehicle.description else "")
    return vehicle.problem(), title, merged


def _check_method(method: Any) -> str:
    if not isinstance(method, str) or method not in EXPORTABLE:
        raise UnknownMethodError(f"method: {method!r} cannot be exported to C; exportable: {', '.join(EXPORTABLE)}",
                                 field="method")
    return method


def _checksum(problem: Problem) -> str:
    h = hashlib.sha256()
    for a in (problem.B, problem.umin, problem.umax, problem.up, problem.Wu, problem.Wv, problem.rate_min,
              problem.rate_max):
        h.update(np.ascontiguousarray(a, dtype=float).tobytes())
    return h.hexdigest()[:16]


def export_c(problem_or_vehicle: Any, method: str = "qp", *, precision: str = "double",
             options: Mapping[str, Any] | None = None, prefix: str | None = None,
             maxit: int | None = None, table: bool | None = None,
             iteration_bound: int | str | None = None, cache: int | None = None) -> ExportedKernel:
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
        C prefix of the public names and file names; default ``alloc_<method>``.
    maxit : int, optional
        Iteration cap per level of the active set; default the library's
        ``50 + 10 (m + k)``.  Lower only to exercise the cap (tests).
    table : bool, optional
        Active set: precompute the factorisation of every free set (2^m per level, the library's
        own ``_factor``, so the answers stay bit for bit) instead of factorising at run time;
        default: when the tables fit :data:`TABLE_BUDGET` bytes.  ``cgi`` always tabulates the
        pseudo-inverse of every free set: refused (ExportError naming ``table``) beyond the
        budget unless ``table=True``.

    iteration_bound : int or "certify", optional
        Active set: the iterations a call with the nominal limits and no rate window may take
        (reaching it returns the safe answer with status 2); default ``levels * maxit``.
        ``"certify"`` sets it to the largest count the library needs on the deterministic
        sample of :func:`alloc.export.certify.certification_demands` (a sampled certification,
        not a proof: see :mod:`alloc.export.certify`; ``double`` only, since the sample is run
        in the library's double arithmetic).
    cache : int, optional
        Active set without tables: slots of the static, direct-mapped cache of the free sets'
        factorisations met last (0: none; a cached factorisation has the bits of a fresh one,
        so the cache changes the time, never the answer); default as many as fit
        :data:`CACHE_BUDGET` bytes, at most one per free set.

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

    method = _check_method(method)
    if precision not in PRECISIONS:
        raise ExportError(f"precision: expected one of {', '.join(PRECISIONS)}, got {precision!r}", field="precision")
    problem, title, opts = _resolve(problem_or_vehicle, method, options)
    if opts.get("incremental"):
        raise OptionError(f"incremental: {method} with incremental=True is not exported (the bias is u_prev)",
                          field="incremental")
    if method in _ACTIVE_SET_METHODS and opts.get("backend", "active_set") != "active_set":
        raise OptionError(f"backend: only the compiled active set is exported, got {opts['backend']!r}",
                          field="backend")
    prefix = f"alloc_{method}" if prefix is None else prefix
    if not (isinstance(prefix, str) and prefix.isidentifier() and prefix.isascii()):
        raise ExportError(f"prefix: expected a C identifier, got {prefix!r}", field="prefix")
    allocator = make_allocator(problem, method, **opts)
    if allocator.impl is None:
        raise ExportError(f"method: {method} could not be built for this problem ({allocator.build_error})",
                          field="method")
    real = _Real(precision)
    k, m = problem.k, problem.m
    umin, umax = real.inward(np.asarray(problem.umin, dtype=float), np.asarray(problem.umax, dtype=float))
    up = np.minimum(np.maximum(np.asarray(problem.up, dtype=float), umin), umax)
    safe = allocator._safe._pinv
    safe_c, safe_p = (problem.up, np.zeros((m, k))) if safe is None else (safe.c, safe.P)
    c = real.consts
    shown = {key: value for key, value in opts.items()}
    fields = {
        "TITLE": f"{method} allocation kernel, {k} axes x {m} effectors, {real.ctype}",
        "VERSION": _version(), "GENERATOR": GENERATOR_VERSION,
        "PROBLEM": f"{title}, {k} x {m}, data sha256 {_checksum(problem)}",
        "METHOD": f"{method}: {type(allocator.impl).summary}", "EQUATION": type(allocator.impl).equation,
        "OPTIONS": "" if not shown else "\n * Options : " + ", ".join(f"{a}={_short(b)}" for a, b in shown.items()),
        "REAL": real.ctype, "K": str(k), "M": str(m),
        "AXES": ", ".join(problem.axes), "EFFECTORS": ", ".join(problem.names),
        "VMAX": c["VMAX"], "RTOL": c["RTOL"], "FABS": c["FABS"], "SQRT": c["SQRT"], "REAL_MAX": c["REAL_MAX"],
        "HEADER_NAME": f"{prefix}.h", "SOURCE_NAME": f"{prefix}.c",
        "ROUND_GAMMA": real.literal((m + 2) * (2.220446049250313e-16 if real.double else 2.0 ** -23), "gamma"),
        "B": real.array(problem.B, "B"), "UMIN": real.array(umin, "umin"), "UMAX": real.array(umax, "umax"),
        "UP": real.array(up, "up"), "RATE_MIN": real.array(problem.rate_min, "rate_min"),
        "RATE_MAX": real.array(problem.rate_max, "rate_max"),
        "SAFE_C": real.array(safe_c, "SafeCommand.c"), "SAFE_P": real.array(safe_p, "SafeCommand.P"),
        "BOUND": "", "HEALTH": "", "LIMITS_QUAL": "const ", "HEALTH_DECL": "", "MAXIT_DEFINE": "",
    }
    impl = allocator.impl
    levels = 0
    budget, cert = None, None
    for name, given in (("iteration_bound", iteration_bound), ("cache", cache)):
        if given is not None and method not in _ACTIVE_SET_METHODS:
            raise ExportError(f"{name}: {method} is closed-form (no iterations to bound or factorisations to cache)",
                              field=name)
    if method in ("pinv", "pinv_clip", "ganging"):
        map_c, map_p = impl.fused
        fields.update(MAP_C=real.array(map_c, "c"), MAP_P=real.array(map_p, "P"))
        body = templates_closed_form.AFFINE
    elif method == "pinv_scale":
        fields.update(MAP_P=real.array(impl._P, "P"))
        body = templates_closed_form.SCALED
    elif method == "cgi" and impl.groups is not None and len(impl.groups) > 1:
        fields.update(_cascade_level_fields(impl, problem, real, table))
        body = templates_cascade.CASCADE_LEVELS
    elif method == "cgi":
        fields.update(TAB_P=_cascade_table(impl, problem, real, table))
        body = templates_closed_form.CASCADE
    else:
        lexico = [impl._static, impl._dynamic] if method == "dynamic" else [impl._impl]
        body, levels, maxit = _active_set_fields(lexico, problem, real, fields, maxit, table, cache)
        budget, cert = _iteration_budget(iteration_bound, allocator, problem, precision, levels * maxit)
        fields["BOUND"] = bound_text(m, levels, maxit, budget, cert)
        fields["MAXIT_DEFINE"] += ("/* iterations of a call with the nominal limits and no rate window (see above) */\n"
                                   f"#define PFX_ITERATION_BOUND {budget}\n")
    source = _fill(templates.COMMON + body, fields, prefix)
    header = _fill(templates.HEADER, fields, prefix)
    return ExportedKernel(prefix=prefix, method=method, precision=precision, header=header, source=source,
                          header_name=f"{prefix}.h", source_name=f"{prefix}.c", k=k, m=m,
                          maxit=maxit if levels else None, levels=levels, options=shown,
                          iteration_bound=budget if levels else None, certificate=cert if levels else None)


def _cascade_table(impl: Any, problem: Problem, real: _Real, table: bool | None) -> str:
    """Every free set's weighted pseudo-inverse, computed as the library's ``cgi`` computes it
    (so the kernel returns its bits): the C table of :data:`templates_closed_form.CASCADE`."""
    from .._kernels import free_set_pinv
    from .._linalg import ABS_FLOOR

    k, m = problem.k, problem.m
    _check_cascade_table(m, k, real, table)
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


def _check_cascade_table(m: int, k: int, real: _Real, table: bool | None) -> None:
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


def _cascade_level_fields(impl: Any, problem: Problem, real: _Real, table: bool | None) -> dict[str, str]:
    """``cgi`` with priority levels: each level's axes and its table of the prioritised
    pseudo-inverse of every free set, from the library's own ``_level_pinv`` (the columns of the
    level's own axes), so the kernel returns the library's bits."""
    k, m = problem.k, problem.m
    _check_cascade_table(m, k, real, table)
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


def _active_set_fields(instances: list[Any], problem: Problem, real: _Real, fields: dict[str, str],
                       maxit: int | None, table: bool | None, cache: int | None) -> tuple[str, int, int]:
    """The active set's constants, read from the library's packed solver states
    (:func:`alloc._active_set.pack`), so the C runs on exactly the library's data.  One
    instance for ``qp`` and ``wls``; ``dynamic`` has two (without and with ``u_prev``), which
    share every level row and differ in the preference weight, cold start and target."""
    from types import SimpleNamespace

    from .. import _active_set, _lsq_factor
    # the packed state's layout and the level iteration are in _active_set, the free sets'
    # factorisation (and its tolerances) in _lsq_factor: the generator reads both by one name
    aset = SimpleNamespace(**{**vars(_lsq_factor), **vars(_active_set)})

    mats, vecs, ivecs = instances[0]._state[:3]
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
    diags = [int(lex._state[2][aset._HEAD, aset._DIAG]) for lex in instances]
    ml = 1 if all(diags) else m  # a diagonal L is stored in column 0 of its row
    fields.update(
        N=str(n), NLEV=str(nlev), FINAL=str(final), NCW=str(ncw), NLW=str(nlw), ML="1" if ml == 1 else "M",
        NINST=str(len(instances)),
        A=real.array(mats[aset._A, :n, :m], "A"), T=real.array(mats[aset._T, :n, :n], "T"),
        PERM=_ints(ivecs[aset._PERM, :n]), STARTS=_ints(ivecs[aset._STARTS, :nlev + 1]),
        GAM=real.array(vecs[aset._GAM, :nlev], "gamma"),
    )
    levels = nlev + final
    keys = _table_keys(ivecs, aset)
    entry = m * ml + m * ncw + ncw * ncw + ncw + m * nlw + nlw * nlw + nlw
    size = len(instances) * len(keys) * (1 << m) * entry * (8 if real.double else 4)
    if table is None:
        table = size <= TABLE_BUDGET
    if table and m > 20:
        raise ExportError(f"table: 2^{m} free sets a level is too many to tabulate", field="table")
    fields["TABLE"] = "1" if table else "0"
    slot_bytes = entry * (8 if real.double else 4) + 4 * (4 + m)
    slots = _cache_slots(cache, bool(table), slot_bytes, len(instances) * len(keys) << min(m, 30))
    fields["CACHE"] = str(slots)
    cached = (f" *\n * Cache: the factorisations of the last free sets met, in static storage ({slots} slots of\n"
              f" * about {slot_bytes} bytes); a factorisation depends on the free set alone, so the cache\n"
              " * changes the time of a call, never its answer.\n") if slots else ""
    fields["INSTANCES"] = _instances(instances, aset, keys, real, ml, bool(table))
    fields["HEALTH"] = (" *\n * Health at run time: PREFIX_set_limits(umin, umax) sets reduced limits or jams\n"
                        " * (umin[j] == umax[j]) within the nominal limits; an effectiveness change needs a new\n"
                        " * export.  The cold start and the safe answer keep the nominal Eq 1.23 matrix.\n" + cached)
    fields["HEALTH_DECL"] = templates.HEALTH_DECL
    fields["LIMITS_QUAL"] = ""
    fields["MAXIT_DEFINE"] = (f"/* iteration cap per level and per call (see the bound above) */\n"
                              f"#define PFX_MAXIT {cap}\n#define PFX_MAXIT_TOTAL {levels * cap}\n")
    return templates_active_set.ACTIVE_SET, levels, cap


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
                      total: int) -> tuple[int, Certificate | None]:
    """The per-call iteration budget of an active-set kernel, and the certification behind it."""
    if bound is None:
        return total, None
    if bound == "certify":
        if precision != "double":
            raise ExportError("iteration_bound: the certification runs the library in double; a float kernel's "
                              "counts can differ (give an integer)", field="iteration_bound")
        cert = certify(allocator, problem)
        return min(cert.bound, total), cert
    if isinstance(bound, bool) or not isinstance(bound, (int, np.integer)) or not 1 <= bound <= total:
        raise ExportError(f"iteration_bound: expected \"certify\" or an integer in [1, {total}], got {bound!r}",
                          field="iteration_bound")
    return int(bound), None


_TABLE_NAMES = ("L", "YC", "VC", "SC", "YA", "VA", "SA")


def _instances(instances: list[Any], aset: Any, keys: list[tuple[int, int]], real: _Real, ml: int,
               table: bool) -> str:
    """Each instance's constants and tables, and the ``INSTANCES`` array of the C source."""
    parts, inits = [], []
    for i, lex in enumerate(instances):
        mats, vecs, ivecs = lex._state[:3]
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
                         "   the library's own code (alloc._lsq_factor._factor): row [key][free-set bits] */")
            parts.append(_tables(mats, ivecs, aset, keys, real, ml, suffix=f"_{i}"))
        kv, ku = (f"KV_{i}", f"KU_{i}") if dyn else ("NULL", "NULL")
        tabs = "".join(f", TAB_{name}_{i}" for name in _TABLE_NAMES) if table else ""
        inits.append(f"    {{{diag}, WU_{i}, P0_{i}, UPT_{i}, {kv}, {ku}{tabs}}}")
    parts.append("static const struct instance INSTANCES[NINST] = {\n" + ",\n".join(inits) + "\n};")
    return "\n".join(parts)


def _short(value: Any) -> str:
    text = repr(value.tolist() if isinstance(value, np.ndarray) else value)
    return text if len(text) <= 60 else text[:57] + "..."


def _version() -> str:
    from .. import __version__

    return __version__


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
    factorisation would drop (below ``rtol`` of the scale, as :func:`alloc._lsq_factor._jacobi`
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
