"""Multirotor vehicle documents for the plant tests: the bundled hexa-x without its [model], and an
octocopter built here (its numbers are this file's, stated where they are set)."""

from __future__ import annotations

import math
from typing import Any

from alloc.vehicle_file import load_vehicle

GRAVITY = 9.81  # RotorPy's


def hexa_document(**body: Any) -> dict[str, Any]:
    """hexa-x's document with no [model] and no [methods], its [body] replaced by ``body``."""
    doc = load_vehicle("hexa-x").to_dict()
    doc.pop("model", None)
    doc["name"], doc["source"], doc["description"] = "hexa-body", "", "hexa-x rotors, [body] only"
    doc["body"] = dict(body) if body else {"mass": 2.0, "inertia": [0.08, 0.08, 0.15], "rotor_speed_max": 900.0}
    return doc


#: the octocopter: 8 rotors on a 0.6 m radius at 22.5 + 45 k deg, alternating spin, 6.5 N each at full
#: command, 3 kg, inertia diag(0.12, 0.12, 0.22) kg m^2, motors 1/30 s, 900 rad/s at full command
OCTO_MASS = 3.0
OCTO_CT = 6.5
OCTO_KM = 0.05


def octo_document() -> dict[str, Any]:
    effectors = []
    for j in range(8):
        a = math.radians(22.5 + 45.0 * j)
        effectors.append({
            "name": f"motor{j + 1}", "kind": "rotor", "unit": "1", "min": 0.0, "max": 1.0, "rate_max": 10.0,
            "dynamics": {"bandwidth": 30.0},
            "rotor": {"position": [0.6 * math.cos(a), 0.6 * math.sin(a), 0.0], "axis": [0.0, 0.0, -1.0],
                      "ct": OCTO_CT, "km": OCTO_KM if j % 2 else -OCTO_KM}})
    return {
        "format": "alloc-vehicle/1", "name": "octo-x", "description": "octocopter for the plant tests",
        "axes": [{"name": "roll", "unit": "N m"}, {"name": "pitch", "unit": "N m"}, {"name": "yaw", "unit": "N m"},
                 {"name": "thrust", "unit": "N", "wrench": "fz", "trim": -OCTO_MASS * GRAVITY}],
        "effectors": effectors,
        "methods": {"qp": {"priorities": [2, 2, 1, 3]}},
        "body": {"mass": OCTO_MASS, "inertia": [0.12, 0.12, 0.22], "rotor_speed_max": 900.0},
    }
