"""Write the seed's aircraft as vehicle files (alloc/data/vehicles/*.toml), once.

    .venv/bin/python tests/make_seed_vehicles.py

Each catalogue entry of :mod:`alloc.vehicles` becomes a file whose ``Problem`` equals
``alloc.vehicles.problem(name)`` bit for bit (floats written with ``repr``), with the
entry's daisy groups as ``[methods.daisy]``, the actuator dynamics of the simulator's seed
tables (``sim/scenarios/ice.py`` Table 4-5, ``sim/scenarios/harv_latdir.py`` Table 4-3) and
the linear models of those scenarios.  tests/test_vehicle_file.py checks that the committed
files are what this script writes.
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


def _floats(a: Any) -> list:
    return np.asarray(a, dtype=float).tolist()


def _ice_model() -> dict[str, Any]:
    from sim.scenarios import ice as scenario

    return {"states": list(scenario.STATES), "outputs": list(scenario.OUTPUTS), "A": _floats(scenario.A),
            "B": _floats(scenario.B), "C": _floats(scenario.C), "D": _floats(scenario.D),
            "controlled": ["alphaw", "ps", "betaw"]}


def _harv_model() -> dict[str, Any]:
    from sim.scenarios import harv_latdir as scenario

    return {"states": ["beta", "p", "r"], "outputs": list(scenario.OUTPUTS), "A": _floats(scenario.A),
            "B": _floats(scenario.B), "C": _floats(scenario.C), "D": _floats(np.zeros((4, 5))),
            "controlled": ["beta", "ps"]}


def document(name: str) -> dict[str, Any]:
    """The vehicle document of catalogue entry ``name``."""
    entry = vehicles.lookup(name)
    p = entry.problem()
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
    return {
        "format": FORMAT, "name": name, "description": entry.title, "source": entry.source,
        "axes": axes, "effectors": effectors, "effectiveness": {"B": _floats(p.B)},
        "methods": {"daisy": {"groups": [list(g) for g in entry.daisy_groups]}},
        "model": _ice_model() if ice else _harv_model(),
    }


def main() -> None:
    DATA_DIR.mkdir(parents=True, exist_ok=True)
    for name in vehicles.names():
        path = vehicle_from_dict(document(name)).save(DATA_DIR / f"{name}.toml")
        print(path.relative_to(ROOT))


if __name__ == "__main__":
    main()
