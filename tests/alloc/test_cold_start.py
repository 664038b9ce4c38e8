"""Compiled kernels for any user (issue 22): where numba's cache goes, and the shipped cache.

The fast tests drive :mod:`alloc._engine._jit_cache` in this process on a one-kernel package written to
a temporary directory (numba compiles it in well under a second).  The slow one installs the
project into a fresh venv and runs ``.ci/check-core-install`` (an unprivileged user with no home
imports and allocates from the root-owned install, no kernel compiled, within 5 s of CPU).
The last ones check what starting costs by what it loads (no timing): importing the service
loads no solver front-end, plot or ``scipy.optimize``; the geometry loads without the
allocator; the service answers while its kernels warm on a thread.
"""

from __future__ import annotations

import importlib.util
import io
import json
import os
import re
import shutil
import subprocess
import sys
import textwrap
import threading
import time
from pathlib import Path

import pytest

from alloc._engine import _jit_cache

ROOT = Path(__file__).resolve().parents[2]
TINY = textwrap.dedent('''
    from numba import njit


    @njit(cache=True)
    def twice(x):
        return 2.0 * x
''')


@pytest.fixture
def fake_root(tmp_path, monkeypatch):
    """A directory standing for site-packages, holding ``alloc/tiny.py`` (one cached kernel)."""
    pkg = tmp_path / "site" / "alloc"
    pkg.mkdir(parents=True)
    (pkg / "tiny.py").write_text(TINY)
    monkeypatch.setattr(_jit_cache, "_ROOT", (tmp_path / "site").resolve())
    monkeypatch.setattr(_jit_cache, "_usable_memo", {})
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    return pkg


def _import_tiny(pkg: Path, tag: str):
    """A new module object (so a new numba dispatcher, a new cache look-up) from ``tiny.py``."""
    spec = importlib.util.spec_from_file_location(f"_cold_start_tiny_{tag}", pkg / "tiny.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _package_dir_read_only(monkeypatch, pkg: Path) -> None:
    """What a user other than the installer sees: the package's __pycache__ is not writable."""
    real = _jit_cache._writable_dir
    shipped = str(pkg / "__pycache__")
    monkeypatch.setattr(_jit_cache, "_writable_dir",
                        lambda path, private_root=None: path != shipped and real(path, private_root))


def _listen():
    from numba.core import event

    notice = _jit_cache.CompileNotice(stream=io.StringIO())
    event.register("numba:compile", notice)
    return notice


def _unlisten(notice) -> None:
    from numba.core import event

    event.unregister("numba:compile", notice)


def test_import_alloc_leaves_numba_alone_until_its_kernels_load():
    """``import alloc`` neither imports numba nor changes it for the process (a user's own numba
    functions keep numba's cache); the locator is installed when alloc's kernel modules load."""
    code = ("import sys, alloc\nprint('numba' in sys.modules)\nimport numba\n"
            "from numba.core.caching import FunctionCache\nprint(FunctionCache._impl_class.__name__)\n"
            "import numpy as np\nalloc.make_allocator(alloc.Problem(np.eye(2), [-1, -1], [1, 1]), 'qp')\n"
            "print(FunctionCache._impl_class.__name__)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=ROOT)
    assert out.stdout.split() == ["False", "CompileResultCacheImpl", "KernelCacheImpl"]


def test_package_kernels_use_the_package_pycache_where_writable():
    def probe():
        pass

    locator = _jit_cache.KernelCacheLocator.from_function(probe, str(ROOT / "alloc" / "_engine" / "_kernels.py"))
    assert locator.writable and locator.get_cache_path() == str(ROOT / "alloc" / "_engine" / "__pycache__")
    # another project's file: numba's own locators decide
    assert _jit_cache.KernelCacheLocator.from_function(probe, str(ROOT / "tests" / "hostile.py")) is None
    assert _jit_cache.KernelCacheLocator.from_function(probe, "/usr/lib/python3/x.py") is None


def test_fallback_order_home_then_temp_then_shm_then_read_only(fake_root, tmp_path, monkeypatch):
    def probe():
        pass

    py_file = str(fake_root / "tiny.py")
    _package_dir_read_only(monkeypatch, fake_root)
    subpath = _jit_cache.KernelCacheLocator.get_suitable_cache_subpath(py_file)
    uid = os.getuid()

    def where() -> tuple[str, bool]:
        _jit_cache._usable_memo.clear()
        locator = _jit_cache.KernelCacheLocator.from_function(probe, py_file)
        return locator.get_cache_path(), locator.writable

    assert where() == (str(tmp_path / "xdg" / "alloc-toolkit" / subpath), True)
    (tmp_path / "blocked").write_text("a file, not a directory")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "blocked"))
    monkeypatch.setattr(_jit_cache.tempfile, "tempdir", str(tmp_path / "tmp"))
    assert where() == (str(tmp_path / "tmp" / f"alloc-toolkit-{uid}" / subpath), True)
    monkeypatch.setattr(_jit_cache.tempfile, "tempdir", str(tmp_path / "blocked"))
    shm = f"/dev/shm/alloc-toolkit-{uid}"
    if os.access("/dev/shm", os.W_OK) and not os.path.exists(shm):
        assert where() == (os.path.join(shm, subpath), True)
        shutil.rmtree(shm)
    monkeypatch.setattr(_jit_cache, "_fallback_dirs", lambda subpath: [])
    assert where() == (str(fake_root / "__pycache__"), False)


