"""JSBSim F-22 in cruise: a stabilator half jammed at trim and the nozzle stuck, five allocations, the criteria.

Run: ``python -m benchmarks.bench_f22_failures --out benchmarks/reference/plants-2026-12-06`` (about a
minute).  Every row is one ``alloc sim --plant jsbsim:f22`` run (:func:`sim.plants.fly_on_plant`): M0.7 at
20,000 ft, the section 4.3 SMC on the aircraft's linearisation, the doublets of
:func:`sim.plants.jsbsim_loop.doublets` (pitch rate 2 deg/s at 2 s and 10 s, roll rate 10 deg/s at 6 s,
yaw rate 2 deg/s at 14 s), 20 s, the failure at 5 s.  Failures: ``jam:stab_l@0`` (the left stabilator half
held at its trim) and ``jam:tvc`` (the nozzle held where it is at 5 s).

Allocations: ``qp`` told, detected (the engine's detector and do-no-harm monitor on the plant's sensed
response, designed on the linear model) and blind; ``px4``, the library's port of PX4's mixer (a
pseudo-inverse, then sequential desaturation), told and blind; ``ganging``, the seed's static design (Eq 1.23
frozen at design time, section 1.3.4.1), blind (a fixed matrix is told nothing) and told (its commands
clipped to the failed limits).

The criteria are :mod:`sim.criteria`'s, the seed scenarios' fractions applied to this loop's demands
(:func:`sim.criteria.demand_criteria`): per channel q, p, r, the error RMS within 0.25 (nominal) and 0.5
(after the failure) of the demand's RMS and the peak within 0.5 and 1.0 of its peak, recovery into the
nominal band within 5 s, no effector on a stop for more than half a phase (the failed effector left out).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import time
from pathlib import Path
from typing import Any

import numpy as np

FAILURES = ("jam:stab_l@0", "jam:tvc")
FAILURE_TIME, DURATION, SEED = 5.0, 20.0, 0
ALLOCATIONS = (("qp", "told"), ("qp", "detected"), ("qp", "blind"), ("px4", "told"), ("px4", "blind"),
               ("ganging", "blind"), ("ganging", "told"))
#: the signals judged by the criteria, with the commands they follow
CHANNELS = ("q", "p", "r")


def criteria() -> Any:
    """The F-22 loop's table (module docstring), from the doublets over the run."""
    from sim.criteria import demand_criteria
    from sim.plants.jsbsim_linear import CONTROLLED
    from sim.plants.jsbsim_loop import doublets

    t = np.arange(0.0, DURATION, 0.01)
    d = doublets(t)
    return demand_criteria("f22_jsbsim", {c: (d[:, CONTROLLED.index(c)], f"the {c} doublets (deg/s)")
                                          for c in CHANNELS})


def row(failure: str | None, method: str, health: str, table: Any) -> tuple[dict[str, Any], Any]:
    from sim.criteria import evaluate
    from sim.plants import fly_on_plant
    from sim.plants.jsbsim import JSBSimPlant

    r = fly_on_plant(None, "jsbsim:f22", method=method, failure=failure, failure_time=FAILURE_TIME, health=health,
                     duration=DURATION, seed=SEED)
    failed = () if failure is None else (JSBSimPlant.effectors.index(failure.split(":")[1].split("@")[0]),)
    verdict = evaluate(r, table, failed=failed)
    e, t = r.extra, r.t
    after = t >= FAILURE_TIME if failure else np.ones(t.shape, dtype=bool)
    i = r.channels.index("q")
    q_err = r.reference[after, i] - r.output[after, i]
    executed = r.settings["plant"]["failures"]
    out = {
        "failure": failure or "none", "method": method, "health": health, "diverged": bool(r.diverged),
        "t_end_s": float(t[-1]),
        "q_rms_after": float(np.sqrt(np.mean(q_err ** 2))), "q_max_after": float(np.max(np.abs(q_err))),
        "alpha_peak_deg": float(np.max(np.abs(e["alpha"]))), "vt_peak_mps": float(np.max(np.abs(e["vt"]))),
        "pass": verdict.passed, "broken": list(verdict.broken),
        "executed": executed,
        "detections_applied": sum(1 for d in (r.detections or []) if d["applied"]),
        "detections": [{k: d.get(k) for k in ("effector", "kind", "time", "applied")} for d in (r.detections or [])],
        "withdrawals": len(r.withdrawals or []),
        "rtf": r.settings["real_time_factor"],
    }
    return out, r


