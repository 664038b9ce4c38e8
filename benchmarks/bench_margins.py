"""Stability margins per allocator: ICE and HARV lat-dir, every method, three frame rates, nominal and failed.

Each case linearises the closed loop (:mod:`sim.linearise`) at its operating point: the
trim, the loop's equilibrium with no input (:func:`sim.linearise.operating_point`; nominal),
or the recorded state ``--after`` seconds after the scenario's failure struck the trim, the
allocator told of it (failed: :func:`sim.linearise.after_failure`).  Noise is off.  Per case:
the closed loop's spectral radius at the frame period (< 1: locally stable), the worst loop-at-a-time gain margin (nearest 0 dB) and
phase margin over the actuator channels, the worst SISO disk margin, the MIMO return
difference's smallest singular value and unstructured disk margin at the actuator inputs,
the pilot loop's margins, and how many effectors the allocator's local map leaves out (zero
rows of ``du/dv``: saturated or outside the active set).

``explain`` linearises along recorded flights (the three observed divergences): at every
``--every`` seconds of the flight (scenario inputs, noise off) the local map and the margins.

    python -m benchmarks.bench_margins table --csv benchmarks/reference/margins.csv
    python -m benchmarks.bench_margins report --csv benchmarks/reference/margins.csv --markdown
    python -m benchmarks.bench_margins explain --scenario ice --method daisy --frame-period 0.0005 --every 4
    python -m benchmarks.bench_margins explain --scenario harv_latdir --method qp --frame-period 0.01 --every 2 --failed
"""

from __future__ import annotations

import os

# Small dense products: BLAS threads on a shared two-core machine cost 50x their work.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse
import csv
import math
import sys
import time
from typing import Any

import numpy as np

import alloc
from sim.allocation import STATIC
from sim.packed import FloatSlot
from sim.linearise import FrameLoop, after_failure, linearise, margins, operating_point
from sim.scenarios import harv_latdir, ice
from sim.scenarios.mimo import MimoScenario, mimo_spec

SCENARIOS: dict[str, tuple[MimoScenario, str]] = {"ice": (ice.SCENARIO, "seed"),
                                                   "harv_latdir": (harv_latdir.SCENARIO, "failure2")}
FRAME_PERIODS = (0.02, 0.01, 0.0005)
FIELDS = ["scenario", "method", "frame_period", "case", "states", "spectral_radius", "stable", "gm_db", "pm_deg",
          "disk", "sigma_min", "mimo_disk", "pilot_gm_db", "pilot_pm_deg", "pilot_disk", "left_out", "smc_saturated",
          "residual", "seconds"]


def methods() -> list[str]:
    """Every registry method and the seed's printed distribution."""
    return [*alloc.methods(), STATIC]


def case_loop(scenario: str, method: str, frame_period: float, failed: bool, **options: Any) -> FrameLoop:
    """The :class:`FrameLoop` of one case (noise off; failed: the scenario's failure, told)."""
    scen, failure = SCENARIOS[scenario]
    spec, _ = mimo_spec(scen, method=method, frame_period=frame_period, noise=False, failure=failure,
                        allocator_knows_failure=True, duration=1.0, **options)
    return FrameLoop(spec, failed=failed)


def margin_row(loop: FrameLoop, X0: np.ndarray, n_frequencies: int = 500) -> dict[str, Any]:
    """One row of the table from a loop and its operating point."""
    lin = linearise(loop, X0)
    mg = margins(lin, n_frequencies=n_frequencies)
    worst = int(np.nanargmin(np.abs(mg.gain_margin_db))) if np.any(np.isfinite(mg.gain_margin_db)) else None
    return {
        "states": loop.n_states, "spectral_radius": mg.spectral_radius, "stable": mg.stable,
        "gm_db": math.nan if worst is None else float(mg.gain_margin_db[worst]),
        "pm_deg": float(np.nanmin(mg.phase_margin_deg)) if np.any(np.isfinite(mg.phase_margin_deg)) else math.inf,
        "disk": mg.worst_channel_disk_margin, "sigma_min": mg.sigma_min, "mimo_disk": mg.mimo_disk_margin,
        "pilot_gm_db": mg.pilot_gain_margin_db, "pilot_pm_deg": mg.pilot_phase_margin_deg,
        "pilot_disk": mg.pilot_disk_margin,
        "left_out": int(np.sum(np.all(np.abs(lin.J_v) < 1e-9, axis=1))),
        "smc_saturated": len(lin.saturated_channels), "residual": lin.residual,
    }


