"""Where numba keeps the distribution's compiled kernels, for any user, and the cache shipped with it.

numba's own choice (``cache=True``) is the package's ``__pycache__`` if this process can write
there, else ``~/.cache/numba``, else it raises ``RuntimeError: cannot cache function ...: no
locator available`` at import -- what a user met whose site-packages was installed by root and
who had no writable home.  :class:`KernelCacheLocator` takes that choice for the files of this
distribution (``alloc``, ``sim``, ``service``, ``benchmarks``) and never fails:

1. the package's ``__pycache__``, if writable (an editable clone; root on a system install);
2. else ``$XDG_CACHE_HOME/alloc-toolkit`` (``~/.cache/alloc-toolkit``);
3. else ``<tempdir>/alloc-toolkit-<uid>``, else ``/dev/shm/alloc-toolkit-<uid>`` (private:
   created 0700, used only if owned by this user and writable by nobody else -- the cache
   holds machine code that this process would load);
4. else the package's ``__pycache__`` read-only: kernels found there load, the others are
   compiled in memory for this process only (nothing is written, nothing raises).

The package's ``__pycache__`` is also the *shipped* cache: ``pip install`` builds the wheel
with every kernel compiled (setup.py's build step runs :func:`alloc._engine._jit_warm.warm` in the build tree), and
``make install`` warms the editable clone.  numba keys an entry by the source file's content
hash, the function's bytecode, the Python and numba versions and the CPU (name and features).
On a user's first use of a kernel from a fallback directory (2-3), the shipped entries for this
CPU are copied there, so that directory holds the kernels compiled for it as well.  On another
CPU, or with another numba version, the shipped entries do not apply: each kernel is compiled
on first use into the location above, with one line on stderr per method (one line, wrapped here)::

    alloc: compiling kernels for qp (not in the kernel cache for this CPU; first use on this machine,
    up to a minute; saved in /home/me/.cache/alloc-toolkit/alloc_4be1...) ...

``NUMBA_CACHE_DIR`` (numba's own setting) still wins: the kernels are then cached only there.
``python -m alloc._engine._jit_warm`` warms the cache (``warm``) or says where the kernels load from
(``where``).

This module imports numba, and importing it installs the locator: numba's per-function cache
(``FunctionCache``) gets :class:`KernelCacheImpl`, which tries :class:`KernelCacheLocator` before
numba's own locators and saves nothing where nothing is writable (a locator alone cannot stop a
save).  Every module with kernels imports it first, through :mod:`alloc._engine._kernel_cache`, before
any kernel is decorated; ``import alloc`` alone does not.
"""

from __future__ import annotations

import functools
import hashlib
import inspect
import os
import pickle
import re
import shutil
import stat
import sys
import tempfile
import threading
from pathlib import Path
from types import FrameType
from typing import Any

import numba
from numba.core import config, event
from numba.core.caching import CacheImpl, CompileResultCacheImpl, FunctionCache, _CacheLocator

__all__ = ["KernelCacheLocator", "install", "kernel_files", "where"]

#: the distribution's packages whose numba kernels this module places
PACKAGES = ("alloc", "sim", "service", "benchmarks")
#: the directory that holds those packages (site-packages, or the root of a clone)
_ROOT = Path(__file__).resolve().parents[2]  # the folder holding the packages (alloc/_engine/ is two below)
_APP = "alloc-toolkit"
_PYCACHE = "__pycache__"


def _ours(py_file: str) -> bool:
    """Whether ``py_file`` is a source file of one of this distribution's packages."""
    try:
        rel = Path(py_file).resolve().relative_to(_ROOT)
    except (ValueError, OSError):
        return False
    return len(rel.parts) > 1 and rel.parts[0] in PACKAGES


@functools.cache
def _content_hash(path: str, mtime: float, size: int) -> bytes:
    # the stamp numba 0.68's own locators use (a content hash; earlier versions used the mtime
    # and size, which an install changes): the same value, so caches made by either agree
    with open(path, "rb") as f:
        return hashlib.sha256(f.read()).digest()


_usable_lock = threading.Lock()
_usable_memo: dict[str, bool] = {}


def _writable_dir(path: str, private_root: str | None = None) -> bool:
    """Whether ``path`` exists (made if need be) and this process can write files in it.

    ``private_root``: a directory in a place other users can write (a temp dir): made 0700,
    and refused unless owned by this user and writable by nobody else.  Memoised: one probe
    per directory and process.
    """
    with _usable_lock:
        known = _usable_memo.get(path)
        if known is not None:
            return known
        try:
            if private_root is not None:
                os.makedirs(private_root, mode=0o700, exist_ok=True)
                st = os.lstat(private_root)
                if (not stat.S_ISDIR(st.st_mode) or st.st_uid != os.getuid()
                        or st.st_mode & (stat.S_IWGRP | stat.S_IWOTH)):
                    raise PermissionError(f"{private_root} is not private to this user")
            os.makedirs(path, exist_ok=True)
            tempfile.TemporaryFile(dir=path).close()
            ok = True
        except (OSError, ValueError):
            ok = False
        _usable_memo[path] = ok
        return ok


