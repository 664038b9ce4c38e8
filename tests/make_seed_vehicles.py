"""Write the seed's aircraft (and three examples) as vehicle files (alloc/data/vehicles/*.toml), once.

    .venv/bin/python tests/make_seed_vehicles.py

Each catalogue entry of :mod:`alloc.vehicles` becomes a file whose ``Problem`` equals
``alloc.vehicles.problem(name)`` bit for bit (floats written with ``repr``), with the
entry's daisy groups as ``[methods.daisy]``, the actuator dynamics of the simulator's seed
tables (``sim/scenarios/ice.py`` Table 4-5, ``sim/scenarios/harv_latdir.py`` Table 4-3) and
the linear models of those scenarios.  Two examples that are not the seed's aircraft:
``tailless`` (3 x 8: ICE's eight surfaces) and ``hexa-x`` (rotor geometry, hover model).
tests/alloc/test_vehicle_file.py checks that the committed files are what this script writes.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from alloc import vehicles  # noqa: E402
from alloc.vehicle_file import DATA_DIR, FORMAT, vehicle_from_dict  # noqa: E402
from alloc.vehicle_file.fields import FORMAT_SIMULATION  # noqa: E402

# ICE: seed Table 4-5 actuator poles (a, b) per effector, as sim/scenarios/ice.py reads them
_ICE_POLES = {
    "elevon_l": (40.0, 100.0), "elevon_r": (40.0, 100.0), "pitch_flap": (40.0, 100.0),
    "amt_l": (40.0, 100.0), "amt_r": (40.0, 100.0), "ssd_l": (40.0, 100.0), "ssd_r": (40.0, 100.0),
    "lef_l": (17.828, 100.0), "lef_r": (17.828, 100.0), "pitch_tv": (37.168, 41.3), "yaw_tv": (37.168, 41.3),
}
_ICE_KIND = {name: ("thrust-vector" if name.endswith("_tv") else "surface") for name in vehicles.ICE_EFFECTORS}
_ICE_AXES = (("alpha", "w/s", "w-dot row of B (seed Eq 4.25: alpha channel)"),
             ("p", "pb/s", "pb-dot row of B (roll channel)"),
             ("beta", "v/s", "v-dot row of B (sideslip channel)"))
# HARV: seed Table 4-3 second-order actuators (wn rad/s, zeta)
_HARV_WN_ZETA = {"diff_tail": (30.0, 0.707), "aileron": (75.0, 0.6), "rudder": (72.0, 0.69),
                 "roll_tv": (20.0, 0.6), "yaw_tv": (20.0, 0.6)}
_HARV_AXES = (("beta", "beta/s", "beta-dot row (seed Eq 4.16)"), ("p", "p/s", "p-dot row"),
              ("r", "r/s", "r-dot row"))


# the seed's model is in degrees (angles deg, rates deg/s, as sim.plots labels them); the speed and
# the accelerations are left without a unit (the scan does not state them)
_ICE_OUTPUT_UNITS = {"alphaw": "deg", "qb": "deg/s", "theta": "deg", "betaw": "deg", "ps": "deg/s", "rs": "deg/s",
                     "phi": "deg"}


def _floats(a: Any) -> list:
    return np.asarray(a, dtype=float).tolist()


def _ice_model() -> dict[str, Any]:
    from sim.scenarios import ice as scenario

    return {"states": list(scenario.STATES), "outputs": list(scenario.OUTPUTS),
            "units": [_ICE_OUTPUT_UNITS.get(o, "") for o in scenario.OUTPUTS], "A": _floats(scenario.A),
            "B": _floats(scenario.B), "C": _floats(scenario.C), "D": _floats(scenario.D),
            "controlled": ["alphaw", "ps", "betaw"]}


def _harv_model() -> dict[str, Any]:
    from sim.scenarios import harv_latdir as scenario

    return {"states": ["beta", "p", "r"], "outputs": list(scenario.OUTPUTS),
            "units": ["deg", "deg/s", "deg/s", "deg/s"], "A": _floats(scenario.A),
            "B": _floats(scenario.B), "C": _floats(scenario.C), "D": _floats(np.zeros((4, 5))),
            "controlled": ["beta", "ps"]}


def _tf(tf: Any) -> dict[str, Any]:
    return {"num": _floats(tf[0]), "den": _floats(tf[1])}


def _failure(f: Any, effectors: tuple[str, ...]) -> dict[str, Any]:
    out: dict[str, Any] = {"time": float(f.time), "description": f.description}
    for name in ("A", "B", "D"):
        if getattr(f, name) is not None:
            out[name] = _floats(getattr(f, name))
    if f.delay is not None:
        out["delay"] = _floats(f.delay) if np.ndim(f.delay) else float(f.delay)
    if f.actuators:
        out["actuators"] = [{"effector": effectors[a.index], "kind": a.kind, **a.params} for a in f.actuators]
    return out


def _simulation(scenario: Any, module: Any, *, commands: list, pilot: dict, failures: dict,
                groups: dict[int, str] | None = None) -> dict[str, Any]:
    """The scenario's loop as a ``[simulation]`` section: its vehicle, designs, failures, pilot."""
    v = scenario.vehicle()
    smc = scenario.smc_design()
    channels = [v.output_names[i] for i in v.controlled]
    hedge = []
    for j, h in enumerate(smc.hedge_terms):
        term = {"out": channels[h.out], "inp": channels[h.inp], "a_f": h.a_f, "a_h": h.a_h, "b_h": h.b_h,
                "gain": h.gain}
        if groups and j in groups:
            term["group"] = groups[j]
        hedge.append(term)
    effectors = tuple(v.effector_names)
    allocation: dict[str, Any] = {"B": _floats(v.B_alloc)}
    if v.Wu is not None:
        allocation["weights"] = _floats(v.Wu)
    allocation["static"] = _floats(v.Bk_seed)
    if not np.array_equal(v.demand_map, np.eye(len(channels))):
        allocation["demand_map"] = _floats(v.demand_map)
    return {
        "scenario": scenario.name, "duration": scenario.default_duration, "method": scenario.default_method,
        "measured": [v.output_names[i] for i in v.measured], "noise": _floats(v.noise_gains),
        "output_bound": _floats(scenario.output_bound), "references": [_tf(r) for r in scenario.references],
        "commands": commands, "allocation": allocation,
        "smc": {"rho": _floats(smc.rho), "eps": _floats(smc.eps), "K0": _floats(smc.K0), "Km1": _floats(smc.Km1),
                "observer_poles": [_floats(r) for r in smc.observer_poles], "hedge": hedge,
                "hedge_gain": _floats(smc.hedge_gain)},
        "loopshape": {"compensators": [_tf(c) for c in scenario.loop_shaped_design().compensators]},
        "pilot": {**pilot, "element": _tf(scenario.pilot_element)},
        "failures": {name: _failure(scenario.failure(name, None), effectors) for name in failures},
    }


