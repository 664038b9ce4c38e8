"""No code outside a method reads the private attributes of a method or an allocator.

What a consumer (the C export, the service, the simulator, the benchmarks) needs of a built
method is declared and public: its capabilities (``alloc.method.Method``), its option specs,
its kernel for the C generator (``Method.export_data``, ``Allocator.export_data``).  This test
reads the source with :mod:`ast`: it lists the private attribute names of the method classes
(``alloc/methods/``: every ``self._x`` and private method), of the solver a method holds
(``alloc/_simplex.py``) and of the allocator (``alloc/api.py``), then fails on any
``obj._x`` with one of those names, or ``getattr(obj, "_x")``, elsewhere in ``alloc``, ``sim``,
``service`` and ``benchmarks`` -- ``self._x`` and ``cls._x`` excepted (an object's own state).

A name is only a name: an unrelated object with a private attribute of the same name is
listed in :data:`ALLOWED` with what it is, and each entry must still occur (no stale entries).
"""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: where the private names are defined (and may be used)
OWNERS = sorted((ROOT / "alloc" / "methods").glob("*.py")) + [ROOT / "alloc" / "_simplex.py", ROOT / "alloc" / "api.py"]
SCANNED = ("alloc", "sim", "service", "benchmarks")

#: (file, expression) -> why it is not a method's or an allocator's private state
ALLOWED = {
    ("alloc/_jit_cache.py", "getattr(dispatcher, '_cache', None)"): "numba's dispatcher, not an allocator",
    ("alloc/_jit_cache.py", "getattr(getattr(dispatcher, '_cache', None), '_impl', None)"): "numba's cache",
    ("alloc/_jit_warm.py", "allocator._solve"): "the kernel-cache warm-up runs the allocator's Python call "
                                                  "path, which a fast path skips (the allocator's own package)",
    ("alloc/estimation/detection.py", "det._U"): "the detector's own buffers, restored from its saved state",
    ("alloc/estimation/detection.py", "det._R"): "the detector's own buffers",
    ("alloc/estimation/detection.py", "det._Q"): "the detector's own buffers",
    ("alloc/export/tables.py", "aset._A"): "an index of alloc._active_set's packed layout (a module constant)",
    ("benchmarks/bench_ams.py", "impl._solve_reference"): "times a method's numpy reference against its "
                                                         "compiled solve, as the method's own tests compare them",
    ("benchmarks/bench_lock.py", "f._W"): "measures the allocator's lock by wiring its call path both ways",
    ("benchmarks/bench_lock.py", "f._packed"): "measures the allocator's lock by wiring its call path both ways",
    ("benchmarks/bench_lock.py", "f._packed_rate"): "measures the allocator's lock by wiring its call path both ways",
    ("benchmarks/bench_lock.py", "f._zm"): "measures the allocator's lock by wiring its call path both ways",
    ("benchmarks/bench_lock.py", "f._fast_setup"): "measures the allocator's lock by wiring its call path both ways",
}


def _is_private(name: str) -> bool:
    return name.startswith("_") and not name.startswith("__")


def private_names() -> set[str]:
    """Private attribute names of the method classes, the simplex and the allocator."""
    names: set[str] = set()
    for path in OWNERS:
        tree = ast.parse(path.read_text())
        for node in ast.walk(tree):
            if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.value.id == "self" \
                    and _is_private(node.attr):
                names.add(node.attr)
            if isinstance(node, ast.ClassDef):
                for item in node.body:
                    if isinstance(item, (ast.FunctionDef, ast.AsyncFunctionDef)) and _is_private(item.name):
                        names.add(item.name)
                    slots = [t for t in getattr(item, "targets", []) if getattr(t, "id", "") == "__slots__"]
                    if slots and isinstance(item.value, ast.Tuple):
                        names.update(e.value for e in item.value.elts
                                     if isinstance(e, ast.Constant) and _is_private(e.value))
    return names


def private_reads(root: Path = ROOT, packages: tuple[str, ...] = SCANNED) -> dict[tuple[str, str], int]:
    """(file, expression) -> first line, for every read of a listed name outside its owners."""
    names = private_names()
    owners = {p.resolve() for p in OWNERS}
    found: dict[tuple[str, str], int] = {}
    for package in packages:
        for path in sorted((root / package).rglob("*.py")):
            if path.resolve() in owners:
                continue
            rel = path.relative_to(root).as_posix()
            for node in ast.walk(ast.parse(path.read_text())):
                if isinstance(node, ast.Attribute) and node.attr in names and not (
                        isinstance(node.value, ast.Name) and node.value.id in ("self", "cls")) or isinstance(node, ast.Call) and getattr(node.func, "id", None) in ("getattr", "hasattr") \
                        and len(node.args) >= 2 and isinstance(node.args[1], ast.Constant) \
                        and node.args[1].value in names:
                    found.setdefault((rel, ast.unparse(node)), node.lineno)
    return found


def test_the_names_are_read_from_the_methods():
    names = private_names()
    # the attributes the C export once read, and the allocator's safe answer
    assert {"_P", "_static", "_dynamic", "_impl", "_lex", "_pinv", "_safe", "_F", "_state"} <= names


def test_no_private_attribute_of_a_method_or_allocator_is_read_outside():
    reads = private_reads()
    unexpected = {f"{path}:{line}: {expr}" for (path, expr), line in reads.items() if (path, expr) not in ALLOWED}
    assert not unexpected, "private state read outside its method or allocator:\n" + "\n".join(sorted(unexpected))
    stale = sorted(f"{path}: {expr}" for path, expr in ALLOWED if (path, expr) not in reads)
    assert not stale, "ALLOWED entries that no longer occur: " + ", ".join(stale)


def test_the_scan_finds_a_read(tmp_path):
    """The scan is not vacuous: a consumer reading the export's old sources is reported."""
    (tmp_path / "service").mkdir()
    (tmp_path / "service" / "probe.py").write_text(
        "def f(allocator, impl):\n    return allocator.impl._P, allocator._safe, getattr(impl, '_lex'), self._P\n")
    reads = private_reads(tmp_path, ("service",))
    assert set(reads) == {("service/probe.py", "allocator.impl._P"), ("service/probe.py", "allocator._safe"),
                          ("service/probe.py", "getattr(impl, '_lex')")}
