"""Control allocation for over-actuated aircraft.

Given an effectiveness matrix ``B`` (k virtual controls x m effectors), a demand ``v``,
position and rate limits, preferences and weights, find effector commands ``u`` with
``B u = v`` (seed section 1.3.4, Eqs 1.14-1.28).  Every method sits behind one registry:

>>> import alloc
>>> p = alloc.Problem([[1.0, 1.0, 0.5]], umin=[-1, -1, -1], umax=[1, 1, 1])
>>> r = alloc.allocate(p, [1.0], method="pinv")
>>> r.status.value, r.u.round(3).tolist()
('exact', [0.444, 0.444, 0.222])

The public names below are loaded on first use (the scientific Python "lazy loading"
convention, SPEC 1): ``import alloc`` is cheap, so the ``alloc`` command's ``--help`` and
the packages built on the library (simulator, service) do not pay for the compiled
kernels until they allocate.  The method modules load on the first registry look-up.
"""

from __future__ import annotations

import importlib
import types
from typing import TYPE_CHECKING, Any

from . import _lazy
from .exceptions import (
    AllocError,
    DemandError,
    OptionError,
    ProblemError,
    SolverError,
    UnknownMethodError,
)

if TYPE_CHECKING:  # the lazily loaded names, for type checkers and IDEs
    from .api import Allocator, allocate, allocate_batch, make_allocator
    from .health import EffectorHealth, FailureEvent, FailureKind
    from .problem import Problem
    from .registry import method_info, methods, register
    from .result import EXACT_RTOL, BatchResult, Result, Status

#: public name -> the submodule defining it (loaded on first attribute access)
_LAZY: dict[str, str] = {
    "Allocator": "api", "allocate": "api", "allocate_batch": "api", "make_allocator": "api",
    "EffectorHealth": "health", "FailureEvent": "health", "FailureKind": "health",
    "Problem": "problem",
    "method_info": "registry", "register": "registry",
    "EXACT_RTOL": "result", "BatchResult": "result", "Result": "result", "Status": "result",
    "load_vehicle": "vehicle_file", "Vehicle": "vehicle_file",
}

__all__ = [
    "Problem", "EffectorHealth", "FailureEvent", "FailureKind", "Result", "BatchResult", "Status", "EXACT_RTOL",
    "allocate", "allocate_batch", "make_allocator", "Allocator",
    "methods", "method_info", "register",
    "AllocError", "ProblemError", "DemandError", "OptionError", "UnknownMethodError", "SolverError",
]
#: the name this project is published under (``pip install alloc-toolkit``); ``alloc`` on the
#: public index is an unrelated project.  The import name and the command stay ``alloc``.
DISTRIBUTION = "alloc-toolkit"
#: the one definition of the version (pyproject.toml reads it: ``[tool.setuptools.dynamic]``)
__version__ = "0.1.0"


def _submodule(name: str) -> types.ModuleType:
    module = _LAZY[name]
    return importlib.import_module(f".{module}", __name__)


def _registry_methods() -> Any:
    from .registry import methods

    return methods


__getattr__, __dir__ = _lazy.attach(__name__, _LAZY, __all__, _submodule)
# the sub-package ``alloc.methods`` has the name of the registry's function ``alloc.methods()``
_lazy.keep_function(__name__, "methods", _registry_methods)