def _ice_simulation() -> dict[str, Any]:
    """sim/scenarios/ice.py as data: seed section 4.7 (alpha sum of sines xi = 5; roll pilot xi = 10, pi/4)."""
    from sim.scenarios import ice as module

    return _simulation(
        module.SCENARIO, module, commands=[{"sines": {"xi": 5.0, "phase_step": 0.0}}, {}, {}],
        pilot={"name": "phi", "channel": "ps", "attitude": {"phi": 1.0}, "integrate": False,
               "commands": {"sines": {"sines": {"xi": 10.0, "phase_step": float(np.pi / 4)}}}},
        failures=module.FAILURES)


def _harv_simulation() -> dict[str, Any]:
    """sim/scenarios/harv_latdir.py as data: seed section 4.6 (roll pilot xi = 6; Failure #2's filtered steps)."""
    from sim.scenarios import harv_latdir as module

    row = module.SCENARIO.pilot({}).row
    attitude = {module.OUTPUTS[i]: float(w) for i, w in enumerate(row) if w != 0.0}
    steps = {"times": list(module.STEP_TIMES), "levels": list(module.STEP_LEVELS), "filter": _tf(module.STEP_FILTER)}
    return _simulation(
        module.SCENARIO, module, commands=[{}, {}],
        pilot={"name": "phi", "channel": "ps", "attitude": attitude, "integrate": True,
               "commands": {"sines": {"sines": {"xi": 6.0, "phase_step": 0.0}}, "filtered_steps": {"steps": steps}}},
        failures=module.FAILURES, groups={2: "cross", 3: "cross"})


