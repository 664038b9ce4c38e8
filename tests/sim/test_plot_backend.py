"""Library code never chooses a matplotlib backend (STYLE.md; issue 10).

Plots are drawn on a bare :class:`matplotlib.figure.Figure`, whose ``savefig``
renders PNG through Agg whatever the backend, so they work headless and leave
the caller's choice of backend alone.
"""

from __future__ import annotations

import ast
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
LIBRARY = ("alloc", "sim", "service", "benchmarks")


def _backend_choices(path: Path) -> list[str]:
    """``matplotlib.use(...)`` calls, ``from matplotlib import use`` and pyplot imports in one file."""
    found = []
    where = path.relative_to(ROOT) if path.is_relative_to(ROOT) else path
    for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr == "use" \
                and isinstance(node.func.value, ast.Name) and node.func.value.id in ("matplotlib", "mpl"):
            found.append(f"{where}:{node.lineno} matplotlib.use")
        elif isinstance(node, ast.ImportFrom) and (node.module or "").startswith("matplotlib") \
                and any(a.name in ("use", "pyplot") for a in node.names):
            found.append(f"{where}:{node.lineno} from {node.module} import ...")
        elif isinstance(node, ast.Import) and any(a.name == "matplotlib.pyplot" for a in node.names):
            found.append(f"{where}:{node.lineno} import matplotlib.pyplot")
    return found


def test_no_library_module_chooses_a_backend_or_uses_pyplot():
    files = [p for pkg in LIBRARY for p in sorted((ROOT / pkg).rglob("*.py"))]
    assert len(files) > 50  # the walk found the packages
    assert [hit for p in files for hit in _backend_choices(p)] == []


def test_the_checker_sees_a_backend_choice(tmp_path):
    bad = tmp_path / "bad.py"
    bad.write_text("import matplotlib\nmatplotlib.use('Agg')\nimport matplotlib.pyplot as plt\nfrom matplotlib import use\n")
    assert len(_backend_choices(bad)) == 3


def test_plots_render_headless_without_touching_the_backend(tmp_path):
    """With no DISPLAY and no MPLBACKEND, the simulator's and the sweep report's figures are written,
    pyplot is never imported and the backend setting is still unresolved (nobody chose one)."""
    pytest.importorskip("matplotlib")
    script = f"""
import sys
import matplotlib
from sim.plots import plot_result
from sim.scenarios import get_scenario
from benchmarks.compare.report import _subplots

before = dict.__getitem__(matplotlib.rcParams, "backend")
plot_result(get_scenario("pendulum")(duration=0.2), {str(tmp_path / "sim.png")!r})
fig, axes = _subplots(1, 2, figsize=(4, 2), sharey=True)
axes[0].plot([0, 1], [1, 0])
fig.savefig({str(tmp_path / "report.png")!r}, dpi=50)
assert "matplotlib.pyplot" not in sys.modules
assert dict.__getitem__(matplotlib.rcParams, "backend") == before
"""
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY", "MPLBACKEND")}
    env["PYTHONPATH"] = str(ROOT)
    proc = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    for name in ("sim.png", "report.png"):
        assert (tmp_path / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
