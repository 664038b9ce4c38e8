"""The kernel caches are placed by the modules that have kernels, not by ``import alloc``: every
module of the distribution that imports numba as it loads imports :mod:`alloc._engine._kernel_cache`
first (so the locator is in place before any kernel is decorated; a function that reads an
existing kernel's types imports numba after some kernel module has), and ``import alloc`` leaves numba
unimported and the import system as it found it."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
EXEMPT = {"alloc/_engine/_jit_cache.py"}  # the locator itself


def _numba_modules() -> list[Path]:
    out = []
    for package in ("alloc", "sim", "service", "benchmarks"):
        for path in sorted((ROOT / package).rglob("*.py")):
            if str(path.relative_to(ROOT)) in EXEMPT:
                continue
            tree = ast.parse(path.read_text())
            for node in tree.body:  # module level: a module that decorates kernels as it loads
                names = ([a.name for a in node.names] if isinstance(node, ast.Import)
                         else [node.module or ""] if isinstance(node, ast.ImportFrom) else [])
                if any(n == "numba" or n.startswith("numba.") for n in names):
                    out.append(path)
                    break
    return out


def _first_line(tree: ast.Module, test) -> int | None:
    lines = [node.lineno for node in ast.walk(tree) if isinstance(node, (ast.Import, ast.ImportFrom)) and test(node)]
    return min(lines) if lines else None


def test_every_kernel_module_places_the_caches_before_importing_numba() -> None:
    modules = _numba_modules()
    assert len(modules) >= 12  # alloc's kernels, the facet kernels, px4, and sim's engine blocks
    for path in modules:
        tree = ast.parse(path.read_text())
        numba = _first_line(tree, lambda n: any(a.name.split(".")[0] == "numba" for a in n.names)
                            if isinstance(n, ast.Import) else (n.module or "").split(".")[0] == "numba")
        placed = [node for node in tree.body if isinstance(node, ast.Import)
                  and any(a.name == "alloc._engine._kernel_cache" for a in node.names)]
        assert placed, f"{path.relative_to(ROOT)} imports numba without alloc._engine._kernel_cache"
        assert placed[0].lineno < numba, f"{path.relative_to(ROOT)}: alloc._engine._kernel_cache after numba"


def test_import_alloc_leaves_numba_and_the_import_system_alone() -> None:
    code = ("import sys; before = list(sys.meta_path); import alloc; alloc.Problem; "
            "assert sys.meta_path == before, sys.meta_path; assert 'numba' not in sys.modules; print('ok')")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert out.returncode == 0 and out.stdout.strip() == "ok", out.stderr