def document(name: str) -> dict[str, Any]:
    """The vehicle document of catalogue entry ``name``."""
    entry = vehicles.lookup(name)  # title and source: the file's own (the catalogue reads the files)
    make, groups = vehicles.SEED[name]  # the problem and groups: the seed as transcribed in Python
    p = make()
    ice = name.startswith("ice")
    axes_meta = _ICE_AXES if ice else _HARV_AXES
    axes = []
    for i, (axis, unit, description) in enumerate(axes_meta):
        assert p.axes[i] == axis
        a: dict[str, Any] = {"name": axis, "unit": unit, "description": description}
        if not (p.Wv == np.eye(p.k)).all():
            a["weight"] = float(p.Wv[i, i])
        axes.append(a)
    weighted = not (p.Wu == np.eye(p.m)).all()
    default_up = np.minimum(np.maximum(0.0, p.umin), p.umax)
    effectors = []
    for j, eff in enumerate(p.names):
        e: dict[str, Any] = {"name": eff, "kind": _ICE_KIND[eff] if ice else
                             ("thrust-vector" if eff.endswith("_tv") else "surface"),
                             "unit": "deg", "min": float(p.umin[j]), "max": float(p.umax[j])}
        rmax, rmin = float(p.rate_max[j]), float(p.rate_min[j])
        assert rmin == -rmax
        e["rate_max"] = rmax
        if p.up[j] != default_up[j]:
            e["preferred"] = float(p.up[j])
        if weighted:
            e["weight"] = float(p.Wu[j, j])
        if ice:
            e["dynamics"] = {"poles": list(_ICE_POLES[eff])}
        else:
            wn, zeta = _HARV_WN_ZETA[eff]
            e["dynamics"] = {"wn": wn, "zeta": zeta}
        effectors.append(e)
    assert (p.Wu == np.diag(np.diag(p.Wu))).all() and (p.Wv == np.diag(np.diag(p.Wv))).all()
    doc = {
        "format": FORMAT, "name": name, "description": entry.title, "source": entry.source,
        "axes": axes, "effectors": effectors, "effectiveness": {"B": _floats(p.B)},
        "methods": {"daisy": {"groups": [list(g) for g in groups]}},
        "model": _ice_model() if ice else _harv_model(),
    }
    # the seed's own loops: ice.toml flies scenario ice, harv.toml scenario harv_latdir
    simulation = {"ice": _ice_simulation, "harv": _harv_simulation}.get(name)
    if simulation is not None:
        doc["format"] = FORMAT_SIMULATION
        doc["simulation"] = simulation()
    return doc


# --------------------------------------------------------------------------- examples not in the seed
#: the tailless example: ICE's eight aerodynamic surfaces, without the pitch flap and thrust vectoring
TAILLESS_EFFECTORS = ("elevon_l", "elevon_r", "amt_l", "amt_r", "ssd_l", "ssd_r", "lef_l", "lef_r")
_G = 9.81
# the hexacopter example: PX4 6001_hexa_x geometry (m), CT 6.5 N, KM 0.05 m; our mass and inertia
_HEXA_ROTORS = ((0.0, 0.5, -0.05), (0.0, -0.5, 0.05), (0.43, -0.25, -0.05), (-0.43, 0.25, 0.05),
                (0.43, 0.25, 0.05), (-0.43, -0.25, -0.05))
_HEXA_MASS, _HEXA_INERTIA = 2.0, (0.08, 0.08, 0.15)
#: rad/s at full command (6.5 N): assumed, a 10-inch propeller near 8600 rpm; RotorPy's k_eta = 6.5 / 900^2
_HEXA_ROTOR_SPEED_MAX = 900.0