def test_shared_temp_root_is_refused_unless_private(tmp_path):
    root = tmp_path / "alloc-toolkit-x"
    root.mkdir(mode=0o700)
    memo = _jit_cache._usable_memo
    assert _jit_cache._writable_dir(str(root / "a"), str(root))
    os.chmod(root, 0o777)  # another user could have planted machine code here
    assert not _jit_cache._writable_dir(str(root / "b"), str(root))
    if os.getuid() == 0:
        os.chmod(root, 0o700)
        os.chown(root, 65534, -1)
        assert not _jit_cache._writable_dir(str(root / "c"), str(root))
    for key in [k for k in memo if k.startswith(str(tmp_path))]:
        del memo[key]


def test_source_stamp_is_the_content_not_the_mtime(fake_root):
    def probe():
        pass

    locator = _jit_cache.KernelCacheLocator.from_function(probe, str(fake_root / "tiny.py"))
    stamp = locator.get_source_stamp()
    os.utime(fake_root / "tiny.py", (1, 1))  # what an install does to the mtime
    assert locator.get_source_stamp() == stamp
    (fake_root / "tiny.py").write_text(TINY + "\n# changed\n")
    assert locator.get_source_stamp() != stamp


def test_nothing_writable_compiles_in_memory_with_a_notice(fake_root, monkeypatch):
    _package_dir_read_only(monkeypatch, fake_root)
    monkeypatch.setattr(_jit_cache, "_fallback_dirs", lambda subpath: [])
    notice = _listen()
    try:
        module = _import_tiny(fake_root, "memory")
        assert module.twice(1.5) == 3.0
    finally:
        _unlisten(notice)
    assert notice.compiles == 1
    text = notice._stream.getvalue()
    assert text.count("\n") == 1 and text.startswith("alloc: compiling kernels (")
    assert "no writable cache directory: kept in memory" in text
    assert not (fake_root / "__pycache__").exists() or not list((fake_root / "__pycache__").glob("*.nb*"))


def test_another_user_loads_the_shipped_cache_without_compiling(fake_root, tmp_path, monkeypatch):
    notice = _listen()
    try:
        assert _import_tiny(fake_root, "installer").twice(2.0) == 4.0  # the build: compiled, saved in the package
        assert notice.compiles == 1 and list((fake_root / "__pycache__").glob("tiny.twice-*.nbi"))
        _package_dir_read_only(monkeypatch, fake_root)
        _jit_cache._usable_memo.clear()
        module = _import_tiny(fake_root, "user")
        assert module.twice(3.0) == 6.0
    finally:
        _unlisten(notice)
    assert notice.compiles == 1, notice._stream.getvalue()  # the user's call loaded it
    assert sum(module.twice.stats.cache_hits.values()) == 1
    seeded = module.twice.stats.cache_path
    assert seeded.startswith(str(tmp_path / "xdg" / "alloc-toolkit")), seeded
    assert {p.name for p in Path(seeded).iterdir()} == {p.name for p in (fake_root / "__pycache__").glob("tiny.*.nb*")}


