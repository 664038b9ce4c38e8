"""What an export will cost, priced before any table is made (:func:`alloc.export.export_c`).

The generated source is the templates (a fixed size per kind of kernel, declared by its
exporter, :class:`alloc.export.exporter.Exporter`) plus printed numbers: the
problem's constants (``O(m k)``; the active set's level rows and weights, ``O(n m + m^2)``; the
simplex's tableau, ``O(k (m + k))``) and the tables, which dominate wherever they exist:

* ``cgi``: the pseudo-inverse of every free set, ``2^m`` rows of ``m k`` numbers (by level or
  not), one pseudo-inverse computed per free set and level;
* the active set with ``table=True``: every free set's factorisation per instance and key,
  ``2^m`` rows of ``entry`` numbers (:func:`alloc.export.tables.active_set_plan`), one
  factorisation per row;
* ``iteration_bound="certify"``: no source, but a library call per demand of the sample.

Bytes, seconds and peak memory are linear in those counts, with the coefficients below measured
on this generator (tests/alloc/export/test_cost.py measures a grid and keeps
measured / declared within [0.1, 2]).  An export priced above :data:`MAX_SOURCE_BYTES`, :data:`MAX_GENERATION_SECONDS` or
:data:`MAX_GENERATION_MEMORY` is refused with an :class:`~alloc.export.ExportError` naming the
field that drives it (``table`` for the tables, ``iteration_bound`` for the certification, ``m``
otherwise), before the work is done.
"""

from __future__ import annotations

from dataclasses import dataclass

from .base import ExportError

#: largest generated source (header and C file): 64 MiB of C is about 4 million numbers (a
#: double table of 32 MB; a flight computer holds far less)
MAX_SOURCE_BYTES = 64 * 2 ** 20
#: longest generation priced (CPU seconds on the reference machine, a 2-core 2026 CI runner)
MAX_GENERATION_SECONDS = 60.0
#: largest peak memory of the generator priced (the tables' text and its pieces)
MAX_GENERATION_MEMORY = 2 ** 30

#: bytes of one printed number with its separator: 13.2 measured on cgi tables (half of them
#: zeros), 21.7 on dense random constants; the declared value is between
BYTES_PER_NUMBER = 16
#: seconds to compute and print one number of a table or constant
SECONDS_PER_NUMBER = 2.5e-6
#: seconds per free set tabulated (a pseudo-inverse or a factorisation, and its row)
SECONDS_PER_FREE_SET = 4e-5
#: seconds and peak memory of the fixed part (checks, building the allocator, filling the
#: templates) by kind of kernel (each exporter names its own): the active set packs its solver
#: state (measured 3 ms and 3.3 MB at 6 x 10), the closed forms a few matrices (1 ms, 31 KB at 3 x 6)
FIXED_CLOSED = (0.004, 128 * 2 ** 10)
FIXED_ACTIVE_SET = (0.01, 4 * 2 ** 20)
FIXED_SIMPLEX = (0.005, 256 * 2 ** 10)
#: what to do about tables above the caps, where the kernel cannot do without them
TABLE_HINT = " (the table grows as m 2^m: fewer effectors)"
#: seconds per m^2 k of building the allocator (its pseudo-inverses and weights): 0.72 s
#: measured at 32 x 512
SECONDS_PER_BUILD = 8e-8
#: seconds per library call of the certification sample, and per (m + k)^2 more (measured
#: 4.7 us a call at 3 x 6, 13 us at 6 x 16: 3 us + 0.02 us (m + k)^2, declared twice that)
SECONDS_PER_CERTIFY_CALL = 6e-6
SECONDS_PER_CERTIFY_SIZE = 4e-8
#: peak memory per byte of source: the rows' strings, their join and the filled text
MEMORY_PER_BYTE = 4.0
#: peak memory per demand of the certification sample and axis (the sample's arrays)
MEMORY_PER_CERTIFY_NUMBER = 32
#: peak memory per m^2 (the m x m weights and their factors the allocator builds: 7.3 MB
#: measured at 32 x 512)
MEMORY_PER_M2 = 24