def tailless_document() -> dict[str, Any]:
    """A 3 x 8 tailless aircraft: the ICE airframe flown on its eight surfaces only (seed section 4.7 data)."""
    from sim.scenarios import ice as scenario

    ice = document("ice")
    cols = [vehicles.ICE_EFFECTORS.index(n) for n in TAILLESS_EFFECTORS]
    B = np.asarray(ice["effectiveness"]["B"])[:, cols]
    model = _ice_model()
    model["B"] = _floats(np.asarray(scenario.B)[:, cols])
    model["D"] = _floats(np.asarray(scenario.D)[:, cols])
    return {
        "format": FORMAT, "name": "tailless",
        "description": "Tailless example, 3 axes x 8 surfaces: the ICE airframe without pitch flap and thrust vectoring",
        "source": "seed section 4.7 (ICE B, A, C, D) and Table 4-5 (limits, rates, actuator poles), columns "
                  + ", ".join(TAILLESS_EFFECTORS),
        "axes": ice["axes"], "effectors": [e for e in ice["effectors"] if e["name"] in TAILLESS_EFFECTORS],
        "effectiveness": {"B": _floats(B)},
        "methods": {"daisy": {"groups": [["elevon_l", "elevon_r", "lef_l", "lef_r"], ["amt_l", "amt_r", "ssd_l", "ssd_r"]]}},
        "model": model,
    }


def hexa_document() -> dict[str, Any]:
    """A hexacopter example: rotor geometry, a hover model, yaw as the axis that gives way first."""
    from alloc.vehicle_file import rotor_wrench

    ct = 6.5
    W = np.array([rotor_wrench((x, y, 0.0), (0.0, 0.0, -1.0), ct, km) for x, y, km in _HEXA_ROTORS]).T
    B_axes = W[[0, 1, 2, 5]]  # roll, pitch, yaw, fz
    Ixx, Iyy, Izz = _HEXA_INERTIA
    # hover, small angles, no aerodynamic damping: phi' = p, theta' = q, psi' = r, p' = L / Ixx, ..., w' = Z / m
    A = np.zeros((7, 7))
    A[0, 3] = A[1, 4] = A[2, 5] = 1.0
    Bm = np.zeros((7, 6))
    Bm[3:6] = B_axes[:3] / np.array([[Ixx], [Iyy], [Izz]])
    Bm[6] = B_axes[3] / _HEXA_MASS
    states = ["phi", "theta", "psi", "p", "q", "r", "w"]
    return {
        "format": FORMAT, "name": "hexa-x",
        "description": "Hexacopter example (6 rotors, X): PX4 6001_hexa_x geometry, 2 kg, hover linear model",
        "source": "rotor positions and KM from PX4 ROMFS airframe 6001_hexa_x, CT 6.5 N (PX4 default); mass 2 kg "
                  "and inertia diag(0.08, 0.08, 0.15) kg m^2 are this example's; motor lag 1/30 s, slew 0.1 s; [body]: "
                  "the same mass and inertia (its hover model is this [model] exactly), rotor_speed_max 900 rad/s "
                  "assumed (a 10-inch propeller near 8600 rpm), motor time constant the effectors' 1/30 s",
        "axes": [{"name": "roll", "unit": "N m"}, {"name": "pitch", "unit": "N m"}, {"name": "yaw", "unit": "N m"},
                 {"name": "thrust", "unit": "N", "wrench": "fz", "trim": -_HEXA_MASS * _G,
                  "description": "body z force (down positive): hover at -m g"}],
        "effectors": [{"name": f"motor{i + 1}", "kind": "rotor", "unit": "1", "min": 0.0, "max": 1.0,
                       "rate_max": 10.0, "dynamics": {"bandwidth": 30.0},
                       "rotor": {"position": [x, y, 0.0], "axis": [0.0, 0.0, -1.0], "ct": ct, "km": km}}
                      for i, (x, y, km) in enumerate(_HEXA_ROTORS)],
        "methods": {"cgi": {"priorities": [2, 2, 1, 3]}, "qp": {"priorities": [2, 2, 1, 3]},
                    "lp": {"priorities": [2, 2, 1, 3]}},
        "body": {"mass": _HEXA_MASS, "inertia": list(_HEXA_INERTIA), "rotor_speed_max": _HEXA_ROTOR_SPEED_MAX},
        "model": {"states": states, "outputs": states,
                  "units": ["rad", "rad", "rad", "rad/s", "rad/s", "rad/s", "m/s"], "A": _floats(A), "B": _floats(Bm), "C": _floats(np.eye(7)),
                  "D": _floats(np.zeros((7, 6))), "controlled": ["p", "q", "r", "w"]},
    }

