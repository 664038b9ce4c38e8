"""Export of the compiled lexicographic least-squares active set (kind ``active_set``: ``wls``,
``qp``, ``dynamic``): the library's packed solver states printed as constants, the iteration
cap per level and per call, optional tables, cache and warm start (:mod:`alloc.export.tables`)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from ..exceptions import OptionError
from ..export_data import ActiveSetData, ExportData
from ..problem import Problem
from .base import _Real
from .certify import bound_text
from .cost import FIXED_ACTIVE_SET
from .exporter import Exporter, Filled, Priced, Settings, exporter
from .tables import _active_set_fields, _iteration_budget, active_set_plan

#: bytes of the templates and the header's prose, and more per instance beyond the first
#: (measured 31,221 to 37,209 with and without warm start; dynamic has two instances)
TEMPLATE_BYTES, INSTANCE_BYTES = 36_000, 2_000


@exporter("active_set")
class ActiveSetExporter(Exporter):
    keeps_working_set = True
    fixed = FIXED_ACTIVE_SET
    table_hint = " (give table=False: the active set factorises at run time)"

    def check_options(self, method: str, options: Mapping[str, Any]) -> None:
        if options.get("backend", "active_set") != "active_set":
            raise OptionError(f"backend: only the compiled active set is exported, got {options['backend']!r}",
                              field="backend")

    def check_counts(self, method: str, settings: Settings) -> None:
        """Takes an iteration bound, a cap per level and a cache."""

    def check_warm_start(self, method: str, warm_start: bool) -> None:
        """Keeps its working set when asked."""

    def check_table(self, method: str, table: bool | None) -> None:
        """Tabulates by default when the tables fit, or as asked."""

    def price(self, data: Any, problem: Problem, real: _Real, settings: Settings) -> Priced:
        assert isinstance(data, ActiveSetData)
        _, consts, tables, free_sets = active_set_plan(list(data.states), real, settings.table)
        return Priced(numbers=consts, table_numbers=tables, free_sets=free_sets,
                      template_bytes=TEMPLATE_BYTES + INSTANCE_BYTES * (len(data.states) - 1))

    def fill(self, export: ExportData, allocator: Any, problem: Problem, real: _Real, fields: dict[str, Any],
             settings: Settings) -> Filled:
        data = export.kernel
        assert isinstance(data, ActiveSetData)
        warm = settings.warm_start
        body, levels, cap = _active_set_fields(list(data.states), problem, real, fields, settings.maxit,
                                               settings.table, settings.cache, warm)
        budget, cert = _iteration_budget(settings.iteration_bound, allocator, problem, settings.precision,
                                         levels * cap)
        fields["BOUND"] = bound_text(problem.m, levels, cap, budget, cert, cap_given=settings.maxit is not None,
                                     warm=warm)
        fields["MAXIT_DEFINE"] += ("/* iterations of a call with the nominal limits and no rate window (see above) */\n"
                                   f"#define PFX_ITERATION_BOUND {budget}\n")
        return Filled(body=body, levels=levels, cap=cap, budget=budget, certificate=cert)
