"""What a request may cost the service: the build-budget policy and a byte estimate.

Allocator builds run off the event loop (:class:`service.builds.Builder`): costly ones
(:func:`is_costly`) in a low-priority build process, the rest on two threads.  The wall-clock
budget is enforced **before** a build starts: :func:`build_seconds` reads the build time
each method declares for the problem and options (:meth:`alloc.registry.Method.build_cost`,
measured numbers with the methods: :mod:`alloc.methods.facet_search`), and a prediction above
``ALLOC_BUILD_BUDGET_S`` is refused with 422 naming the predicted cost.

The policy is the service's own: the default budget is 3.0 s of declared build time, more
than a facet enumeration at the library's facet limit (:data:`alloc.facet_cost.FACET_LIMIT`
subsets: 0.46 s at 6 x 21 under the measured model), so the service admits every build the
library's own ``backend="auto"`` would choose.  Per-call option caps are declared on the
methods' option specs (:attr:`alloc.options.Option.call_cap`) and checked by :mod:`service.builds`.

Memory: a facet-enumerating allocator holds about 4.5 KiB per subset (k = 6, m = 20:
60-71 MiB measured as RSS growth), so one build at the cap is ~90 MiB transient.  Cached
allocators are measured with :func:`estimate_bytes` and the cache is bounded in bytes.
"""

from __future__ import annotations

import sys
import types
from collections.abc import Mapping
from typing import Any

import numpy as np

import alloc
from alloc.registry import CHEAP_BUILD_SECONDS, get_method

__all__ = ["DEFAULT_BUILD_BUDGET_S", "build_seconds", "call_seconds", "batch_seconds",
           "answer_bytes", "estimate_bytes", "is_costly", "is_costly_batch", "CHEAP_BATCH_SECONDS"]

#: a batch predicted (build + rows x per-call cost) above this runs in the build process, not
#: on a service thread: a thread shares the GIL with the event loop for as long as it runs
CHEAP_BATCH_SECONDS = 0.02

#: the default build budget (s): the service's policy, kept at its value from before the facet
#: model was measured again (it was the old model's price of FACET_LIMIT subsets); it admits
#: every build the library's ``backend="auto"`` would choose (tests/alloc/test_build_cost.py)
DEFAULT_BUILD_BUDGET_S = 3.0


def build_seconds(problem: alloc.Problem, method: str, options: Mapping[str, Any]) -> float:
    """Predicted build time of ``make_allocator(problem, method, **options)``: the method's
    declared :meth:`~alloc.registry.Method.build_cost` (seconds, the project's machine)."""
    return float(get_method(method).build_cost(problem, **dict(options)))


def call_seconds(problem: alloc.Problem, method: str, options: Mapping[str, Any]) -> float:
    """Declared worst-case seconds of one call of the built allocator: the method's
    :meth:`~alloc.registry.Method.call_cost` (the project's machine, conservative)."""
    return float(get_method(method).call_cost(problem, **dict(options)))


def batch_seconds(problem: alloc.Problem, method: str, options: Mapping[str, Any], rows: int) -> float:
    """Predicted time of a batch of ``rows`` demands: the build plus ``rows`` declared calls."""
    return build_seconds(problem, method, options) + rows * call_seconds(problem, method, options)


#: bytes of one number in an answer, at most: shortest round-trip float (``-1.2345678901234567e-123``,
#: 24 characters) and its separator
_NUMBER_BYTES = 26
#: bytes of one row's status (``"unattainable",``) and the rows' brackets
_ROW_BYTES = 16 + 3 * 4


def answer_bytes(problem: alloc.Problem, rows: int) -> int:
    """Largest JSON answer of a batch of ``rows`` (``u``: m numbers a row; ``v_achieved`` and
    ``unallocated``: k each; a status), an upper bound computed before the batch runs."""
    return 1024 + rows * ((problem.m + 2 * problem.k) * _NUMBER_BYTES + _ROW_BYTES)


def is_costly_batch(seconds: float) -> bool:
    """A batch that goes to the build process (predicted above :data:`CHEAP_BATCH_SECONDS`)."""
    return seconds > CHEAP_BATCH_SECONDS


def is_costly(seconds: float) -> bool:
    """A build predicted above the library's cheap default (a facet enumeration, a direction
    table), which goes to the build process rather than a service thread."""
    return seconds > CHEAP_BUILD_SECONDS


_SHARED = (type, bool, int, float, str, bytes, types.FunctionType, types.BuiltinFunctionType, types.MethodType,
           types.ModuleType)


def estimate_bytes(obj: object, _limit: int = 100_000) -> int:
    """Bytes held by ``obj``: numpy buffers plus Python objects, walked once (bounded walk).

    Counts every array's ``nbytes`` (its base's once), containers and instance
    ``__dict__``/``__slots__``; objects of C extensions count ``sys.getsizeof`` only.
    """
    seen: set[int] = set()
    stack = [obj]
    total = 0
    steps = 0
    while stack and steps < _limit:
        steps += 1
        o = stack.pop()
        if id(o) in seen or o is None or isinstance(o, _SHARED) or (o is not obj and hasattr(o, "py_func")):
            # code, not data: functions, modules and numba dispatchers (the compiled kernels an
            # allocator holds are shared by every allocator; walking one counted its overloads)
            if isinstance(o, (str, bytes)) and id(o) not in seen:
                seen.add(id(o))
                total += sys.getsizeof(o)
            continue
        seen.add(id(o))
        if isinstance(o, np.ndarray):
            base = o
            while isinstance(base.base, np.ndarray):
                base = base.base
            if id(base) not in seen or base is o:
                seen.add(id(base))
                total += base.nbytes + 112
            continue
        total += sys.getsizeof(o, 64)
        if isinstance(o, dict):
            stack.extend(o.values())
        elif isinstance(o, (list, tuple, set, frozenset)):
            stack.extend(o)
        else:
            d = getattr(o, "__dict__", None)
            if isinstance(d, dict):
                stack.append(d)
            for slot in getattr(type(o), "__slots__", ()):
                stack.append(getattr(o, slot, None))
    return total