#: X-57-like high-lift propeller stations (m, each side), chosen: evenly spaced from 0.9 m to
#: 4.15 m; the public sources give the count (12) and the leading-edge placement, not stations
_X57_STATIONS = (0.9, 1.55, 2.2, 2.85, 3.5, 4.15)
#: kg (about 3,000 lb: NASA's fact sheet) and kg m^2 (Ixx, Iyy, Izz: chosen for a light twin)
_X57_MASS, _X57_INERTIA = 1361.0, (1400.0, 1800.0, 3000.0)
#: N: level-flight thrust = drag at a chosen lift-to-drag ratio of 10 (1,361 kg x 9.81 / 10)
_X57_TRIM_THRUST = 1335.0
#: surfaces (rad): N m per rad at q = 980 Pa (40 m/s, sea level), S = 6.2 m^2, b = 9.6 m, mean
#: chord 0.65 m, all chosen: aileron dCl/d(delta) 0.08 each (980 6.2 9.6 0.08 = 4,667 N m) with
#: 5 % adverse yaw; stabilator dCm/d(delta) -1.5 (-5,924 N m); rudder dCn/d(delta) -0.06
#: (-3,500 N m) with 10 % roll
_X57_SURFACES = (("aileron_l", [-4667.0, 0.0, 233.0, 0.0], 0.35), ("aileron_r", [4667.0, 0.0, -233.0, 0.0], 0.35),
                 ("stabilator", [0.0, -5924.0, 0.0, 0.0], 0.26), ("rudder", [-350.0, 0.0, -3500.0, 0.0], 0.44))


