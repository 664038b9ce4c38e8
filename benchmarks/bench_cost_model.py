"""The declared build cost model against measured builds: time and peak memory, every priced method.

For every cell (method, k, m, conditioning, options) a fresh interpreter builds the allocator
twice: once timed (CPU seconds, ``time.process_time``, and the growth of the peak RSS), once under
``tracemalloc`` (the peak of the traced allocations: numpy's buffers are traced).  ``t_ratio`` and
``m_ratio`` are measured / declared (``Method.build_cost``, ``Method.build_memory``); the model
holds a cell when both lie in ``[0.1, 2]``.  A facet search that the model routes to ``da``'s LP
(``route = lp``) is compared with what that build declares: the LP's own cost
(``get_method("da").build_cost(problem, backend="daqp")``, and the facet search's
``build_memory``, which is the LP's when routed); a refusal lists its field.

Conditionings: ``random`` (seeded Gaussian ``B``, diagonal weights), ``fullW`` (the same with full
symmetric positive definite ``Wu`` and ``Wv``: the facet builds do not read the weights, shown
here), ``near`` (rank ``k - 1`` plus ``1e-9`` Gaussian: the hyperplane tolerance merges
directions unevenly; routed to the LP before any enumeration), ``nearW`` (the same with full
weights), ``mild`` (rank ``k - 1`` plus ``1e-6``: enumerated, a few more tiles than in general
position).

Usage::

    nice -n 10 python -m benchmarks.bench_cost_model               # the table
    python -m benchmarks.bench_cost_model --quick                  # the small cells only
    python -m benchmarks.bench_cost_model --write-docs             # also into docs/contract.md
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
LOW, HIGH = 0.1, 2.0
_BEGIN, _END = "<!-- cost-model table: begin -->", "<!-- cost-model table: end -->"

#: (method, k, m, conditioning, options): up to and just past where the bounds bite
#: (k = 3: m > 223 by memory; k = 4: m > 71; k = 6: m > 28; k = 2 never within m <= 512)
CELLS: list[tuple[str, int, int, str, dict]] = [
    *[("da_facet", 2, m, "random", {}) for m in (8, 64, 512)],
    *[(name, 3, m, "random", {}) for m in (16, 64, 141, 223, 224) for name in ("da_facet", "da_bisect")],
    *[("da_table", 3, m, "random", {"resolution": r}) for m, r in ((16, 16), (16, 64), (64, 16), (64, 64),
                                                                    (100, 32), (141, 16))],
    *[("da_facet", 4, m, "random", {}) for m in (12, 32, 71, 72)],
    *[("da_facet", 6, m, "random", {}) for m in (10, 20, 28, 29)],
    ("da_facet", 8, 16, "random", {}), ("da_facet", 14, 17, "random", {}),
    ("da_facet", 3, 64, "fullW", {}), ("da_table", 3, 64, "fullW", {"resolution": 64}),
    ("da_facet", 6, 20, "fullW", {}),
    ("da_facet", 3, 26, "near", {}), ("da_table", 3, 26, "near", {"resolution": 64}),
    ("da_facet", 3, 26, "nearW", {}), ("da_table", 3, 26, "nearW", {"resolution": 64}),
    ("da_facet", 3, 64, "near", {}), ("da_facet", 4, 20, "near", {}), ("da_facet", 6, 14, "near", {}),
    ("da_facet", 3, 64, "mild", {}), ("da_table", 3, 26, "mild", {"resolution": 64}),
    ("da_facet", 4, 32, "mild", {}),
]
QUICK = [c for c in CELLS if c[2] <= 32 and c[1] < 14]

_CHILD = r"""
import json, resource, sys, time, tracemalloc
import numpy as np
import alloc
from alloc.registry import get_method
from benchmarks.bench_cost_model import problem
name, k, m, cond, options = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), sys.argv[4], json.loads(sys.argv[5])
p = problem(k, m, cond)
warm = problem(k, k + 1, "random")
alloc.make_allocator(warm, name, **options)  # kernels loaded, imports done
cls = get_method(name)
out = {"subsets": cls.facet_subsets(p, options), "declared_s": cls.build_cost(p, **options),
       "declared_b": cls.build_memory(p, **options)}
r0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
t0 = time.process_time()
try:
    f = alloc.make_allocator(p, name, **options)
except alloc.AllocError as exc:
    out.update(route="refused", field=exc.field, message=str(exc))
    print(json.dumps(out)); raise SystemExit
out["cpu_s"] = time.process_time() - t0
out["rss_b"] = (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - r0) * 1024
impl = f.impl
lp = bool(getattr(impl, "uses_lp", False))
out["route"] = "lp" if lp else "facets"
out["reason"] = getattr(impl, "lp_reason", "")
out["tiles"] = getattr(impl, "tile_count", 0)
if lp:  # what the routed build declares: the LP's set-up
    out["declared_s"] = get_method("da").build_cost(p, backend="daqp")
