"""Lazily loaded public names for the facade packages (:mod:`alloc`, :mod:`alloc.ams`).

PEP 562 (module ``__getattr__``/``__dir__``), the scientific Python "lazy loading"
convention (SPEC 1): a package lists its public names and the submodule defining each, and
a name's submodule is imported on the first access, so importing the package stays cheap.

Each package passes its own ``load`` function (``importlib.import_module`` of the name's
submodule, read from the package's own table): written in the package, the submodules it
can load stay visible as import arrows to ``tests/test_layering.py``, which a generic
import here would hide.
"""

from __future__ import annotations

import sys
import types
from collections.abc import Callable, Iterable, Mapping
from typing import Any

__all__ = ["attach", "keep_function"]


def attach(package: str, names: Mapping[str, str], public: Iterable[str],
           load: Callable[[str], types.ModuleType]) -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """The module ``__getattr__`` and ``__dir__`` of ``package``.

    ``names`` maps a public name to its submodule; ``load(name)`` imports that submodule.
    A loaded value is stored in the package's namespace, so later look-ups never reach
    ``__getattr__``; any other name raises ``AttributeError``.
    """
    namespace = vars(sys.modules[package])
    listed = frozenset(public)

    def __getattr__(name: str) -> Any:
        if name not in names:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(load(name), name)
        namespace[name] = value
        return value

    def __dir__() -> list[str]:
        return sorted(set(namespace) | listed)

    return __getattr__, __dir__


def keep_function(package: str, name: str, function: Callable[[], Any]) -> None:
    """Keep ``package.<name>`` the public function ``function()`` returns, although a
    submodule of ``package`` has the same name.

    Importing that submodule makes the import system bind it on its parent package, which
    would hide the function; the package's module object gets a class whose property
    ``name`` returns the function and ignores the binding (the submodule stays reachable as
    ``sys.modules[f"{package}.{name}"]``).
    """
    module = sys.modules[package]

    def ignore_binding(self: types.ModuleType, value: Any) -> None:
        pass

    cls = type("_Package", (types.ModuleType,), {
        "__doc__": f"The {package!r} module object: ``{package}.{name}`` stays the function.",
        name: property(lambda self: function(), ignore_binding),
    })
    module.__class__ = cls
