"""Real-time factor of each plant in the closed loop: ``alloc sim --plant linear|rotorpy|jsbsim:f22``.

Run: ``python -m benchmarks.bench_plants_rtf [--repeat 3] [--duration 10] [--json FILE]``.  Each plant
flies its own nominal loop for ``--duration`` simulated seconds (no failure, seed 0), ``--repeat`` times:

* ``linear``: hexa-x's linear model in the compiled engine, the seed's section 4.3 design and sum of
  sines, 0.5 ms steps, sensor noise on (``alloc sim --vehicle hexa-x``);
* ``rotorpy``: hexa-x on RotorPy, the cascade holding the hover, 4 ms frames;
* ``jsbsim:f22``: the F-22 at M0.7, 20,000 ft, the doublets, 1/120 s frames.

The real-time factor is simulated seconds over the wall seconds of the whole run (``fly_on_plant``,
design and set-up included for ``linear``, whose engine reports no loop-only time; the loop alone for the
others, as their runs time it), the median of the repeats, with the load average before and after.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import time
from pathlib import Path

RUNS = (("linear", "hexa-x"), ("rotorpy", "hexa-x"), ("jsbsim:f22", None))


def one(plant: str, vehicle: str | None, duration: float) -> float:
    from sim.plants import fly_on_plant

    t0 = time.perf_counter()
    r = fly_on_plant(vehicle, plant, method="qp", failure=None, duration=duration, seed=0)
    wall = time.perf_counter() - t0
    if r.diverged:
        raise RuntimeError(f"{plant}: the nominal run diverged")
    return float(r.settings["real_time_factor"]) if "real_time_factor" in r.settings else duration / wall


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--duration", type=float, default=10.0)
    parser.add_argument("--json", type=Path)
    args = parser.parse_args()
    rows = []
    for plant, vehicle in RUNS:
        one(plant, vehicle, 0.5)  # warm: kernels compiled, the JSBSim aircraft copy built
        load = os.getloadavg()[0]
        factors = [one(plant, vehicle, args.duration) for _ in range(args.repeat)]
        rows.append({"plant": plant, "vehicle": vehicle or "f22_jsbsim", "rtf_median": statistics.median(factors),
                     "rtf": factors, "load_before": load, "load_after": os.getloadavg()[0]})
    print("| plant | vehicle | real-time factor (median) | runs | load average (1 min) |")
    print("|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['plant']} | {r['vehicle']} | {r['rtf_median']:.1f} | {', '.join(f'{x:.1f}' for x in r['rtf'])} "
              f"| {r['load_before']:.1f} to {r['load_after']:.1f} |")
    if args.json:
        args.json.write_text(json.dumps({"utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
                                         "duration_s": args.duration, "rows": rows}, indent=1) + "\n")


if __name__ == "__main__":
    main()
