"""Run inside a clean venv holding only ``pip install .``: the core works alone.

Asserts that the optional packages are absent, allocates with every registered method on
the seed's ICE problem without compiling a kernel (the wheel carries them: setup.py), and
checks that the commands of the packages built on the library point at their extra instead of
failing obscurely.

``core_install.py --cold`` (run first, by a user who can write neither the installed package
nor a home): each default method's first allocation in a fresh interpreter imports, builds and
allocates without compiling, within ``COLD_CPU_S`` of CPU for the whole process.
"""

from __future__ import annotations

import importlib.util
import os
import shutil
import subprocess
import sys

import numpy as np

#: the goal for the default methods' first allocation after a fresh install (issue 22)
COLD_CPU_S = 5.0
COLD_METHODS = ("pinv", "qp")


def cold_check() -> None:
    import alloc
    from benchmarks.bench_startup import first_allocation  # the benchmark's own probe, installed with alloc

    pkg_cache = os.path.join(os.path.dirname(alloc.__file__), "__pycache__")
    assert not os.access(pkg_cache, os.W_OK), f"this check needs a read-only install: {pkg_cache} is writable"
    assert not os.access(os.path.expanduser("~"), os.W_OK), "this check needs a user without a writable home"
    for method in COLD_METHODS:
        row = first_allocation(method)
        assert "compiling" not in row["stderr"] and row["compiles"] == 0, (method, row)
        assert row["status"] in ("exact", "unattainable"), (method, row)  # not a fallback
        assert row["process_cpu"] < COLD_CPU_S, (method, row)
        assert not row["cache"].startswith(os.path.dirname(alloc.__file__)), row  # a fallback, not the package
        print(f"core install, uid {os.getuid()}, read-only package, no home: first {method} allocation "
              f"{row['process_cpu']:.2f} s CPU (import {row['import_cpu']:.2f}, make_allocator "
              f"{row['make_cpu']:.2f}, call {row['call_cpu']:.3f}), no kernel compiled; cache {row['cache']}")


if "--cold" in sys.argv:
    cold_check()
    sys.exit(0)

ABSENT = ("fastapi", "dask", "distributed", "cvxpy", "matplotlib", "qpsolvers", "sqlalchemy", "uvicorn", "tqdm")
present = [name for name in ABSENT if importlib.util.find_spec(name) is not None]
assert not present, f"the core install pulled in optional packages: {present}"

import alloc  # noqa: E402
from alloc import vehicles  # noqa: E402

assert "site-packages" in alloc.__file__, f"not the installed package: {alloc.__file__}"
from alloc.api import has_c_call_path  # noqa: E402

# the C call path (alloc/_engine/_fastcall.c) is optional in general, but this machine has a compiler
assert has_c_call_path(), "alloc._engine._fastcall was not built by `pip install .`"
p = vehicles.problem("ice")
v = np.array([2.0, 30.0, 0.5])  # attainable: the README's example demand
for method in alloc.methods():
    options = {"groups": vehicles.daisy_groups("ice")} if method == "daisy" else {}
    r = alloc.make_allocator(p, method, **options)(v)
    assert np.isfinite(r.u).all() and (r.u >= p.umin).all() and (r.u <= p.umax).all(), method
    assert r.status.value in ("exact", "unattainable"), (method, r.status)
    meets = np.allclose(p.B @ r.u, v, rtol=1e-6, atol=1e-6)
    assert meets == (r.status.value == "exact"), (method, r.status, p.B @ r.u)
    if method in ("qp", "lp", "da", "da_facet", "cgi"):  # optimal or boundary methods reach it
        assert meets, (method, p.B @ r.u)
from alloc._engine import _jit_cache  # noqa: E402

assert _jit_cache.notice.compiles == 0, f"{_jit_cache.notice.compiles} kernels compiled: the wheel lacks them"
print(f"core install: {len(alloc.methods())} methods allocate on ICE without optional packages, "
      "every kernel loaded from the wheel's cache")

exe = shutil.which("alloc")
assert exe is not None, "the alloc command is not installed"
out = subprocess.run([exe, "--help"], capture_output=True, text=True, check=True).stdout
for command in ("methods", "allocate", "ams", "sim", "serve", "bench"):
    assert command in out, (command, out)
for command, extra in (("serve", "service"), ("sim", "sim")):
    run = subprocess.run([exe, command, "--port", "1"] if command == "serve" else [exe, command, "ice"],
                         capture_output=True, text=True, env={**os.environ, "COLUMNS": "200"})
    assert run.returncode == 2 and f"alloc-toolkit[{extra}]" in run.stderr, (command, run.returncode, run.stderr)
print("core install: `alloc serve` and `alloc sim` name their extras")
sys.exit(0)
