"""The closed-loop simulator's old single module, kept as the names it exported.

The loop is split by concern: :mod:`sim.model` (vehicle, failure, designs, pilot),
:mod:`sim.settings` (:class:`LoopSpec` and the rules its settings name), :mod:`sim.packed`
(packed state and compiled step), :mod:`sim.engine` (:func:`simulate`) and
:mod:`sim.injection` (failure injection).  Import from those; this module re-exports them.
"""

from __future__ import annotations

# the private names are what tests/sim/test_blocks.py and older callers import from here
from sim.engine import _controller_system, simulate  # noqa: F401
from sim.injection import inject_failure as _inject  # noqa: F401
from sim.model import TF, Failure, LoopShapedDesign, Pilot, SMCDesign, PlantModel
from sim.packed import FloatSlot, IntSlot, Misc, _matvec  # noqa: F401
from sim.settings import (
    ANTI_WINDUP_RULES,
    BOUNDARY_LAYER_RULES,
    SEED_FRAME_PERIOD,
    U_PREV_SOURCES,
    LoopSpec,
    anti_windup_on,
    boundary_layer_at,
)

__all__ = ["PlantModel", "Failure", "SMCDesign", "LoopShapedDesign", "Pilot", "LoopSpec", "simulate",
           "boundary_layer_at", "BOUNDARY_LAYER_RULES", "anti_windup_on", "ANTI_WINDUP_RULES",
           "FloatSlot", "IntSlot", "Misc", "TF", "U_PREV_SOURCES", "SEED_FRAME_PERIOD"]