def _fallback_dirs(subpath: str) -> list[tuple[str, str | None]]:
    """(directory, private root or None) for a kernel file's cache, in order of preference."""
    out: list[tuple[str, str | None]] = []
    home_cache = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    if os.path.isabs(home_cache):
        root = os.path.join(home_cache, _APP)
        out.append((os.path.join(root, subpath), root))
    uid = os.getuid() if hasattr(os, "getuid") else 0
    try:
        bases = [tempfile.gettempdir()]
    except OSError:  # no usable temporary directory at all
        bases = []
    for base in [*bases, "/dev/shm"]:
        root = os.path.join(base, f"{_APP}-{uid}")
        out.append((os.path.join(root, subpath), root))
    return out


class KernelCacheLocator(_CacheLocator):
    """numba's cache locator for this distribution's kernels (see the module's docstring).

    ``writable`` is False only in the last resort (nothing writable anywhere): the entries
    in the shipped cache load, nothing is saved.
    """

    def __init__(self, py_func: Any, py_file: str, cache_path: str, writable: bool) -> None:
        self._py_file = py_file
        self._lineno = py_func.__code__.co_firstlineno
        self._cache_path = cache_path
        self.writable = writable
        #: the cache that ``pip install`` ships, beside the source file
        self.shipped_path = os.path.join(os.path.dirname(py_file), _PYCACHE)

    def ensure_cache_path(self) -> None:
        if self.writable:
            super().ensure_cache_path()

    def get_cache_path(self) -> str:
        return self._cache_path

    def get_source_stamp(self) -> bytes:
        st = os.stat(self._py_file)
        return _content_hash(self._py_file, st.st_mtime, st.st_size)

    def get_disambiguator(self) -> str:
        return str(self._lineno)

    @classmethod
    def from_function(cls, py_func: Any, py_file: str) -> KernelCacheLocator | None:
        if config.CACHE_DIR or not _ours(py_file):
            return None  # NUMBA_CACHE_DIR, or not our file: numba's own locators decide
        in_tree = os.path.join(os.path.dirname(py_file), _PYCACHE)
        if _writable_dir(in_tree):
            return cls(py_func, py_file, in_tree, True)
        subpath = cls.get_suitable_cache_subpath(py_file)
        for path, private_root in _fallback_dirs(subpath):
            if _writable_dir(path, private_root):
                return cls(py_func, py_file, path, True)
        return cls(py_func, py_file, in_tree, False)

    def seed_from_shipped(self, filename_base: str) -> None:
        """Copy the shipped entries of one kernel into this (fallback) cache directory.

        Only when this directory has no fresh index for the kernel and the shipped one is
        fresh and holds entries for this CPU; each file written whole (a temporary name, then
        renamed), so a concurrent reader sees the old file or the new one.
        """
        if not self.writable or self._cache_path == self.shipped_path:
            return
        index = filename_base + ".nbi"
        target = os.path.join(self._cache_path, index)
        stamp = self.get_source_stamp()
        if _read_index(target, stamp) is not None:
            return
        overloads = _read_index(os.path.join(self.shipped_path, index), stamp)
        if not overloads:
            return
        magic = _host_magic()
        names = {name for key, name in overloads.items() if key[1] == magic}
        if not names:
            return  # compiled for another CPU: nothing here to reuse
        try:
            for name in sorted(names) + [index]:
                _copy_whole(os.path.join(self.shipped_path, name), os.path.join(self._cache_path, name))
        except OSError:
            pass  # a partial copy is harmless: a missing data file is a miss, then a compile


def _read_index(path: str, stamp: bytes) -> dict[Any, str] | None:
    """A numba cache index's entries ({key: data file name}), or None if absent or stale."""
    try:
        with open(path, "rb") as f:
            version = pickle.load(f)
            if version != numba.__version__:
                return None
            saved_stamp, overloads = pickle.loads(f.read())
    except (OSError, EOFError, pickle.UnpicklingError, ValueError, TypeError, AttributeError):
        return None
    return overloads if saved_stamp == stamp else None


def _copy_whole(src: str, dst: str) -> None:
    tmp = f"{dst}.tmp.{os.getpid()}.{threading.get_ident()}"
    try:
        shutil.copyfile(src, tmp)
        os.replace(tmp, dst)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