def test_another_cpu_compiles_into_the_fallback_with_a_notice(fake_root, tmp_path, monkeypatch):
    _import_tiny(fake_root, "build").twice(1.0)
    notice = _listen()
    try:
        _package_dir_read_only(monkeypatch, fake_root)
        _jit_cache._usable_memo.clear()
        # the shipped entries were written on another CPU: their key's CPU name is not this one's
        monkeypatch.setattr(_jit_cache, "_host_magic", lambda: ("x86_64-unknown-linux-gnu", "another-cpu", ""))
        module = _import_tiny(fake_root, "other_cpu")
        fallback = Path(module.twice.stats.cache_path)
        assert fallback.is_relative_to(tmp_path / "xdg") and not list(fallback.glob("*.nb*"))  # nothing copied
        assert module.twice(2.0) == 4.0
    finally:
        _unlisten(notice)
    assert notice.compiles == 1
    assert "saved in " + str(fallback) in notice._stream.getvalue()
    assert list(fallback.glob("tiny.twice-*.nbi")) and list(fallback.glob("tiny.twice-*.nbc"))


@pytest.mark.slow
@pytest.mark.timeout(3600)
def test_fresh_root_install_serves_an_unprivileged_user_without_compiling():
    """``.ci/check-core-install``: ``pip install .`` as root into a fresh venv, then as ``nobody``
    with HOME=/nonexistent the first pinv and qp allocations within 5 s of CPU, nothing compiled;
    then every method on ICE as root, nothing compiled."""
    if os.getuid() != 0 or shutil.which("setpriv") is None:
        pytest.skip("needs root and setpriv to act as another user")
    out = subprocess.run([str(ROOT / ".ci" / "check-core-install")], capture_output=True, text=True, cwd=ROOT)
    assert out.returncode == 0, out.stdout[-3000:] + out.stderr[-3000:]
    firsts = re.findall(r"first (\w+) allocation ([\d.]+) s CPU .*no kernel compiled", out.stdout)
    assert sorted(m for m, _ in firsts) == ["pinv", "qp"], out.stdout
    assert all(float(cpu) < 5.0 for _, cpu in firsts), firsts
    assert "every kernel loaded from the wheel's cache" in out.stdout


# ----------------------------------------------------------------- what starting costs
#: packages a service start-up or a geometry user does not need: solver front-ends, plotting,
#: scipy's optimizer (the exact coverage polytope), the coverage module itself, the detector's
#: statistics and filters (1.4-1.7 s of CPU), the migration tool (only a database to upgrade needs it)
NOT_AT_START = ("scipy.optimize", "cvxpy", "qpsolvers", "matplotlib", "highspy", "osqp", "clarabel",
                "alloc.ams.coverage", "alloc.ams.plot", "sim", "benchmarks", "scipy.stats", "scipy.signal",
                "alembic")


def _loaded_by(code: str) -> set[str]:
    out = subprocess.run([sys.executable, "-c", code + "\nimport sys, json\nprint(json.dumps(sorted(sys.modules)))"],
                         capture_output=True, text=True, check=True, cwd=ROOT)
    return set(json.loads(out.stdout.splitlines()[-1]))


def _heavy(loaded: set[str]) -> list[str]:
    return sorted(m for m in loaded if any(m == p or m.startswith(p + ".") for p in NOT_AT_START))


def test_importing_the_service_loads_no_solver_front_end_plot_or_optimizer():
    loaded = _loaded_by("import service.main")
    assert _heavy(loaded) == []
    assert "fastapi" in loaded and "service.warm" in loaded  # the probe sees what it should


