"""The look-up of allocation methods: one registry, all methods with the same signature.

A method is a class deriving from :class:`Method`, registered with ``@register("name")``
(both defined in :mod:`alloc.method` and re-exported here).  The look-ups below load the
built-in methods (the package :mod:`alloc.methods`, one module per family) before they
answer, so this module sits above the methods and the methods import :mod:`alloc.method`,
never this one.
"""

from __future__ import annotations

from typing import Any

from . import method as _method
from .exceptions import UnknownMethodError
from .export_data import KINDS
from .method import (
    BUILD_LIMIT_BYTES,
    BUILD_LIMIT_SECONDS,
    CALL_LIMIT_SECONDS,
    CAPABILITIES,
    CHEAP_BUILD_SECONDS,
    FloatArray,
    Method,
    register,
)
from .options import validate
from .problem import Problem

__all__ = ["Method", "register", "get_method", "methods", "families", "exportable", "method_info", "build",
           "DEFAULT_METHOD", "FloatArray", "CHEAP_BUILD_SECONDS", "BUILD_LIMIT_SECONDS", "BUILD_LIMIT_BYTES",
           "CALL_LIMIT_SECONDS", "CAPABILITIES"]

#: the method used wherever none is named (library, command line, HTTP): ``qp`` meets every
#: attainable demand exactly (seed Eqs 1.20-1.21), which the pseudo-inverse family (Eq 1.23) does not
DEFAULT_METHOD = "qp"


def _load_builtin() -> None:
    # Importing the package registers the built-in methods (one module per family).  By
    # full name: ``from . import methods`` would find the function ``alloc.methods``.
    import alloc.methods  # noqa: F401


def get_method(name: str) -> type[Method]:
    """The method class registered as ``name``; unknown names list the registered ones."""
    _load_builtin()
    registered = _method._REGISTRY
    if not isinstance(name, str) or name not in registered:
        raise UnknownMethodError(f"method: unknown method {name!r}; registered: {', '.join(sorted(registered))}")
    return registered[name]


def methods() -> list[str]:
    """Names of the registered allocation methods."""
    _load_builtin()
    return sorted(_method._REGISTRY)


def families() -> dict[str, list[str]]:
    """Each declared family (:attr:`Method.family`: methods computing one allocation by
    different algorithms) and its registered members, sorted; a method alone is its own."""
    out: dict[str, list[str]] = {}
    for name in methods():
        out.setdefault(get_method(name).family, []).append(name)
    return out


def exportable() -> list[str]:
    """The methods that declare a C kernel (:attr:`Method.export`; ``alloc export`` writes
    them): kind by kind in the order of :data:`alloc.export_data.KINDS` (closed forms first),
    each kind's methods in the order they were registered."""
    _load_builtin()
    registered = _method._REGISTRY
    return [name for kind in KINDS for name, cls in registered.items() if cls.export == kind]


def method_info(name: str) -> dict[str, Any]:
    """Name, seed equation, summary, options and capabilities of a method (CLI and service).

    ``options`` maps each option to one descriptive line; ``option_specs`` gives the typed
    specification (type, default, constraint, doc); ``family`` the allocation it computes and
    ``export`` the kind of C kernel ``alloc export`` writes for it (``None``: not exported).
    """
    cls = get_method(name)
    return {"name": name, "equation": cls.equation, "summary": cls.summary,
            "options": {opt: spec.describe() for opt, spec in cls.options.items()},
            "option_specs": {opt: spec.to_dict() for opt, spec in cls.options.items()},
            "capabilities": {cap: bool(getattr(cls, cap)) for cap in CAPABILITIES},
            "family": cls.family, "export": cls.export}


def build(problem: Problem, name: str, options: dict[str, Any]) -> Method:
    """Construct method ``name`` for ``problem`` with validated options.

    Unknown options and inadmissible values raise :class:`~alloc.exceptions.OptionError`
    (a ``TypeError``) naming the option (:func:`alloc.options.validate`).
    """
    cls = get_method(name)
    values = validate(name, cls.options, options)
    if not isinstance(problem, Problem):
        raise TypeError(f"problem: expected alloc.Problem, got {type(problem).__name__}")
    return cls(problem, **values)
