"""Run inside a clean venv holding only ``pip install .``: the core works alone.

Asserts that the optional packages are absent, allocates with every registered method on
the seed's ICE problem, and checks that the commands of the packages built on the library
point at their extra instead of failing obscurely.
"""

from __future__ import annotations

import importlib.util
import os
import shutil
import subprocess
import sys

import numpy as np

ABSENT = ("fastapi", "dask", "distributed", "cvxpy", "matplotlib", "qpsolvers", "sqlalchemy", "uvicorn", "tqdm")
present = [name for name in ABSENT if importlib.util.find_spec(name) is not None]
assert not present, f"the core install pulled in optional packages: {present}"

import alloc  # noqa: E402
from alloc import vehicles  # noqa: E402

assert "site-packages" in alloc.__file__, f"not the installed package: {alloc.__file__}"
from alloc.api import FAST_CALL  # noqa: E402

# the C call path (alloc/_fastcall.c) is optional in general, but this machine has a compiler
assert FAST_CALL, "alloc._fastcall was not built by `pip install .`"
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
print(f"core install: {len(alloc.methods())} methods allocate on ICE without optional packages")

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