def test_the_geometry_loads_without_the_allocator():
    loaded = _loaded_by("from alloc.ams import AttainableSet, zonotope_volume")
    assert _heavy(loaded) == [] and "alloc.ams.geometry" in loaded
    assert not {"alloc.api", "alloc.registry", "alloc.methods"} & loaded
    # coverage is still one attribute away, and is the function (not its module)
    loaded = _loaded_by("import alloc.ams, types\nassert isinstance(alloc.ams.coverage, types.FunctionType)")
    assert {"alloc.ams.coverage", "scipy.optimize"} <= loaded


def test_the_service_answers_before_its_kernels_are_warm(tmp_path, monkeypatch):
    """The start-up does not wait for the kernel warm-up (service/warm.py): ``/v1/health`` and
    ``/v1/ready`` answer while it runs; the build processes start only after it."""
    from fastapi.testclient import TestClient

    import service.warm
    from service.builds import Builder
    from service.config import Settings
    from service.main import create_app

    release, warming, order = threading.Event(), threading.Event(), []

    def slow_warm_up(stop=None):
        warming.set()
        assert release.wait(30)
        order.append("warmed")
        return 0.0

    monkeypatch.setattr(service.warm, "warm_up", slow_warm_up)
    monkeypatch.setattr(Builder, "start_processes", lambda self: order.append("processes") or [])
    app = create_app(Settings(data_dir=tmp_path, warmup=True))
    with TestClient(app) as client:
        assert warming.wait(30)
        assert client.get("/v1/health").status_code == 200
        assert client.get("/v1/ready").status_code == 200
        assert order == []  # still warming: no build process yet
        release.set()
        deadline = time.monotonic() + 30
        while len(order) < 2 and time.monotonic() < deadline:
            time.sleep(0.01)
    assert order == ["warmed", "processes"]


def test_a_stopped_service_starts_no_build_process_after_warming(tmp_path, monkeypatch):
    """Shutting down while the warm-up runs: the warm-up stops between methods and no build
    process is started after the store closed."""
    from fastapi.testclient import TestClient

    import alloc
    import service.warm
    from service.builds import Builder
    from service.config import Settings
    from service.main import create_app

    started, calls = threading.Event(), []
    real_one = service.warm._warm_one

    def one(name, problem, v):
        started.set()
        calls.append(name)
        time.sleep(0.05)
        real_one(name, problem, v)

    monkeypatch.setattr(service.warm, "_warm_one", one)
    monkeypatch.setattr(service.warm, "_warm", set())
    monkeypatch.setattr(Builder, "start_processes", lambda self: calls.append("processes") or [])
    with TestClient(create_app(Settings(data_dir=tmp_path, warmup=True))):
        assert started.wait(30)
    n = len(calls)
    time.sleep(0.3)
    assert len(calls) == n and "processes" not in calls and n < len(alloc.methods())


def test_warm_as_a_script_tells_each_compile_once_and_quiet_prints_nothing(tmp_path):
    """``python -m alloc._engine._jit_warm warm`` tells each compile once (when the warm-up lived in the
    locator's module, the script was a second module object that installed a second listener,
    and every compile notice came out twice), and prints nothing when asked."""
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path)}
    command = [sys.executable, "-m", "alloc._engine._jit_warm", "warm", "pinv"]
    cold = subprocess.run(command, capture_output=True, text=True, cwd=ROOT, env=env, check=True)
    notices = [line for line in cold.stderr.splitlines() if line.startswith("alloc: compiling")]
    assert notices and len(notices) == len(set(notices)), cold.stderr
    assert re.search(r"^warmed 1 methods in .*kernels compiled\)$", cold.stdout, re.MULTILINE), cold.stdout
    quiet = subprocess.run(command + ["--quiet"], capture_output=True, text=True, cwd=ROOT, env=env, check=True)
    assert (quiet.stdout, quiet.stderr) == ("", "")
    summary = subprocess.run(command + ["--summary"], capture_output=True, text=True, cwd=ROOT, env=env, check=True)
    assert summary.stderr == "" and len(summary.stdout.splitlines()) == 1, summary.stdout
