"""Export of the cascaded generalized inverse (kind ``cascade``: ``cgi``): a table of every free
set's pseudo-inverse, by priority level or not (:mod:`alloc.export.tables`)."""

from __future__ import annotations

from typing import Any

from ..export_data import CascadeData, ExportData
from ..problem import Problem
from . import templates_cascade, templates_closed_form
from .base import _Real
from .exporter import Exporter, Filled, Priced, Settings, exporter
from .tables import _cascade_level_fields, _cascade_table

#: bytes of the templates and the header's prose (the closed forms' 9,000 and the cascade's loop)
TEMPLATE_BYTES = 10_000


def _by_level(data: CascadeData) -> bool:
    return data.groups is not None and len(data.groups) > 1


@exporter("cascade")
class CascadeExporter(Exporter):
    def check_table(self, method: str, table: bool | None) -> None:
        """Always tabulated: the budget check is the table's own (:func:`alloc.export.tables._check_cascade_table`)."""

    def price(self, data: Any, problem: Problem, real: _Real, settings: Settings) -> Priced:
        assert isinstance(data, CascadeData)
        k, m = problem.k, problem.m
        levels = len(data.groups) if _by_level(data) else 1  # type: ignore[arg-type]
        return Priced(numbers=0, table_numbers=(m * k) << m, free_sets=levels << m, template_bytes=TEMPLATE_BYTES)

    def fill(self, export: ExportData, allocator: Any, problem: Problem, real: _Real, fields: dict[str, Any],
             settings: Settings) -> Filled:
        data = export.kernel
        assert isinstance(data, CascadeData)
        if _by_level(data):
            fields.update(_cascade_level_fields(data, problem, real, settings.table))
            return Filled(body=templates_cascade.CASCADE_LEVELS)
        fields.update(TAB_P=_cascade_table(data, problem, real, settings.table))
        return Filled(body=templates_closed_form.CASCADE)
