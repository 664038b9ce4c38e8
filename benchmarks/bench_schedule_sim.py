"""The schedule in the simulator: hexa-x with its rotors tilting forward, the allocator following B(x) or not.

Run: ``python -m benchmarks.bench_schedule_sim --out benchmarks/reference/plants-2026-12-06`` (about two
minutes).  The vehicle is hexa-x with every rotor tilting forward together
(``tests/sim/schedule_files.py``: ``B(t) = B + (cos t - 1) B_up + sin t B_forward``, t in deg, written
beside the results as ``hexa-tilt.toml``).  Each run is ``alloc sim --vehicle hexa-tilt.toml --schedule
tilt=0:END`` (:func:`sim.plants.scheduled.fly_scheduled`): the tilt moves linearly from 0 to END over
20 s, ``qp`` with hexa-x's priorities, the seed's section 4.3 design at the nominal point and its sum of
sines, 250 Hz frames, no sensor noise, seed 0; no failure, or ``float:motor1`` told at 10 s.  The
allocator is rebuilt on ``B(x)`` every frame (``follow``) or kept at the nominal ``B`` (``frozen``).

Columns: the tracking error RMS and peak of each channel over the run (p, q, r rad/s, w m/s; after the
failure when there is one), the largest unallocated demand's norm, and the real-time factor.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).parents[1]
ENDS = (45.0, 60.0)
FAILURES = (None, "float:motor1")


def main() -> None:
    sys.path.insert(0, str(ROOT / "tests" / "sim"))
    from schedule_files import tilting_hexa_document

    from alloc.vehicle_file import vehicle_from_dict
    from alloc.vehicle_file.toml_writer import to_toml
    from sim.plants.scheduled import fly_scheduled

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args()
    doc = tilting_hexa_document()
    (args.out / "hexa-tilt.toml").write_text(to_toml(doc))
    fv = vehicle_from_dict(doc)
    machine = {"utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()), "load_average": list(os.getloadavg()),
               "cpus": os.cpu_count()}
    rows = []
    for end in ENDS:
        for failure in FAILURES:
            for mode in ("follow", "frozen"):
                r = fly_scheduled(fv, [f"tilt=0:{end:g}"], method="qp", duration=20.0, failure=failure,
                                  failure_time=10.0, health="told", allocator=mode, seed=0)
                s = r.summary()
                phase = "rms_after" if failure else "rms_before"
                peak = "max_after" if failure else "max_before"
                rows.append({"tilt_end_deg": end, "failure": failure or "none", "allocator": mode,
                             "diverged": bool(r.diverged), "t_end_s": float(r.t[-1]),
                             "rms": {c: v[phase] for c, v in s["channels"].items()},
                             "peak": {c: v[peak] for c, v in s["channels"].items()},
                             "unallocated_max": float(np.max(np.linalg.norm(r.unallocated, axis=1))),
                             "rtf": r.settings["real_time_factor"]})
                print(json.dumps(rows[-1]), flush=True)
    machine["load_average_after"] = list(os.getloadavg())
    (args.out / "schedule-sim.json").write_text(json.dumps({"machine": machine, "rows": rows}, indent=1) + "\n")
    lines = ["| tilt 0 to | failure (told) | allocator | diverged | p RMS | q RMS | r RMS | w RMS | w peak "
             "| max unallocated | real-time factor |", "|---|---|---|---|---|---|---|---|---|---|---|"]
    for x in rows:
        div = f"at {x['t_end_s']:.2f} s" if x["diverged"] else "no"
        lines.append(f"| {x['tilt_end_deg']:g} deg | {x['failure']} | {x['allocator']} | {div} | "
                     + " | ".join(f"{x['rms'][c]:.4f}" for c in ("p", "q", "r", "w"))
                     + f" | {x['peak']['w']:.3f} | {x['unallocated_max']:.3g} | {x['rtf']:.2f} |")
    (args.out / "schedule-sim.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
