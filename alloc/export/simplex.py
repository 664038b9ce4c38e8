"""Export of the compiled lexicographic simplex (kind ``simplex``: ``lp``): the library's scaled
problem printed as constants, its pivot cap and an optional per-call pivot bound
(:mod:`alloc.export.tables`)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from ..exceptions import OptionError
from ..export_data import ExportData, SimplexData
from ..problem import Problem
from .base import ExportError, _Real
from .certify import SIMPLEX_RANDOM_DEMANDS, simplex_bound_text
from .cost import FIXED_SIMPLEX
from .exporter import Exporter, Filled, Priced, Settings, _no_tables, exporter
from .tables import _iteration_budget, _simplex_fields, _simplex_pivots

#: bytes of the templates and the header's prose (measured 21,733)
TEMPLATE_BYTES = 22_000


@exporter("simplex")
class SimplexExporter(Exporter):
    certify_random = SIMPLEX_RANDOM_DEMANDS
    fixed = FIXED_SIMPLEX

    def check_options(self, method: str, options: Mapping[str, Any]) -> None:
        if options.get("backend", "simplex") != "simplex":
            raise OptionError(f"backend: {method} exports the library's compiled simplex only, got "
                              f"{options['backend']!r}", field="backend")

    def check_counts(self, method: str, settings: Settings) -> None:
        """Takes an iteration (pivot) bound only: the library's pivot cap stays, and there are no
        factorisations to cache."""
        for name in ("maxit", "cache"):
            if getattr(settings, name) is not None:
                raise ExportError(f"{name}: {method} keeps the library's pivot cap and has no factorisations to "
                                  "cache (give iteration_bound to bound its pivots)", field=name)

    def check_table(self, method: str, table: bool | None) -> None:
        if table is not None:  # not even table=False: there is no choice to make
            raise ExportError(_no_tables(method), field="table")

    def price(self, data: Any, problem: Problem, real: _Real, settings: Settings) -> Priced:
        assert isinstance(data, SimplexData)
        F, costs = data.F, data.costs
        return Priced(numbers=F.size + costs.size + F.shape[0] + F.shape[1], template_bytes=TEMPLATE_BYTES)

    def fill(self, export: ExportData, allocator: Any, problem: Problem, real: _Real, fields: dict[str, Any],
             settings: Settings) -> Filled:
        data = export.kernel
        assert isinstance(data, SimplexData)
        body, cap = _simplex_fields(data, real, fields)
        # one pivot budget a call (its stages share it, as the library's cap)
        budget, cert = _iteration_budget(settings.iteration_bound, allocator, problem, settings.precision, cap - 1,
                                         count=_simplex_pivots(data, problem), unit="pivots",
                                         random=SIMPLEX_RANDOM_DEMANDS)
        fields["BOUND"] = simplex_bound_text(cap, budget, cert)
        fields["MAXIT_DEFINE"] += ("/* pivots of a call with the nominal limits and no rate window (see above) */\n"
                                   f"#define PFX_ITERATION_BOUND {budget}\n")
        return Filled(body=body, levels=1, cap=cap, budget=budget, certificate=cert)
