"""Per-call cost and behaviour of ``px4`` (PX4's mixer) beside ``pinv_clip`` and ``qp`` on multirotors.

Vehicles: the bundled ``hexa-x`` (physical units, axes roll, pitch, yaw, thrust) and X rings of
4 and 8 rotors built with PX4's importer (``CA_ROTORn_*``, 0.25 m arms).  Demands: hover thrust
plus random moments (``random``), or a sum of sines sampled at 2 kHz (``sines``), both scaled so
that about half the calls saturate.  Every method sees the same demands, interleaved in blocks
(so they share the machine's state).  Printed: median and p99 microseconds per call through
``make_allocator``, the share of calls that met the demand exactly and, where not, the median
error on roll and pitch (what airmode is there to keep) in the vehicle's units, plus the
machine's load (``uptime``).

    python -m benchmarks.bench_px4 [--calls 3000] [--blocks 30]
"""

from __future__ import annotations

import argparse
import os
import platform
import subprocess
import time

import numpy as np

import alloc
from alloc.importers.px4 import vehicle_from_params

METHODS = (("px4", {}), ("px4", {"airmode": "roll_pitch"}), ("px4", {"airmode": "roll_pitch_yaw"}),
           ("pinv_clip", {}), ("qp", {}))


def ring(n: int, first_deg: float) -> alloc.Problem:
    params: dict[str, float] = {"CA_AIRFRAME": 0, "CA_ROTOR_COUNT": n}
    for i in range(n):
        a = np.deg2rad(first_deg + 360.0 * i / n)
        params |= {f"CA_ROTOR{i}_PX": 0.25 * np.cos(a), f"CA_ROTOR{i}_PY": 0.25 * np.sin(a),
                   f"CA_ROTOR{i}_KM": 0.05 if i % 2 == 0 else -0.05}
    return vehicle_from_params(params, name=f"ring{n}").problem()


def demands(p: alloc.Problem, kind: str, n: int, rng: np.random.Generator) -> np.ndarray:
    """Hover (half of full thrust on every rotor) plus moments up to 0.8 of what one axis
    alone reaches from hover; ``sines`` moves them smoothly at 2 kHz."""
    hover = p.B @ (0.5 * (p.umin + p.umax))
    reach = 0.5 * np.abs(p.B) @ (p.umax - p.umin)
    moment = np.array([a in ("roll", "pitch", "yaw") for a in p.axes], dtype=float)
    if kind == "random":
        w = rng.uniform(-0.8, 0.8, (n, p.k))
    else:
        t = np.arange(n)[:, None] / 2000.0
        f = rng.uniform(0.5, 3.0, (1, p.k))
        w = 0.8 * np.sin(2 * np.pi * f * t + rng.uniform(0, 2 * np.pi, (1, p.k)))
    return hover + w * reach * moment


def run(p: alloc.Problem, V: np.ndarray, blocks: int) -> list[tuple[str, float, float, float, float]]:
    fs = [(m + "".join(f" {k}={v}" for k, v in o.items()), alloc.make_allocator(p, m, **o)) for m, o in METHODS]
    times = {name: [] for name, _ in fs}
    for f in fs:  # warm: kernels compiled, caches filled
        f[1](V[0])
    rp = [i for i, a in enumerate(p.axes) if a in ("roll", "pitch")]
    chunks = np.array_split(np.arange(len(V)), blocks)
    for b, idx in enumerate(chunks):
        order = fs if b % 2 == 0 else fs[::-1]
        for name, f in order:
            for i in idx:
                t0 = time.perf_counter()
                f(V[i])
                times[name].append(time.perf_counter() - t0)
    out = []
    for name, f in fs:
        rs = [f(v) for v in V]
        exact = np.mean([r.status is alloc.Status.EXACT for r in rs])
        miss = [np.abs(r.unallocated[rp]).max() for r in rs if r.status is not alloc.Status.EXACT]
        t = np.array(times[name]) * 1e6
        out.append((name, float(np.median(t)), float(np.quantile(t, 0.99)), float(exact),
                    float(np.median(miss)) if miss else 0.0))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--calls", type=int, default=3000)
    ap.add_argument("--blocks", type=int, default=30)
    args = ap.parse_args()
    load = subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip()
    print(f"# bench_px4: {args.calls} calls per method and sequence; {platform.machine()}, "
          f"{os.cpu_count()} cores, numpy {np.__version__}; uptime: {load}")
    vehicles = {"hexa-x (6, physical units)": alloc.load_vehicle("hexa-x").problem(),
                "quad X ring (4)": ring(4, 45.0), "octa X ring (8)": ring(8, 22.5)}
    rng = np.random.default_rng(0)
    for vname, p in vehicles.items():
        for kind in ("random", "sines"):
            V = demands(p, kind, args.calls, rng)
            print(f"\n## {vname}, {kind}")
            print("| method | median us | p99 us | exact share | median roll/pitch miss when not exact |")
            print("|---|---|---|---|---|")
            for name, med, p99, exact, miss in run(p, V, args.blocks):
                print(f"| {name} | {med:.2f} | {p99:.1f} | {exact:.3f} | {miss:.3g} |")
    load = subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip()
    print(f"\n# uptime at the end: {load}")


if __name__ == "__main__":
    main()
