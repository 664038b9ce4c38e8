"""Input checks shared by the estimators, the detector and the excitation wrapper.

Settings raise :class:`~alloc.exceptions.OptionError` (a TypeError, as every option of the
library does); samples raise :class:`SampleError` (a ValueError); stored states that do not
fit raise :class:`StateError` (a ValueError).  Every message starts with the field.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from ..exceptions import AllocError, OptionError
from ..problem import MAX_MAGNITUDE, as_float_array, as_real, check_magnitude, short_repr

__all__ = ["SampleError", "StateError", "sample_vector", "setting_real", "setting_int", "setting_vector",
           "state_array", "state_mapping", "state_count", "samples_in", "MAX_COUNT"]

#: Largest stored counter (samples, alarms): integers a float holds exactly, so ``samples *
#: sample_time`` and every ratio of counts stay exact and finite.
MAX_COUNT = 2 ** 53


class SampleError(AllocError, ValueError):
    """A sample (command, measured response, position, time) is malformed or not finite."""


class StateError(AllocError, ValueError):
    """A stored estimator or detector state does not fit (missing key, wrong shape or kind)."""


def sample_vector(name: str, value: Any, n: int) -> np.ndarray:
    """``value`` as a finite float vector of length ``n`` (a new array), or SampleError naming ``name``."""
    if type(value) is np.ndarray and value.dtype == np.float64 and value.shape == (n,):
        if np.abs(value).max(initial=0.0) <= MAX_MAGNITUDE:  # the common case: one pass, no walk
            return value.copy()
    arr = as_float_array(name, value, SampleError)
    if arr.shape != (n,):
        raise SampleError(f"{name}: expected shape ({n},), got {arr.shape}")
    check_magnitude(name, arr, SampleError)
    return arr


def setting_real(name: str, value: Any, lo: float, hi: float, *, lo_open: bool = False,
                 hi_open: bool = False) -> float:
    """A real setting within ``[lo, hi]`` (ends open as asked), or OptionError naming it."""
    x = as_real(name, value, OptionError)
    below = x <= lo if lo_open else x < lo
    above = x >= hi if hi_open else x > hi
    if below or above:
        raise OptionError(f"{name}: {x:g} outside {'(' if lo_open else '['}{lo:g}, {hi:g}{')' if hi_open else ']'}")
    return x


def setting_int(name: str, value: Any, lo: int, hi: int) -> int:
    """An integer setting within ``[lo, hi]``, or OptionError naming it."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        raise OptionError(f"{name}: expected an integer, got {type(value).__name__}")
    if not lo <= int(value) <= hi:
        raise OptionError(f"{name}: {short_repr(int(value))} outside [{lo}, {hi}]")
    return int(value)


def samples_in(name: str, seconds: float, sample_time: float, cap: int) -> int:
    """``round(seconds / sample_time)``, or OptionError naming ``name`` when above ``cap``.

    The ratio is compared as a float before any integer is made: a subnormal sample time
    gives ``inf``, which ``int`` cannot convert, and a huge count would be allocated later.
    """
    ratio = seconds / sample_time
    if not ratio <= cap:  # also inf
        raise OptionError(f"{name}: {seconds:g} s at {sample_time:g} s per sample is {ratio:.3g} samples; "
                          f"at most {cap}")
    return int(round(ratio))


def setting_vector(name: str, value: Any, n: int, *, positive: bool = False) -> np.ndarray:
    """A scalar (broadcast) or a length-``n`` vector of finite reals, or OptionError naming it."""
    arr = as_float_array(name, value, OptionError)
    if arr.ndim == 0:
        arr = np.full(n, float(arr))
    if arr.shape != (n,):
        raise OptionError(f"{name}: expected a number or shape ({n},), got {arr.shape}")
    check_magnitude(name, arr, OptionError)
    if positive and not (arr > 0).all():
        i = int(np.argmax(~(arr > 0)))
        raise OptionError(f"{name}: {name}[{i}] = {arr[i]:g} must be > 0")
    return arr


def state_mapping(data: Any, kind: str, keys: tuple[str, ...]) -> Mapping[str, Any]:
    """``data`` if it is a mapping of kind ``kind`` holding ``keys``; StateError otherwise."""
    if not isinstance(data, Mapping):
        raise StateError(f"state: expected a mapping, got {type(data).__name__}")
    if data.get("kind") != kind:
        raise StateError(f"kind: expected {kind!r}, got {data.get('kind')!r}")
    missing = [k for k in keys if k not in data]
    if missing:
        raise StateError(f"{missing[0]}: missing from the stored {kind} state")
    return data


def state_count(name: str, value: Any, hi: int = MAX_COUNT) -> int:
    """A stored non-negative integer up to ``hi`` (not a bool), or StateError naming it."""
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= hi:
        raise StateError(f"{name}: expected an integer in [0, {hi}], got {short_repr(value)}")
    return value


def state_array(name: str, value: Any, shape: tuple[int, ...], *, allow_nan: bool = False) -> np.ndarray:
    """A stored array of exactly ``shape`` (finite unless ``allow_nan``), or StateError naming it."""
    arr = as_float_array(name, value, StateError)
    if arr.shape != shape:
        raise StateError(f"{name}: expected shape {shape}, got {arr.shape}")
    if not allow_nan:
        check_magnitude(name, arr, StateError)
    return arr
