"""RotorPy plant: hover with a rotor loss, told against blind, still air and turbulence; real-time factor.

Run: ``python -m benchmarks.bench_rotorpy [--duration 20] [--vehicle hexa-x]``.  Every row is one
:func:`sim.plants.fly_on_plant` run (qp, the vehicle's priorities, ``float:motor1`` at 10 s, seed 0):
roll and pitch RMS after the failure (deg; a diverged run: up to its end), the lowest altitude below the hover (m), the heading
change at the end (deg, yaw is given up), the horizontal drift at the end (m, no position loop), and
the real-time factor (simulated / wall seconds of the loop, RotorPy's share in brackets).
Also the plant alone: 2 s of RotorPy at its step with the trim command (no controller, no allocator).
"""

from __future__ import annotations

import argparse
import time

import numpy as np


def hover_row(vehicle: str, health: str, turbulence: str, duration: float, failure: str | None) -> dict[str, float]:
    from sim.plants import fly_on_plant

    r = fly_on_plant(vehicle, "rotorpy", method="qp", failure=failure, health=health, duration=duration,
                     turbulence=turbulence)
    e, t = r.extra, r.t
    after = t >= (10.0 if failure else 0.0)
    timing = r.settings["timing"]
    return {
        "diverged": r.diverged,
        "phi_rms": float(np.degrees(np.sqrt(np.mean(e["phi"][after] ** 2)))),
        "theta_rms": float(np.degrees(np.sqrt(np.mean(e["theta"][after] ** 2)))),
        "phi_max": float(np.degrees(np.max(np.abs(e["phi"][after])))),
        "altitude_loss": float(-np.min(e["altitude_m"])),
        "heading": float(np.degrees(e["psi"][-1])),
        "drift": float(np.hypot(e["north_m"][-1], e["east_m"][-1])),
        "rtf": timing["simulated_s"] / timing["wall_s"],
        "rtf_plant": timing["simulated_s"] / timing["plant_s"],
        "wind_std": r.settings.get("world", {}).get("std"),
        "t_end": float(t[-1]),
        "detections": sum(1 for d in (r.detections or []) if d["applied"]),
        "withdrawals": len(r.withdrawals or []),
    }


def plant_alone(vehicle: str, seconds: float = 2.0) -> float:
    from alloc import vehicles
    from sim.plants import ROTORPY_FRAME, rotorpy_plant
    from sim.user_vehicle import flight_model

    fm = flight_model(vehicles.get_vehicle(vehicle))
    plant = rotorpy_plant(fm, dt_step=ROTORPY_FRAME)
    plant.reset(seed=0)
    u = np.zeros(len(plant.effectors))
    n = int(round(seconds / ROTORPY_FRAME))
    t0 = time.perf_counter()
    for _ in range(n):
        plant.step(u, ROTORPY_FRAME)
    return seconds / (time.perf_counter() - t0)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=20.0)
    parser.add_argument("--vehicle", default="hexa-x")
    parser.add_argument("--turbulence", nargs="+", default=["none", "moderate"])
    args = parser.parse_args()
    print(f"RotorPy alone ({args.vehicle}, trim command): real-time factor {plant_alone(args.vehicle):.2f}")
    print("| health | turbulence | diverged | roll RMS deg | pitch RMS deg | max abs roll deg | altitude loss m "
          "| heading end deg | drift m | real-time factor (plant) |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    notes = []
    for turbulence in args.turbulence:
        for health in ("told", "blind", "detected"):
            row = hover_row(args.vehicle, health, turbulence, args.duration, "float:motor1")
            if health == "detected":
                notes.append(f"detected, {turbulence}: {row['detections']} beliefs applied, {row['withdrawals']} "
                             f"withdrawn; run ended at {row['t_end']:.2f} s")
            diverged = f"at {row['t_end']:.2f} s" if row["diverged"] else "no"
            print(f"| {health} | {turbulence} | {diverged} | {row['phi_rms']:.2f} | {row['theta_rms']:.2f} | "
                  f"{row['phi_max']:.1f} | {row['altitude_loss']:.2f} | {row['heading']:.1f} | {row['drift']:.1f} | "
                  f"{row['rtf']:.2f} ({row['rtf_plant']:.2f}) |")
            if row["wind_std"] is not None and health == "told":
                notes.append(f"wind std north/east/down m/s, {turbulence}: {', '.join(f'{s:.2f}' for s in row['wind_std'])}")
    for note in notes:
        print(note)


if __name__ == "__main__":
    main()
