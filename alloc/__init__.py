"""Control allocation for over-actuated aircraft.

Given an effectiveness matrix ``B`` (k virtual controls x m effectors), a demand ``v``,
position and rate limits, preferences and weights, find effector commands ``u`` with
``B u = v`` (seed section 1.3.4, Eqs 1.14-1.28).  Every method sits behind one registry:

>>> import alloc
>>> p = alloc.Problem([[1.0, 1.0, 0.5]], umin=[-1, -1, -1], umax=[1, 1, 1])
>>> r = alloc.allocate(p, [1.0], method="pinv")
>>> r.status.value, r.u.round(3).tolist()
('exact', [0.444, 0.444, 0.222])
"""

from .api import Allocator, allocate, allocate_batch, make_allocator
from .exceptions import (
    AllocError,
    DemandError,
    OptionError,
    ProblemError,
    SolverError,
    UnknownMethodError,
)
from .health import EffectorHealth, FailureEvent, FailureKind
from .problem import Problem
from .registry import method_info, methods, register
from .result import EXACT_RTOL, BatchResult, Result, Status

__all__ = [
    "Problem", "EffectorHealth", "FailureEvent", "FailureKind", "Result", "BatchResult", "Status", "EXACT_RTOL",
    "allocate", "allocate_batch", "make_allocator", "Allocator",
    "methods", "method_info", "register",
    "AllocError", "ProblemError", "DemandError", "OptionError", "UnknownMethodError", "SolverError",
]
__version__ = "0.1.0"
