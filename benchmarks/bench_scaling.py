"""Host ``qp``, ``wls`` and ``dynamic``, cold and warm-started (``warm_start=True``), against
DAQP's Python ``Model`` as the number of effectors grows.

Problems: ``k`` = 4 and 6 axes, ``m`` = 6 ... 192 effectors, ``B`` seeded normal, limits
[-1, 1], ``up = 0``, identity weights.  Demands: ``random`` (independent, each axis uniform in
0.8 of what it reaches alone: most calls saturate some effectors) and ``smooth`` (a sum of sines
sampled at 2 kHz, 0.6 of that reach: how a flight controller calls).  DAQP's reference is its
own Python API on the ``wls`` problem (``benchmarks.bench_alloc.daqp_reference``): one Model
built once, the linear term updated per call, its active set kept ("warm") or reset ("cold").
Every variant sees the same demands, interleaved in blocks so that they share the machine's
state; each allocator (and DAQP model) is warmed on the first 50 calls, which are not timed.

Printed per cell: median and p99 microseconds per call, the ratios of host ``qp`` cold and warm
to DAQP warm, the mean active-set iterations of ``qp`` cold and warm, and the largest
disagreement between warm and cold answers (``qp``: commands, in units of the limit span),
with the machine's load (``uptime``) before and after.

    python -m benchmarks.bench_scaling [--calls 2000] [--blocks 20] [--ms 6,12,24,48,96,192] [--ks 4,6]
"""

from __future__ import annotations

import argparse
import os
import platform
import subprocess
import time

import numpy as np

import alloc
from benchmarks.bench_alloc import daqp_reference


def problem(k: int, m: int, seed: int) -> alloc.Problem:
    rng = np.random.default_rng(seed)
    return alloc.Problem(rng.normal(size=(k, m)), -np.ones(m), np.ones(m))


def demands(p: alloc.Problem, kind: str, n: int, rng: np.random.Generator) -> np.ndarray:
    reach = np.abs(p.B).sum(axis=1)  # each axis alone, every effector at its bound
    if kind == "random":
        return rng.uniform(-0.8, 0.8, (n, p.k)) * reach
    t = np.arange(n)[:, None] / 2000.0
    f = rng.uniform(0.3, 3.0, (2, p.k))
    ph = rng.uniform(0.0, 2 * np.pi, (2, p.k))
    return reach * (0.35 * np.sin(2 * np.pi * f[0] * t + ph[0]) + 0.25 * np.sin(2 * np.pi * f[1] * t + ph[1]))


def variants(p: alloc.Problem) -> dict:
    return {"qp cold": alloc.make_allocator(p, "qp"), "qp warm": alloc.make_allocator(p, "qp", warm_start=True),
            "wls cold": alloc.make_allocator(p, "wls"), "wls warm": alloc.make_allocator(p, "wls", warm_start=True),
            "dynamic cold": alloc.make_allocator(p, "dynamic"),
            "dynamic warm": alloc.make_allocator(p, "dynamic", warm_start=True),
            "daqp warm": daqp_reference(p, keep_active_set=True), "daqp cold": daqp_reference(p)}


def cell(p: alloc.Problem, V: np.ndarray, blocks: int, warmup: int = 50) -> dict:
    fs = variants(p)
    for v in V[:warmup]:
        for f in fs.values():
            f(v)
    V = V[warmup:]
    times: dict[str, list[float]] = {name: [] for name in fs}
    iters = {"qp cold": 0, "qp warm": 0}
    worst = 0.0
    span = float(np.max(p.umax - p.umin))
    names = list(fs)
    for b, idx in enumerate(np.array_split(np.arange(len(V)), blocks)):
        order = names if b % 2 == 0 else names[::-1]
        for name in order:
            f = fs[name]
            for i in idx:
                t0 = time.perf_counter()
                f(V[i])
                times[name].append(time.perf_counter() - t0)
    # answers and iterations in a separate pass (not timed): the same calls in the same order
    cold, warm = variants(p)["qp cold"], variants(p)["qp warm"]
    for v in V:
        rc, rw = cold(v), warm(v)
        iters["qp cold"] += rc.iterations
        iters["qp warm"] += rw.iterations
        worst = max(worst, float(np.abs(rc.u - rw.u).max()) / span)
    out = {name: (float(np.median(t)) * 1e6, float(np.quantile(t, 0.99)) * 1e6) for name, t in times.items()}
    out["iters"] = (iters["qp cold"] / len(V), iters["qp warm"] / len(V))
    out["worst"] = worst
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--calls", type=int, default=2000)
    ap.add_argument("--blocks", type=int, default=20)
    ap.add_argument("--ms", default="6,12,24,48,96,192")
    ap.add_argument("--ks", default="4,6")
    args = ap.parse_args()
    import daqp

    uptime = subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip()
    print(f"# bench_scaling: {args.calls} calls per variant and cell (50 untimed first); {platform.machine()}, "
          f"{os.cpu_count()} cores, Python {platform.python_version()}, numpy {np.__version__}, "
          f"daqp {getattr(daqp, '__version__', '0.11.0')}; uptime: {uptime}")
    print("# medians / p99 in microseconds per call; ratio = host qp / DAQP Model warm (medians); "
          "iterations: qp's mean per call, cold / warm; |du|: largest warm-cold difference / limit span")
    rng = np.random.default_rng(2026)
    for k in (int(x) for x in args.ks.split(",")):
        print(f"\n## k = {k}")
        print("| m | demands | qp cold | qp warm | wls cold | wls warm | dynamic cold | dynamic warm | DAQP warm | "
              "DAQP cold | qp cold / DAQP warm | qp warm / DAQP warm | iterations | abs du |")
        print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
        for m in (int(x) for x in args.ms.split(",")):
            p = problem(k, m, seed=1000 * k + m)
            for kind in ("random", "smooth"):
                c = cell(p, demands(p, kind, args.calls + 50, rng), args.blocks)

                def fmt(name: str) -> str:
                    return f"{c[name][0]:.1f} / {c[name][1]:.0f}"

                dw = c["daqp warm"][0]
                print(f"| {m} | {kind} | {fmt('qp cold')} | {fmt('qp warm')} | {fmt('wls cold')} | {fmt('wls warm')} | "
                      f"{fmt('dynamic cold')} | {fmt('dynamic warm')} | {fmt('daqp warm')} | {fmt('daqp cold')} | "
                      f"{c['qp cold'][0] / dw:.2f} | {c['qp warm'][0] / dw:.2f} | {c['iters'][0]:.1f} / {c['iters'][1]:.1f} | "
                      f"{c['worst']:.1e} |", flush=True)
    uptime = subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip()
    print(f"\n# uptime at the end: {uptime}")


if __name__ == "__main__":
    main()
