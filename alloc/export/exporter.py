"""How each kind of kernel is exported: one :class:`Exporter` per kind, registered with
``@exporter(kind)``.

A method declares the kind of its kernel at registration (``@register("name",
export="affine")``, :attr:`alloc.method.Method.export`) and describes a built instance with
:meth:`alloc.method.Method.export_data` (:mod:`alloc.export_data`).  :func:`alloc.export.export_c`
finds the kind's exporter here and lets it check the options and settings, price the kernel
and fill the template's fields; it never asks which method it is exporting.  The exportable
methods are those whose kind has an exporter (:func:`exportable`).

Adding a method of an existing kind is its registration alone; a new kind is one module of
:mod:`alloc.export` with an :class:`Exporter` subclass under ``@exporter("kind")`` (imported by
the package), and a description class in :mod:`alloc.export_data`.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

from ..export_data import KINDS, ExportData, KernelData
from ..problem import Problem
from .base import ExportError, _Real
from .certify import Certificate
from .cost import FIXED_CLOSED, TABLE_HINT

__all__ = ["Exporter", "Filled", "Priced", "Settings", "exportable", "exporter", "exporter_for", "methods_of_kind"]


@dataclass(frozen=True)
class Settings:
    """The generator's settings of one export (:func:`alloc.export.export_c`'s arguments)."""

    precision: str
    maxit: int | None
    table: bool | None
    iteration_bound: int | str | None
    cache: int | None
    warm_start: bool


@dataclass(frozen=True)
class Priced:
    """What a kernel prints beyond the common constants, before it is made (:mod:`alloc.export.cost`)."""

    #: constants besides the tables
    numbers: int
    #: numbers of the precomputed tables
    table_numbers: int = 0
    #: free sets factorised (or inverted) for the tables
    free_sets: int = 0
    #: bytes of the kind's templates and the header's prose (measured)
    template_bytes: int = 0


@dataclass(frozen=True)
class Filled:
    """The kind's template and what :class:`alloc.export.ExportedKernel` reports of it."""

    #: the source template after :data:`alloc.export.templates.COMMON`
    body: str
    #: levels of the iteration cap (0: closed form)
    levels: int = 0
    #: iteration (pivot) cap per level, or None
    cap: int | None = None
    #: iterations (pivots) a call with the nominal limits may take, and the sampled certification
    budget: int | None = None
    certificate: Certificate | None = None


class Exporter:
    """Export of one kind of kernel; the defaults are a closed form's (no iterations, no
    tables, no working set).  Subclasses set :attr:`kind` and implement :meth:`price` and
    :meth:`fill`."""

    #: the kind it exports (:data:`alloc.export_data.KINDS`), set by :func:`exporter`
    kind: ClassVar[str] = ""
    #: extra random demands of the certification sample (:func:`alloc.export.certify.sample_size`)
    certify_random: ClassVar[int] = 0
    #: seconds and peak memory of the fixed part of an export (:mod:`alloc.export.cost`)
    fixed: ClassVar[tuple[float, int]] = FIXED_CLOSED
    #: what to do about tables above the export's caps
    table_hint: ClassVar[str] = TABLE_HINT
    #: the kernel keeps a working set between calls when exported with ``warm_start``
    keeps_working_set: ClassVar[bool] = False

    def check_options(self, method: str, options: Mapping[str, Any]) -> None:
        """Refuse (OptionError naming it) an option whose kernel is not exported; before the build."""

    def check_counts(self, method: str, settings: Settings) -> None:
        """Refuse ``iteration_bound``, ``maxit``, ``cache`` where the kernel has no use for them."""
        for name in ("iteration_bound", "maxit", "cache"):
            if getattr(settings, name) is not None:
                raise ExportError(f"{name}: {method} is closed-form (no iterations to cap or bound, or "
                                  "factorisations to cache)", field=name)

    def check_warm_start(self, method: str, warm_start: bool) -> None:
        """Refuse ``warm_start`` where there is no working set to keep."""
        if warm_start:
            keeping = ", ".join(m for m in exportable() if _EXPORTERS[_kind(m)].keeps_working_set)
            raise ExportError(f"warm_start: {method} has no working set to keep (only the active-set methods "
                              f"{keeping} do)", field="warm_start")

    def check_table(self, method: str, table: bool | None) -> None:
        """Refuse ``table`` where there are no tables to make."""
        if table:
            raise ExportError(_no_tables(method), field="table")

    def price(self, data: KernelData, problem: Problem, real: _Real, settings: Settings) -> Priced:
        """What the kernel prints beyond the common constants, before any table is made."""
        raise NotImplementedError

    def fill(self, export: ExportData, allocator: Any, problem: Problem, real: _Real, fields: dict[str, Any],
             settings: Settings) -> Filled:
        """Add the kind's constants to ``fields`` and return its template (``allocator``: the
        built allocator, run by the certification)."""
        raise NotImplementedError


#: kind -> its exporter; filled by :func:`exporter` when :mod:`alloc.export` imports its kinds
_EXPORTERS: dict[str, Exporter] = {}


def exporter(kind: str) -> Callable[[type[Exporter]], type[Exporter]]:
    """Class decorator registering the exporter of kernels of ``kind``."""
    if kind not in KINDS:
        raise TypeError(f"exporter: unknown kind {kind!r}; declared kinds: {', '.join(KINDS)}")

    def deco(cls: type[Exporter]) -> type[Exporter]:
        if kind in _EXPORTERS:
            raise ValueError(f"exporter of {kind!r} registered twice")
        cls.kind = kind
        _EXPORTERS[kind] = cls()
        return cls

    return deco


def _kind(method: str) -> str:
    from ..registry import get_method

    return get_method(method).export or ""


def exportable() -> tuple[str, ...]:
    """The methods :func:`alloc.export.export_c` generates: those whose declared kind has an
    exporter, in :func:`alloc.registry.exportable`'s order (closed forms first)."""
    from ..registry import exportable as declared

    return tuple(m for m in declared() if _kind(m) in _EXPORTERS)


def methods_of_kind(kind: str) -> list[str]:
    """The exportable methods of one kind, in :func:`exportable`'s order."""
    return [m for m in exportable() if _kind(m) == kind]


def exporter_for(method: str) -> Exporter:
    """The exporter of an exportable ``method``'s kind."""
    return _EXPORTERS[_kind(method)]


def _no_tables(method: str) -> str:
    cascades = " and ".join(methods_of_kind("cascade"))
    return f"table: {method} has no tables to make (only {cascades} and the active-set methods do)"
