"""What a request may cost the service: a measured build-cost model and a byte estimate.

Allocator builds run off the event loop in a small pool of build threads
(:class:`service.store.Builder`).  A Python thread cannot be killed, so the wall-clock
budget is enforced **before** a build starts: :func:`build_seconds` predicts the build
time from a cost model fitted to measured builds, and a prediction above
``ALLOC_BUILD_BUDGET_S`` (default 3 s) is refused with 422 naming the predicted cost.

Measured on this machine (2 shared cores, 2026-11-30, ``/tmp`` script in the report of
issue 12; alloc at this commit), seconds per build:

=====================  ======================  =========  =================================
method                 problem                 build      per facet subset C(m_free, k-1)
=====================  ======================  =========  =================================
da_facet               k=6, m=20 (15,504)      0.72 s     46 us
da_bisect              k=6, m=20 (15,504)      1.13 s     73 us
da_bisect              k=3, m=64 (2,016)       0.29 s     142 us
da_table res 64        k=6, m=20 (15,504)      0.95 s     62 us (no table above k = 3)
da_table res 64        k=3, m=20 (190)         1.72 s     table term dominates
da_table res 64        k=3, m=64 (2,016)       7.34 s     table term dominates
da_table res 128/32    k=3, m=20               3.46/0.45 s
=====================  ======================  =========  =================================

Model (conservative: it over-predicts every measurement above, by up to 2x):

* facet enumeration (methods declaring ``needs_ams``): ``150 us x facet_subsets``, the
  subsets counted by the method itself (``Method.facet_subsets``).  At the library's
  :data:`alloc.methods.direct.FACET_LIMIT` (20,000) that is 3.0 s, which is why the default
  budget is 3 s: the service accepts every build the library's own limit admits, no more.
* the k = 3 spherical table of ``da_table``: ``resolution^2 x (270 + 0.75 x subsets) us``
  (two ray casts per cell against every tile): res 64 on m = 64 predicts 7.3 s (refused),
  res 64 on ICE (m = 11, 55 subsets) 1.3 s.
* every other method builds in milliseconds within the size caps (an SVD or a QP set-up of
  at most 6 x 64): cost 0.

Memory: a facet-enumerating allocator holds about 4.5 KiB per subset (k = 6, m = 20:
60-71 MiB measured as RSS growth), so one build at the cap is ~90 MiB transient.  Cached
allocators are measured with :func:`estimate_bytes` and the cache is bounded in bytes.
"""

from __future__ import annotations

import sys
from collections.abc import Mapping
from typing import Any

import numpy as np

import alloc
from alloc.methods.direct import FACET_LIMIT
from alloc.registry import get_method

__all__ = ["FACET_SECONDS", "DEFAULT_BUILD_BUDGET_S", "build_seconds", "estimate_bytes"]

#: seconds per facet generator subset enumerated by a ``needs_ams`` build (measured <= 142 us)
FACET_SECONDS = 150e-6
#: the default build budget: the predicted time of a facet enumeration at the library's own
#: limit (:data:`alloc.methods.direct.FACET_LIMIT`, 20,000 subsets -> 3.0 s), so the service
#: admits every build the library's ``backend="auto"`` would choose, and nothing larger
DEFAULT_BUILD_BUDGET_S = round(FACET_SECONDS * FACET_LIMIT, 6)
#: the k = 3 look-up table of ``da_table``: seconds per cell, and per cell and subset
_TABLE_CELL_SECONDS, _TABLE_CELL_SUBSET_SECONDS = 270e-6, 0.75e-6
#: methods whose build adds a (resolution x resolution) table at k = 3, and its option
_TABLE_METHODS = {"da_table": ("resolution", 64)}


def build_seconds(problem: alloc.Problem, method: str, options: Mapping[str, Any]) -> float:
    """Predicted build time of ``make_allocator(problem, method, **options)`` (seconds, this machine)."""
    cls = get_method(method)
    subsets = cls.facet_subsets(problem, dict(options)) if cls.needs_ams else 0
    seconds = FACET_SECONDS * subsets
    table = _TABLE_METHODS.get(method)
    if table is not None and problem.k == 3:
        res = options.get(table[0], table[1])
        if isinstance(res, int) and not isinstance(res, bool) and res > 0:
            seconds += float(res) ** 2 * (_TABLE_CELL_SECONDS + _TABLE_CELL_SUBSET_SECONDS * subsets)
    return seconds


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
        if id(o) in seen or o is None or isinstance(o, (type, bool, int, float, str, bytes)):
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
