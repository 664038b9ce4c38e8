"""RotorPy: one rotor lost in hover and at 5 m/s, light and moderate wind, qp told/detected against PX4's mixer.

Run: ``python -m benchmarks.bench_rotor_loss --out benchmarks/reference/plants-2026-12-06`` (about 10
minutes on 2 shared cores).  Every row is one :func:`sim.plants.fly_on_plant` run on ``--plant rotorpy``
with the cascade's velocity loop (:class:`sim.plant_control.VelocityHold`): ground speed 0 (hover) or
5 m/s due north reached on a 1 m/s^2 ramp, ``float:motor1`` at 10 s, 20 s, seed 0.  The vehicles are
hexa-x (bundled) and ``octa-x``, ArduPilot's Octa X layout (``FRAME_CLASS`` 3, ``FRAME_TYPE`` 1:
:data:`alloc.importers.ardupilot_frames.TABLES`) with the rotors and ``[body]`` of the plant tests'
octocopter (:func:`octa_document`; the file is written beside the results).

The allocations: ``qp`` with the vehicle's priorities (thrust, then roll and pitch, then yaw), told of
the loss or detecting it (``--health detected``), and PX4's multirotor mixer (``px4``: pseudo-inverse,
then sequential desaturation, airmode off) told (PX4's ``CA_FAILURE_MODE`` 1 removes a motor its
failure detector reports) and blind (``CA_FAILURE_MODE`` 0, PX4's default).

Columns (after the failure, t >= 10 s; a diverged run: up to its end): roll and pitch RMS and the
largest roll error (deg, the attitude minus the velocity loop's set-point), the altitude loss (m:
the altitude at the failure minus the lowest after it), the heading at the end and the largest yaw
rate (deg, deg/s: yaw given up), the RMS ground-speed error (m/s) and the real-time factor of the loop
(simulated over wall seconds; RotorPy's own in brackets).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import subprocess
import time
from pathlib import Path
from typing import Any

import numpy as np

#: the run matrix's free choices (all stated in the module docstring)
FAILURE, FAILURE_TIME, DURATION, SEED = "float:motor1", 10.0, 20.0, 0
SPEEDS = (0.0, 5.0)
TURBULENCE = ("light", "moderate")
ALLOCATIONS = (("qp", "told"), ("qp", "detected"), ("px4", "told"), ("px4", "blind"))
#: octa-x: ArduPilot's Octa X angles and spins on a 0.6 m radius; the plant tests' octocopter's numbers
OCTA_RADIUS, OCTA_MASS, OCTA_CT, OCTA_KM, GRAVITY = 0.6, 3.0, 6.5, 0.05, 9.81


def octa_document() -> dict[str, Any]:
    """ArduPilot's Octa X (motor ``k`` = ``AP_MOTORS_MOT_k``) as a vehicle document with a ``[body]``.

    A motor at ArduPilot angle ``a`` (deg, clockwise from the nose seen from above) sits at
    ``r (cos a, sin a, 0)`` in body FRD; a CW rotor (yaw factor -1) has ``km = -0.05`` m, as hexa-x's
    motor1 (ArduPilot's Hexa X motor 1, 90 deg, CW) has.
    """
    from alloc.importers.ardupilot_frames import TABLES

    effectors = []
    for k, motor in enumerate(TABLES[(3, 1)]):
        a = math.radians(motor.roll)
        effectors.append({
            "name": f"motor{k + 1}", "kind": "rotor", "unit": "1", "min": 0.0, "max": 1.0, "rate_max": 10.0,
            "dynamics": {"bandwidth": 30.0},
            "rotor": {"position": [round(OCTA_RADIUS * math.cos(a), 12), round(OCTA_RADIUS * math.sin(a), 12), 0.0],
                      "axis": [0.0, 0.0, -1.0], "ct": OCTA_CT, "km": OCTA_KM * motor.yaw}})
    return {
        "format": "alloc-vehicle/1", "name": "octa-x",
        "description": "ArduPilot Octa X (FRAME_CLASS 3, FRAME_TYPE 1) on a 0.6 m radius, 3 kg, 6.5 N rotors",
        "source": "benchmarks/bench_rotor_loss.py octa_document (angles and spins: ArduPilot setup_octa_matrix)",
        "axes": [{"name": "roll", "unit": "N m"}, {"name": "pitch", "unit": "N m"}, {"name": "yaw", "unit": "N m"},
                 {"name": "thrust", "unit": "N", "wrench": "fz", "trim": -OCTA_MASS * GRAVITY}],
        "effectors": effectors,
        "methods": {"qp": {"priorities": [2, 2, 1, 3]}},
        "body": {"mass": OCTA_MASS, "inertia": [0.12, 0.12, 0.22], "rotor_speed_max": 900.0},
    }


def row(vehicle: Any, speed: float, turbulence: str, method: str, health: str) -> tuple[dict[str, Any], Any]:
    """One run's numbers (module docstring) and its result."""
    from sim.plants import fly_on_plant

    r = fly_on_plant(vehicle, "rotorpy", method=method, failure=FAILURE, failure_time=FAILURE_TIME, health=health,
                     duration=DURATION, turbulence=turbulence, seed=SEED, forward_speed=speed)
    e, t = r.extra, r.t
    after = t >= FAILURE_TIME
    deg = np.degrees
    roll_err = e["phi"][after] - e["phi_setpoint"][after]
    pitch_err = e["theta"][after] - e["theta_setpoint"][after]
    at_failure = float(np.interp(FAILURE_TIME, t, e["altitude_m"]))
    speed_err = np.hypot(e["v_north_mps"][after] - e["v_north_ref"][after], e["v_east_mps"][after])
    timing = r.settings["timing"]
    out = {
        "speed_mps": speed, "turbulence": turbulence, "method": method, "health": health,
        "diverged": bool(r.diverged), "t_end_s": float(t[-1]),
        "roll_rms_deg": float(deg(np.sqrt(np.mean(roll_err ** 2)))),
        "pitch_rms_deg": float(deg(np.sqrt(np.mean(pitch_err ** 2)))),
        "roll_err_max_deg": float(deg(np.max(np.abs(roll_err)))),
        "altitude_loss_m": float(at_failure - np.min(e["altitude_m"][after])),
        "heading_end_deg": float(deg(e["psi"][-1])),
        "yaw_rate_max_deg_s": float(deg(np.max(np.abs(e["r"][after])))),
        "speed_err_rms_mps": float(np.sqrt(np.mean(speed_err ** 2))),
        "rtf": timing["simulated_s"] / timing["wall_s"], "rtf_plant": timing["simulated_s"] / timing["plant_s"],
        "wind_std_mps": r.settings.get("world", {}).get("std"),
        "detections_applied": sum(1 for d in (r.detections or []) if d["applied"]),
        "withdrawals": len(r.withdrawals or []),
    }
    return out, r


def machine() -> dict[str, Any]:
    """The machine state the numbers were measured in."""
    commit = subprocess.run(["git", "rev-parse", "HEAD"], capture_output=True, text=True, check=False).stdout.strip()
    import rotorpy

    return {"utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()), "load_average": list(os.getloadavg()),
            "cpus": os.cpu_count(), "python": platform.python_version(), "numpy": np.__version__,
            "rotorpy": getattr(rotorpy, "__version__", "3.0.0"), "commit": commit}


def table(rows: list[dict[str, Any]]) -> str:
    lines = [("| vehicle | speed m/s | wind | allocation | diverged | roll RMS deg | pitch RMS deg | max roll err deg "
             "| altitude loss m | heading end deg | max yaw rate deg/s | speed err RMS m/s | real-time factor (plant) |"),
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        div = f"at {r['t_end_s']:.2f} s" if r["diverged"] else "no"
        lines.append(f"| {r['vehicle']} | {r['speed_mps']:g} | {r['turbulence']} | {r['method']} {r['health']} | {div} "
                     f"| {r['roll_rms_deg']:.2f} | {r['pitch_rms_deg']:.2f} | {r['roll_err_max_deg']:.1f} "
                     f"| {r['altitude_loss_m']:.2f} | {r['heading_end_deg']:.0f} | {r['yaw_rate_max_deg_s']:.0f} "
                     f"| {r['speed_err_rms_mps']:.2f} | {r['rtf']:.2f} ({r['rtf_plant']:.2f}) |")
    return "\n".join(lines)


def plot(results: dict[str, Any], path: Path) -> None:
    """Roll error, altitude and heading of the 5 m/s moderate-wind runs, one column per vehicle."""
    from matplotlib.figure import Figure  # a bare figure renders headless; no backend chosen

    vehicles = sorted({k[0] for k in results})
    fig = Figure(figsize=(6 * len(vehicles), 8))
    axes = fig.subplots(3, len(vehicles), sharex=True, squeeze=False)
    for j, name in enumerate(vehicles):
        for (veh, speed, turb, method, health), r in results.items():
            if veh != name or speed != 5.0 or turb != "moderate":
                continue
            label = f"{method} {health}"
            e = r.extra
            axes[0, j].plot(r.t, np.degrees(e["phi"] - e["phi_setpoint"]), label=label, lw=0.8)
            axes[1, j].plot(r.t, e["altitude_m"], label=label, lw=0.8)
            axes[2, j].plot(r.t, np.degrees(e["psi"]), label=label, lw=0.8)
        axes[0, j].set_title(f"{name}: motor1 lost at {FAILURE_TIME:g} s, 5 m/s north, moderate wind")
        axes[0, j].set_ylabel("roll error (deg)")
        axes[1, j].set_ylabel("altitude (m)")
        axes[2, j].set_ylabel("heading (deg)")
        axes[2, j].set_xlabel("time (s)")
        axes[0, j].legend(fontsize=7)
        for ax in axes[:, j]:
            ax.axvline(FAILURE_TIME, color="grey", lw=0.5)
            ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main() -> None:
    from alloc.vehicle_file import vehicle_from_dict
    from alloc.vehicle_file.toml_writer import to_toml

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True, help="folder for rotor-loss.json, .md, .png, octa-x.toml")
    parser.add_argument("--vehicle", nargs="+", default=["hexa-x", "octa-x"])
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    octa = args.out / "octa-x.toml"
    octa.write_text(to_toml(octa_document()))
    sources = {"hexa-x": "hexa-x", "octa-x": vehicle_from_dict(octa_document())}
    state = {"before": machine()}
    rows, results = [], {}
    for name in args.vehicle:
        for speed in SPEEDS:
            for turbulence in TURBULENCE:
                for method, health in ALLOCATIONS:
                    out, r = row(sources[name], speed, turbulence, method, health)
                    rows.append({"vehicle": name, **out})
                    results[(name, speed, turbulence, method, health)] = r
                    print(table(rows[-1:]).splitlines()[-1], flush=True)
    state["after"] = machine()
    settings = {"failure": FAILURE, "failure_time_s": FAILURE_TIME, "duration_s": DURATION, "seed": SEED,
                "frame_s": 0.004, "velocity_loop": "sim.plant_control.VelocityHold defaults (ramp 1 m/s^2, "
                "P 1.8 /s, I 0.4 /s^2, tilt 35 deg)", "cascade": "sim.plant_control.CascadeGains.for_motor_lag"}
    (args.out / "rotor-loss.json").write_text(json.dumps({"settings": settings, "machine": state, "rows": rows},
                                                         indent=1) + "\n")
    (args.out / "rotor-loss.md").write_text(table(rows) + "\n")
    plot(results, args.out / "rotor-loss.png")
    print(table(rows))


if __name__ == "__main__":
    main()