def machine() -> dict[str, Any]:
    commit = subprocess.run(["git", "rev-parse", "HEAD"], capture_output=True, text=True, check=False).stdout.strip()
    import jsbsim

    return {"utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()), "load_average": list(os.getloadavg()),
            "cpus": os.cpu_count(), "python": platform.python_version(), "numpy": np.__version__,
            "jsbsim": getattr(jsbsim, "__version__", "?"), "commit": commit}


def markdown(rows: list[dict[str, Any]]) -> str:
    lines = [("| failure at 5 s | allocation | diverged | RMS q error after deg/s | max q error after deg/s "
             "| peak alpha deg | criteria | broken | detections applied, withdrawals | real-time factor |"),
             "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        div = f"at {r['t_end_s']:.2f} s" if r["diverged"] else "no"
        broken = ", ".join(r["broken"][:4]) + (" ..." if len(r["broken"]) > 4 else "")
        det = f"{r['detections_applied']}, {r['withdrawals']}" if r["health"] == "detected" else ""
        lines.append(f"| {r['failure']} | {r['method']} {r['health']} | {div} | {r['q_rms_after']:.3f} "
                     f"| {r['q_max_after']:.2f} | {r['alpha_peak_deg']:.2f} | {'pass' if r['pass'] else 'fail'} "
                     f"| {broken} | {det} | {r['rtf']:.0f} |")
    return "\n".join(lines)


def plot(results: dict[tuple[str, str, str], Any], path: Path) -> None:
    """q command, reference and output per failure, one line per allocation."""
    from matplotlib.figure import Figure  # a bare figure renders headless; no backend chosen

    fig = Figure(figsize=(10, 3.6 * len(FAILURES)))
    axes = fig.subplots(len(FAILURES), 1, sharex=True, squeeze=False)
    for k, failure in enumerate(FAILURES):
        ax = axes[k, 0]
        for (f, method, health), r in results.items():
            if f != failure:
                continue
            i = r.channels.index("q")
            ax.plot(r.t, r.output[:, i], lw=0.8, label=f"{method} {health}")
        ref = next(r for (f, *_), r in results.items() if f == failure)
        ax.plot(ref.t, ref.reference[:, ref.channels.index("q")], "k--", lw=0.8, label="reference")
        ax.axvline(FAILURE_TIME, color="grey", lw=0.5)
        ax.set_ylim(-6, 6)
        ax.set_ylabel("pitch rate q (deg/s from trim)")
        ax.set_title(f"JSBSim F-22, M0.7 at 20,000 ft: {failure} at {FAILURE_TIME:g} s")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, ncol=4)
    axes[-1, 0].set_xlabel("time (s)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    table = criteria()
    state = {"before": machine()}
    rows, results = [], {}
    out, _ = row(None, "qp", "told", table)
    rows.append(out)
    for failure in FAILURES:
        for method, health in ALLOCATIONS:
            out, r = row(failure, method, health, table)
            rows.append(out)
            results[(failure, method, health)] = r
            print(markdown(rows[-1:]).splitlines()[-1], flush=True)
    state["after"] = machine()
    doc = {"settings": {"plant": "jsbsim:f22", "failure_time_s": FAILURE_TIME, "duration_s": DURATION, "seed": SEED,
                        "commands": "sim.plants.jsbsim_loop.doublets"},
           "criteria": {"limits": table.limits(), "sources": table.sources()}, "machine": state, "rows": rows}
    (args.out / "f22-failures.json").write_text(json.dumps(doc, indent=1) + "\n")
    (args.out / "f22-failures.md").write_text(markdown(rows) + "\n")
    plot(results, args.out / "f22-failures.png")
    print(markdown(rows))


if __name__ == "__main__":
    main()