@functools.lru_cache(maxsize=1)
def _host_magic() -> tuple[Any, ...]:
    """What numba's cache keys say about this machine: target triple, CPU name, features."""
    from numba.core.registry import cpu_target

    return tuple(cpu_target.target_context.codegen().magic_tuple())


class KernelCacheImpl(CompileResultCacheImpl):
    """numba's cache of compile results, placed by :class:`KernelCacheLocator` for our files.

    For every other function numba's own locators decide, as before.
    """

    _locator_classes = [KernelCacheLocator, *CacheImpl._locator_classes]

    def __init__(self, py_func: Any) -> None:
        super().__init__(py_func)
        if isinstance(self._locator, KernelCacheLocator):
            self._locator.seed_from_shipped(self.filename_base)

    def check_cachable(self, cres: Any) -> bool:
        if isinstance(self._locator, KernelCacheLocator) and not self._locator.writable:
            return False  # nowhere to write: the kernel lives in memory for this process
        return super().check_cachable(cres)


class CompileNotice(event.Listener):
    """One line on stderr when one of our kernels is compiled rather than loaded: per method
    (or once, outside a method), at the start of the outermost compile."""

    def __init__(self, stream: Any = None) -> None:
        self._stream = stream
        self._depth = 0
        self._told: set[str] = set()
        self.compiles = 0  #: outermost compiles of our kernels in this process
        self.silent = False  #: counts without a line (``warm`` is the one asked to compile)

    def on_start(self, ev: event.Event) -> None:
        # numba holds its global compiler lock across a compile: the nesting is one thread's
        self._depth += 1
        if self._depth > 1:
            return
        dispatcher = ev.data.get("dispatcher") if isinstance(ev.data, dict) else None
        py_func = getattr(dispatcher, "py_func", None)
        try:
            source = inspect.getfile(py_func) if py_func is not None else ""
        except TypeError:
            return
        if not _ours(source):
            return
        self.compiles += 1
        if self.silent:
            return
        method = _calling_method()
        if method in self._told:
            return
        self._told.add(method)
        cache = getattr(getattr(dispatcher, "_cache", None), "cache_path", None)
        where = f"; saved in {cache}" if cache else "; kept in memory for this process"
        locator = getattr(getattr(getattr(dispatcher, "_cache", None), "_impl", None), "locator", None)
        if isinstance(locator, KernelCacheLocator) and not locator.writable:
            where = "; no writable cache directory: kept in memory for this process"
        what = f"kernels for {method}" if method else "kernels"
        print(f"alloc: compiling {what} (not in the kernel cache for this CPU; first use on this machine, "
              f"up to a minute{where}) ...", file=self._stream or sys.__stderr__ or sys.stderr, flush=True)

    def on_end(self, ev: event.Event) -> None:
        self._depth -= 1


def _calling_method() -> str:
    """The registered method whose allocator is being built or called, if any (for the notice)."""
    api = os.path.join(str(_ROOT), "alloc", "api.py")
    frame: FrameType | None = sys._getframe(2)
    while frame is not None:
        if frame.f_code.co_filename == api:
            local = frame.f_locals
            name = local.get("method")
            if not isinstance(name, str):
                name = getattr(local.get("self"), "method", None)
            if isinstance(name, str):
                return name
        frame = frame.f_back
    return ""


_installed = False
notice = CompileNotice()


def install() -> None:
    """Place our kernels' caches with :class:`KernelCacheLocator` and report compiles.

    Idempotent.  Must run before a kernel is decorated (:mod:`alloc._engine._kernel_cache` sees to it).
    """
    global _installed
    if _installed:
        return
    FunctionCache._impl_class = KernelCacheImpl
    event.register("numba:compile", notice)
    _installed = True


if __name__ != "__main__":
    # importing this module is what installs it (alloc._engine._kernel_cache does, first thing in every
    # module with kernels)
    install()


def kernel_files() -> list[Path]:
    """Source files of our packages that hold numba kernels (they import numba's ``njit``)."""
    out = []
    for package in PACKAGES:
        for path in sorted((_ROOT / package).rglob("*.py")):
            try:
                text = path.read_text(encoding="utf-8")
            except OSError:
                continue
            if re.search(r"^@njit", text, re.MULTILINE):
                out.append(path)
    return out


def where() -> list[tuple[str, str, bool]]:
    """For each kernel file: (file, the cache directory its kernels use, writable)."""

    def probe() -> None:
        """probe"""

    out = []
    for path in kernel_files():
        locator = KernelCacheLocator.from_function(probe, str(path))
        if locator is None:
            out.append((str(path), f"NUMBA_CACHE_DIR={config.CACHE_DIR}", True))
        else:
            out.append((str(path), locator.get_cache_path(), locator.writable))
    return out