def x57_document() -> dict[str, Any]:
    """A distributed-propulsion example after NASA's X-57 Maxwell (Mod IV layout): 18 effectors
    on roll, pitch, yaw and forward thrust (the source line says which numbers are sourced)."""
    rotors = []
    for side, sgn in (("l", -1.0), ("r", 1.0)):  # 0.6 m ahead of and 0.15 m below the CG (chosen)
        rotors += [{"name": f"hl{n + 1}_{side}", "kind": "rotor", "unit": "1", "min": 0.0, "max": 1.0, "rate_max": 8.0,
                    "dynamics": {"bandwidth": 25.0},
                    "rotor": {"position": [0.6, sgn * y, 0.15], "axis": [1.0, 0.0, 0.0], "ct": 250.0, "km": 0.05 * sgn}}
                   for n, y in enumerate(_X57_STATIONS)]
    rotors += [{"name": f"cruise_{side}", "kind": "rotor", "unit": "1", "min": 0.0, "max": 1.0, "rate_max": 4.0,
                "dynamics": {"bandwidth": 15.0},
                "rotor": {"position": [0.3, sgn * 4.8, 0.0], "axis": [1.0, 0.0, 0.0], "ct": 1500.0, "km": 0.08 * sgn}}
               for side, sgn in (("l", -1.0), ("r", 1.0))]
    surfaces = [{"name": name, "kind": "surface", "unit": "rad", "min": -lim, "max": lim, "rate_max": 1.5,
                 "dynamics": {"bandwidth": 20.0}, "effectiveness": col} for name, col, lim in _X57_SURFACES]
    props = [e["name"] for e in rotors]
    # rigid body, small angles, no aerodynamic damping (as hexa-x): phi' = p, ..., p' = L / Ixx, ...,
    # u' = X / mass; mass 1,361 kg (about 3,000 lb, sourced); inertias chosen for a light twin
    from alloc.vehicle_file import rotor_wrench

    W = np.array([rotor_wrench(e["rotor"]["position"], e["rotor"]["axis"], e["rotor"]["ct"], e["rotor"]["km"])
                  for e in rotors]).T
    B_axes = np.hstack([W[[0, 1, 2, 3]], np.array([e["effectiveness"] for e in surfaces]).T])
    A = np.zeros((7, 7))
    A[0, 3] = A[1, 4] = A[2, 5] = 1.0
    Bm = np.zeros((7, B_axes.shape[1]))
    Bm[3:6] = B_axes[:3] / np.array([[_X57_INERTIA[0]], [_X57_INERTIA[1]], [_X57_INERTIA[2]]])
    Bm[6] = B_axes[3] / _X57_MASS
    states = ["phi", "theta", "psi", "p", "q", "r", "u"]
    return {
        "format": FORMAT, "name": "x57-dep",
        "description": "Distributed electric propulsion example after NASA's X-57 Maxwell (Mod IV layout): 12 "
                       "high-lift and 2 wingtip cruise propellers, ailerons, stabilator and rudder; 4 axes x 18 "
                       "effectors",
        "source": "layout (12 high-lift propellers on the wing leading edge, 2 cruise propellers of 5 ft diameter at "
                  "the wingtips, 10.5 kW per high-lift motor, about 3,000 lb): NASA's X-57 Mod IV release of "
                  "2020-03-27 (reprinted by greencarcongress.com and aerotechnews.com, 2020-04-03) and NASA's X-57 "
                  "fact sheet as quoted by avionicsea.com (2023-06-27). Chosen here, not sourced: span 9.6 m (the "
                  "often-quoted 31.6 ft, unchecked against a primary source), propeller stations, static thrusts "
                  "(momentum theory, figure of merit 0.7: 250 N per high-lift, 1,500 N per cruise propeller at an "
                  "assumed 60 kW), torque ratios km, the surfaces' moment derivatives (q = 980 Pa, S = 6.2 m^2), "
                  "limits, rates, actuator bandwidths, the inertias diag(1400, 1800, 3000) kg m^2 of the rigid-body "
                  "model (mass 1,361 kg: 3,000 lb) and its lack of aerodynamic damping, the thrust trim 1,335 N (L/D 10). An allocation example, not a "
                  "model of the aircraft.",
        "axes": [{"name": "roll", "unit": "N m"}, {"name": "pitch", "unit": "N m"}, {"name": "yaw", "unit": "N m"},
                 {"name": "thrust", "unit": "N", "wrench": "fx", "trim": _X57_TRIM_THRUST,
                  "description": "body x force (forward positive): trimmed at the drag of level flight"}],
        "effectors": rotors + surfaces,
        "methods": {"daisy": {"groups": [[e["name"] for e in surfaces], props]}},
        "model": {"states": states, "outputs": states,
                  "units": ["rad", "rad", "rad", "rad/s", "rad/s", "rad/s", "m/s"], "A": _floats(A), "B": _floats(Bm),
                  "C": _floats(np.eye(7)), "D": _floats(np.zeros((7, B_axes.shape[1]))),
                  "controlled": ["p", "q", "r", "u"]},
    }


#: the bundled examples that are not the seed's: file name -> document
EXAMPLES = {"tailless": tailless_document, "hexa-x": hexa_document, "x57-dep": x57_document}


def main() -> None:
    DATA_DIR.mkdir(parents=True, exist_ok=True)
    docs = {name: (lambda n=name: document(n)) for name in vehicles.SEED} | EXAMPLES
    for name, make in docs.items():
        path = vehicle_from_dict(make()).save(DATA_DIR / f"{name}.toml")
        print(path.relative_to(ROOT))


if __name__ == "__main__":
    main()