del f, impl
tracemalloc.start()
alloc.make_allocator(p, name, **options)
out["peak_b"] = tracemalloc.get_traced_memory()[1]
tracemalloc.stop()
print(json.dumps(out))
"""


def problem(k: int, m: int, conditioning: str):
    """The seeded problem of one cell (see the module docstring for the conditionings)."""
    import numpy as np

    import alloc
    from alloc.testing import random_problem

    rng = np.random.default_rng(1000 * k + m)
    p = random_problem(rng, k, m, "general", weights=False, rates=False)
    if conditioning == "random":
        return p
    B, Wu, Wv = p.B, None, None
    if conditioning in ("near", "nearW", "mild"):
        eps = 1e-6 if conditioning == "mild" else 1e-9
        B = rng.standard_normal((k, k - 1)) @ rng.standard_normal((k - 1, m)) + eps * rng.standard_normal((k, m))
    if conditioning in ("fullW", "nearW"):
        L = rng.standard_normal((m, m))
        Wu = L @ L.T / m + np.eye(m)
        L = rng.standard_normal((k, k))
        Wv = L @ L.T + k * np.eye(k)
    elif conditioning not in ("near", "mild"):
        raise ValueError(f"conditioning: unknown {conditioning!r}")
    return alloc.Problem(B, p.umin, p.umax, Wu=Wu, Wv=Wv)


def measure(cell: tuple[str, int, int, str, dict]) -> dict:
    name, k, m, cond, options = cell
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    run = subprocess.run([sys.executable, "-c", _CHILD, name, str(k), str(m), cond, json.dumps(options)],
                         capture_output=True, text=True, timeout=1800, env=env, cwd=ROOT)
    if run.returncode:
        raise RuntimeError(run.stderr[-2000:])
    return json.loads(run.stdout.strip().splitlines()[-1])


def row(cell, got: dict) -> tuple[str, bool]:
    name, k, m, cond, options = cell
    opts = ",".join(f"{a}={b}" for a, b in options.items()) or "-"
    head = f"| {name} | {k} | {m} | {cond} | {opts} | {got['subsets']:,} |"
    if got["route"] == "refused":
        return f"{head} refused ({got['field']}) | {got['declared_s']:.3g} | | | | | | |", True
    t_ratio = got["cpu_s"] / got["declared_s"]
    m_ratio = got["peak_b"] / got["declared_b"]
    ok = LOW <= t_ratio <= HIGH and LOW <= m_ratio <= HIGH
    return (f"{head} {got['route']} | {got['declared_s']:.3g} | {got['cpu_s']:.3g} | {t_ratio:.2f} | "
            f"{got['declared_b'] / 2**20:.3g} | {got['peak_b'] / 2**20:.3g} | {got['rss_b'] / 2**20:.3g} | "
            f"{m_ratio:.2f} |{'' if ok else ' **outside**'}"), ok


def machine_state() -> str:
    load = os.getloadavg()
    when = datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M UTC")
    return (f"{when}, {platform.machine()} {os.cpu_count()} cores, load average {load[0]:.2f} / {load[1]:.2f} / "
            f"{load[2]:.2f} (1 / 5 / 15 min), Python {platform.python_version()}")


def table(cells) -> tuple[list[str], int]:
    lines = ["| method | k | m | conditioning | options | subsets | route | declared s | CPU s | t ratio | "
             "declared MiB | peak MiB (traced) | RSS growth MiB | m ratio |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    bad = 0
    print("\n".join(lines), flush=True)
    for cell in cells:
        line, ok = row(cell, measure(cell))
        bad += not ok
        lines.append(line)
        print(line, flush=True)
    return lines, bad


def write_docs(lines: list[str], state: str, bad: int) -> None:
    path = ROOT / "docs" / "contract.md"
    text = path.read_text()
    block = "\n".join([_BEGIN, "", f"Measured {state}; `python -m benchmarks.bench_cost_model --write-docs`. "
                       f"Cells outside [{LOW:g}, {HIGH:g}]: {bad}.", "", *lines, "", _END])
    if _BEGIN in text:
        text = re.sub(re.escape(_BEGIN) + ".*?" + re.escape(_END), lambda _: block, text, flags=re.S)
    else:
        raise SystemExit(f"docs/contract.md: no {_BEGIN!r} marker")
    path.write_text(text)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="the small cells only")
    ap.add_argument("--write-docs", action="store_true", help="write the table into docs/contract.md")
    args = ap.parse_args()
    state = machine_state()
    print(f"machine: {state}")
    lines, bad = table(QUICK if args.quick else CELLS)
    state_after = machine_state()
    print(f"machine after: {state_after}\ncells outside [{LOW:g}, {HIGH:g}]: {bad}")
    if args.write_docs:
        write_docs(lines, f"{state}; after: load {state_after.split('load average ')[1].split(' (')[0]}", bad)


if __name__ == "__main__":
    main()