def table(args: argparse.Namespace) -> None:
    done = set()
    if os.path.exists(args.csv):
        with open(args.csv) as f:
            done = {(r["scenario"], r["method"], float(r["frame_period"]), r["case"]) for r in csv.DictReader(f)}
    new = not os.path.exists(args.csv)
    with open(args.csv, "a", newline="") as f:
        out = csv.DictWriter(f, FIELDS)
        if new:
            out.writeheader()
        for scenario in args.scenarios:
            for T in args.frame_periods:
                for method in args.methods or methods():
                    for case in args.cases:
                        if (scenario, method, T, case) in done:
                            continue
                        t0 = time.process_time()
                        nominal = case_loop(scenario, method, T, False)
                        X = operating_point(nominal, settle=args.settle)
                        loop = nominal
                        if case == "failed":
                            loop = case_loop(scenario, method, T, True)
                            X = after_failure(nominal, loop, X, args.after)
                        row = {"scenario": scenario, "method": method, "frame_period": T, "case": case,
                               **margin_row(loop, X, args.frequencies)}
                        row["seconds"] = round(time.process_time() - t0, 2)
                        out.writerow(row)
                        f.flush()
                        print(f"{scenario} {method} {T} {case}: rho {row['spectral_radius']:.5f} "
                              f"sigma_min {row['sigma_min']:.3f} ({row['seconds']} s)", file=sys.stderr)


def _fmt(x: Any, digits: int = 2) -> str:
    try:
        v = float(x)
    except (TypeError, ValueError):
        return str(x)
    if math.isnan(v):
        return "-"
    if math.isinf(v):
        return "inf" if v > 0 else "-inf"
    return f"{v:.{digits}f}"


def report(args: argparse.Namespace) -> None:
    with open(args.csv) as f:
        rows = list(csv.DictReader(f))
    print("| scenario | T (ms) | method | case | rho | GM (dB) | PM (deg) | disk | sigma_min(I+L) | MIMO disk | "
          "pilot GM (dB) | pilot PM (deg) | left out | SMC sat |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['scenario']} | {float(r['frame_period']) * 1e3:g} | {r['method']} | {r['case']} | "
              f"{_fmt(r['spectral_radius'], 4)} | {_fmt(r['gm_db'], 1)} | {_fmt(r['pm_deg'], 1)} | "
              f"{_fmt(r['disk'])} | {_fmt(r['sigma_min'], 3)} | {_fmt(r['mimo_disk'], 3)} | "
              f"{_fmt(r['pilot_gm_db'], 1)} | {_fmt(r['pilot_pm_deg'], 1)} | {r['left_out']} | {r['smc_saturated']} |")


def flight_points(loop: FrameLoop, duration: float, every: float, failure_time: float | None
                  ) -> list[tuple[float, np.ndarray, bool]]:
    """States along the scenario's own flight (its commands and pilot input, noise off) every ``every`` s.

    Returns ``(t, state, failed)``; the flight stops at a non-finite state or at the scenario's
    divergence bound.  With ``failure_time`` the failure is injected then (the failed loop takes
    over the state).
    """
    spec = loop.spec
    n = int(round(duration / loop.T))
    t = np.arange(n) * loop.T
    cmd = np.asarray(spec.commands)[:: loop.N][:n]
    att = np.column_stack([p.attitude_command(t) for p in spec.pilots]) if spec.pilots else None
    failed_loop = FrameLoop(spec, failed=True) if failure_time is not None else None
    X, current, failed = loop.initial_state(), loop, False
    out, stride = [], int(round(every / loop.T))
    bound = np.broadcast_to(spec.output_bound, (loop.k,))
    for i in range(n):
        if failed_loop is not None and not failed and t[i] >= failure_time - 0.5 * loop.T:
            X0 = failed_loop.initial_state()
            # the failed loop's delay ring starts empty (the engine pre-fills it with the last command)
            for name in ("x", "pos", "rate", "uact", "xc", "xk", "integ", "phist", "pxf", "uprev"):
                failed_loop.part(X0, name)[:] = loop.part(X, name)
            X, current, failed = X0, failed_loop, True
        if i % stride == 0:
            out.append((float(t[i]), X.copy(), failed))
        X, o = current.step(X, cmd[i], None if att is None else att[i])
        if not np.all(np.isfinite(X)) or np.any(np.abs(o["y"]) > bound):
            out.append((float(t[i]), None, failed))
            break
    return out


