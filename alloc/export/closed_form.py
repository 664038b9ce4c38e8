"""Export of the closed forms: ``u = clip(c + P v)`` (kind ``affine``: ``pinv``, ``pinv_clip``,
``ganging``) and the increment scaled into the box (kind ``scaled``: ``pinv_scale``)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from ..exceptions import OptionError
from ..export_data import AffineData, ExportData, ScaledData
from ..problem import Problem
from . import templates_closed_form
from .base import _Real
from .exporter import Exporter, Filled, Priced, Settings, exporter

#: bytes of the templates and the header's prose (measured 7,948 to 9,755 for the closed forms)
TEMPLATE_BYTES = 9_000


class _PseudoInverse(Exporter):
    def check_options(self, method: str, options: Mapping[str, Any]) -> None:
        # the bias of an incremental pseudo-inverse is u_prev: not the kernel's constant c
        if options.get("incremental"):
            raise OptionError(f"incremental: {method} with incremental=True is not exported (the bias is u_prev)",
                              field="incremental")


@exporter("affine")
class AffineExporter(_PseudoInverse):
    def price(self, data: Any, problem: Problem, real: _Real, settings: Settings) -> Priced:
        return Priced(numbers=problem.m + problem.m * problem.k, template_bytes=TEMPLATE_BYTES)

    def fill(self, export: ExportData, allocator: Any, problem: Problem, real: _Real, fields: dict[str, Any],
             settings: Settings) -> Filled:
        data = export.kernel
        assert isinstance(data, AffineData)
        fields.update(MAP_C=real.array(data.c, "c"), MAP_P=real.array(data.P, "P"))
        return Filled(body=templates_closed_form.AFFINE)


@exporter("scaled")
class ScaledExporter(_PseudoInverse):
    def price(self, data: Any, problem: Problem, real: _Real, settings: Settings) -> Priced:
        return Priced(numbers=problem.m * problem.k, template_bytes=TEMPLATE_BYTES)

    def fill(self, export: ExportData, allocator: Any, problem: Problem, real: _Real, fields: dict[str, Any],
             settings: Settings) -> Filled:
        data = export.kernel
        assert isinstance(data, ScaledData)
        fields.update(MAP_P=real.array(data.P, "P"))
        return Filled(body=templates_closed_form.SCALED)
