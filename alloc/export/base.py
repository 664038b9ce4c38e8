"""What the C generator's modules share: its constants, :class:`ExportError`,
:class:`ExportedKernel` and how constants of one precision are printed.

A leaf of :mod:`alloc.export`: the generator (``__init__``) and the table builders
(:mod:`alloc.export.tables`) both import it, and it imports neither.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..exceptions import AllocError
from ..problem import MAX_MAGNITUDE
from ..result import EXACT_RTOL
from .._engine._warm import WARM_COND_MAX, WARM_ROUND_OFF  # noqa: F401 - re-exported (export's names)
from .certify import Certificate

#: bumped whenever the generated code changes for the same input
GENERATOR_VERSION = "5"
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
# the warm start's conditioning limits (WARM_COND_MAX, WARM_ROUND_OFF) are the library's, shared with the
# host's warm_start option: alloc/_engine/_warm.py

#: ``float`` ``lp``: the simplex's tolerances (alloc._engine._simplex's names; the double build takes the
#: library's values) at float's round-off.  Reduced costs and pivots at 1e-5 (about 80 float ulps
#: of the O(1) scaled tableau, as FLOAT_SIGMA_RTOL); ties, degenerate steps and singular pivots at
#: 1e-6 (8 ulps); the final feasibility check at 1e-4 relative (the library's 1e-9 is below a
#: float basic value's round-off); the right-hand side clamped at 1e30 (1e200 is beyond float)
FLOAT_SIMPLEX_TOLS = {"DUAL_TOL": 1e-5, "PIVOT_TOL": 1e-5, "TIE_RTOL": 1e-6, "DEGENERATE_TOL": 1e-6,
                      "SINGULAR_TOL": 1e-6, "FEASIBLE_RTOL": 1e-4, "B_CLAMP": 1e30}

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
    #: iteration cap per level (active-set methods), the pivot cap ``50 (N + k)`` (``lp``), else None
    maxit: int | None = None
    #: levels of the active set (its total cap is ``levels * maxit``); 1 for ``lp``
    levels: int = 0
    #: iterations (``lp``: pivots) a call with the nominal limits and no rate window may take
    iteration_bound: int | None = None
    #: the sampled certification behind ``iteration_bound`` (``iteration_bound="certify"``)
    certificate: Certificate | None = None
    options: dict[str, Any] = field(default_factory=dict)
    #: the active set keeps its last working set between calls (``warm_start=True``)
    warm_start: bool = False
    #: the size and generation time and memory priced before it was made (alloc.export.cost)
    cost: Any = None

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


def _short(value: Any) -> str:
    text = repr(value.tolist() if isinstance(value, np.ndarray) else value)
    return text if len(text) <= 60 else text[:57] + "..."


def _version() -> str:
    from .. import __version__

    return __version__