def explain(args: argparse.Namespace) -> None:
    """Linearise along one recorded flight (scenario inputs, noise off): rho, left-out effectors, margins."""
    scen, failure = SCENARIOS[args.scenario]
    spec, flown = mimo_spec(scen, method=args.method, frame_period=args.frame_period, noise=False,
                            allocator_knows_failure=True, duration=args.duration,
                            failure=failure if args.failed else None, pilot_gain=args.pilot_gain)
    loop = FrameLoop(spec)
    points = flight_points(loop, args.duration, args.every, flown.failure_time if args.failed else None)
    print(f"| {args.scenario} {args.method} T = {args.frame_period * 1e3:g} ms | t (s) | rho | sigma_min(I+L) | "
          "pilot PM (deg) | left out | rate-limited |")
    print("|---|---|---|---|---|---|---|")
    for t, X, failed in points:
        if X is None:
            print(f"| | {t:.2f} | diverged | | | | |")
            continue
        current = FrameLoop(spec, failed=True) if failed else loop
        lin = linearise(current, X)
        mg = margins(lin, n_frequencies=args.frequencies)
        rate = current.part(X, "rate")
        limited = int(np.sum(np.abs(np.abs(rate) - current.P[FloatSlot.RMAX]) < 1e-9))
        left = int(np.sum(np.all(np.abs(lin.J_v) < 1e-9, axis=1)))
        print(f"| | {t:.2f} | {mg.spectral_radius:.4f} | {mg.sigma_min:.3f} | {_fmt(mg.pilot_phase_margin_deg, 1)} | "
              f"{left} | {limited} |", flush=True)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    t = sub.add_parser("table")
    t.add_argument("--csv", default="benchmarks/reference/margins.csv")
    t.add_argument("--scenarios", nargs="+", default=list(SCENARIOS))
    t.add_argument("--frame-periods", nargs="+", type=float, default=list(FRAME_PERIODS))
    t.add_argument("--methods", nargs="+")
    t.add_argument("--cases", nargs="+", default=["nominal", "failed"], choices=["nominal", "failed"])
    t.add_argument("--settle", type=float, default=0.0)
    t.add_argument("--after", type=float, default=1.0, help="failed: seconds after the failure struck the trim")
    t.add_argument("--frequencies", type=int, default=500, help="frequency grid, log-spaced to Nyquist")
    r = sub.add_parser("report")
    r.add_argument("--csv", default="benchmarks/reference/margins.csv")
    r.add_argument("--markdown", action="store_true")
    e = sub.add_parser("explain")
    e.add_argument("--scenario", default="ice", choices=list(SCENARIOS))
    e.add_argument("--method", default="daisy")
    e.add_argument("--frame-period", type=float, default=0.0005)
    e.add_argument("--duration", type=float, default=40.0)
    e.add_argument("--every", type=float, default=2.5)
    e.add_argument("--failed", action="store_true")
    e.add_argument("--pilot-gain", type=float, default=None)
    e.add_argument("--frequencies", type=int, default=100)
    args = parser.parse_args(argv)
    {"table": table, "report": report, "explain": explain}[args.command](args)


if __name__ == "__main__":
    main()
