"""Estimation, detection and identifiable allocation (seed section 1.3.1-1.3.2).

Without an oracle an allocator must learn what failed from what it measures.  This package
holds the library's part, streaming (one sample per call), with bounded memory and a state
that round-trips through a JSON-ready dict (``to_dict`` / ``from_dict``):

:class:`RecursiveLeastSquares`, :class:`EffectivenessRLS`
    the effectiveness matrix by least squares with exponential forgetting and the Eq 1.4
    parameter-change penalty, with its exact error covariance (:mod:`.rls`).
:class:`FrequencyDomainEstimator`
    the seed's frequency-domain estimator (Eqs 1.5-1.12) over a stated band, with a windowed
    restart so it follows a change (:mod:`.frequency`).
:class:`FailureDetector`
    per-effector hypothesis tests on residuals with thresholds from a design false-alarm
    rate, isolating each failure kind of :mod:`alloc.health` into a
    :class:`~alloc.health.FailureEvent` with its evidence (:mod:`.detection`).
:class:`NullSpaceExcitation`, :class:`RandomWeightAllocator`
    identifiable allocation for every registry allocator: excitation in the null space of
    ``B`` (``B u`` unchanged), and the seed's random weights (:mod:`.excitation`).

Bad settings raise :class:`~alloc.exceptions.OptionError` (a TypeError), bad samples
:class:`SampleError` and unusable stored states :class:`StateError` (ValueErrors), all
:class:`~alloc.exceptions.AllocError` naming the field.
"""

from __future__ import annotations

import importlib
import types
from typing import TYPE_CHECKING

from .. import _lazy
from ._checks import SampleError, StateError

if TYPE_CHECKING:
    from .detection import Detection, FailureDetector, Withdrawal
    from .excitation import NullSpaceExcitation, RandomWeightAllocator, regressor_condition
    from .frequency import FrequencyDomainEstimator, FrequencyEstimate
    from .rls import EffectivenessRLS, RecursiveLeastSquares
    from .robust import RobustSettings

__all__ = [
    "RecursiveLeastSquares", "EffectivenessRLS", "FrequencyDomainEstimator", "FrequencyEstimate",
    "FailureDetector", "Detection", "Withdrawal", "NullSpaceExcitation", "RandomWeightAllocator", "regressor_condition",
    "RobustSettings", "SampleError", "StateError",
]

# Loaded on first access (alloc/_lazy.py): the excitation module needs the allocators and
# their compiled kernels (numba, 0.2-0.3 s of CPU), which a caller that only detects, such
# as the service at start, should not pay for.
_LAZY = {
    "Detection": "detection", "FailureDetector": "detection", "Withdrawal": "detection",
    "NullSpaceExcitation": "excitation", "RandomWeightAllocator": "excitation", "regressor_condition": "excitation",
    "FrequencyDomainEstimator": "frequency", "FrequencyEstimate": "frequency",
    "EffectivenessRLS": "rls", "RecursiveLeastSquares": "rls", "RobustSettings": "robust",
}


def _submodule(name: str) -> types.ModuleType:
    module = _LAZY[name]
    return importlib.import_module(f".{module}", __name__)


__getattr__, __dir__ = _lazy.attach(__name__, _LAZY, __all__, _submodule)