@dataclass(frozen=True)
class ExportCost:
    """The priced size of one export: what it prints and computes, and what that costs."""

    #: numbers printed (constants and tables)
    numbers: int
    #: of which in tables
    table_numbers: int
    #: free sets tabulated (pseudo-inverses or factorisations computed)
    free_sets: int
    #: library calls of the certification sample (``iteration_bound="certify"``), else 0
    certify_calls: int
    #: the problem's sizes, for the per-call price of the certification
    k: int
    m: int
    method: str
    #: bytes of the kernel's templates and the header's prose (its exporter's, measured)
    template_bytes: int = 0
    #: seconds and peak memory of the fixed part (its exporter's: :data:`FIXED_CLOSED`, ...)
    fixed: tuple[float, int] = FIXED_CLOSED
    #: what to do about tables above the caps (its exporter's)
    table_hint: str = TABLE_HINT

    @property
    def source_bytes(self) -> int:
        """Bytes of the header and the C file."""
        return self.template_bytes + BYTES_PER_NUMBER * self.numbers

    @property
    def seconds(self) -> float:
        """CPU seconds of generation on the reference machine."""
        return (self.fixed[0] + SECONDS_PER_BUILD * self.m ** 2 * self.k + SECONDS_PER_NUMBER * self.numbers
                + SECONDS_PER_FREE_SET * self.free_sets + self.certify_seconds)

    @property
    def certify_seconds(self) -> float:
        return self.certify_calls * (SECONDS_PER_CERTIFY_CALL + SECONDS_PER_CERTIFY_SIZE * (self.m + self.k) ** 2)

    @property
    def memory_bytes(self) -> int:
        """Peak memory of generation."""
        return int(self.fixed[1] + MEMORY_PER_BYTE * self.source_bytes + MEMORY_PER_M2 * self.m ** 2
                   + MEMORY_PER_CERTIFY_NUMBER * self.certify_calls * self.k)


def check(cost: ExportCost) -> ExportCost:
    """``cost`` if within the caps, else :class:`ExportError` naming the field that drives it."""
    method = cost.method
    tables = cost.table_numbers > (cost.numbers - cost.table_numbers)
    field = "table" if tables else "m"
    what = (f"{method}'s tables of the 2^{cost.m} free sets ({cost.table_numbers:,} numbers)" if tables
            else f"{method}'s constants for {cost.k} x {cost.m} ({cost.numbers:,} numbers)")
    hint = cost.table_hint if tables else ""
    certify_memory = MEMORY_PER_CERTIFY_NUMBER * cost.certify_calls * cost.k
    if cost.certify_seconds > MAX_GENERATION_SECONDS or certify_memory > MAX_GENERATION_MEMORY:
        raise ExportError(f"iteration_bound: certifying on {cost.certify_calls:,} demands of {cost.k} x {cost.m} "
                          f"takes about {cost.certify_seconds:,.0f} s and {certify_memory / 2 ** 20:,.0f} MiB, above "
                          f"the caps ({MAX_GENERATION_SECONDS:g} s, {MAX_GENERATION_MEMORY // 2 ** 20} MiB; the "
                          "sample's grid grows as 3^k): give an integer bound", field="iteration_bound")
    if cost.source_bytes > MAX_SOURCE_BYTES:
        raise ExportError(f"{field}: {what} make about {cost.source_bytes / 2 ** 20:,.0f} MiB of C, above the "
                          f"{MAX_SOURCE_BYTES // 2 ** 20} MiB cap{hint}", field=field)
    if cost.memory_bytes > MAX_GENERATION_MEMORY:
        raise ExportError(f"{field}: {what} need about {cost.memory_bytes / 2 ** 20:,.0f} MiB to generate, above "
                          f"the {MAX_GENERATION_MEMORY // 2 ** 20} MiB cap{hint}", field=field)
    if cost.seconds > MAX_GENERATION_SECONDS:
        raise ExportError(f"{field}: {what} take about {cost.seconds:,.0f} s to generate, above the "
                          f"{MAX_GENERATION_SECONDS:g} s cap{hint}", field=field)
    return cost
