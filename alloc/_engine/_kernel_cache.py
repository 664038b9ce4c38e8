"""Imported first by every module that decorates numba kernels (alloc's and sim's): it places the
kernel caches (:mod:`alloc._engine._jit_cache`) before any kernel is decorated, since numba's default
cache locators raise at decoration where the package directory and the home are not writable
(a root install used by another user).

Only a module with kernels imports it, so ``import alloc`` touches neither numba nor the
import system (it used to wrap numba's loader in ``sys.meta_path`` for the whole process).
A numba whose private cache API changed leaves its own cache locations in place, with a
warning: importing numba never breaks.
"""

from __future__ import annotations

import importlib
import warnings

try:
    importlib.import_module("alloc._engine._jit_cache")
except Exception as exc:  # noqa: BLE001 - numba's private cache API changed: never break a kernel module
    warnings.warn(f"alloc: the kernel cache locator is not installed ({type(exc).__name__}: {exc}); "
                  "numba's own cache locations apply", RuntimeWarning, stacklevel=2)
