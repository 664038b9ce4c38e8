"""A scheduled multirotor for the simulator's schedule tests: hexa-x with every rotor tilting forward together.

The tilt ``t`` (deg, 0 to 60, nominal 0) turns each rotor's axis from body up to forward, ``a(t) = cos(t)
(0, 0, -1) + sin(t) (1, 0, 0)``; the rotor's wrench is linear in its axis (PX4's rotor column,
:func:`alloc.vehicle_file.parts.rotor_wrench`), so ``B(t) = B + (cos t - 1) B_up + sin t B_forward``:
two ``[schedule]`` terms, the columns computed from hexa-x's own rotors."""

from __future__ import annotations

from typing import Any

import numpy as np

from alloc.vehicle_file import load_vehicle
from alloc.vehicle_file.parts import rotor_wrench

#: the wrench components of hexa-x's axes, in rotor_wrench's order [roll, pitch, yaw, fx, fy, fz]
_ROWS = {"roll": 0, "pitch": 1, "yaw": 2, "fz": 5}


def tilting_hexa_document(max_tilt: float = 60.0) -> dict[str, Any]:
    fv = load_vehicle("hexa-x")
    rows = [_ROWS[a.component] for a in fv.axes]

    def columns(axis: tuple[float, float, float]) -> list[list[float]]:
        W = np.array([rotor_wrench(e.rotor.position, axis, e.rotor.ct, e.rotor.km) for e in fv.effectors]).T
        return W[rows].tolist()

    doc = fv.to_dict()
    doc["format"] = "alloc-vehicle/1.2"
    doc["name"], doc["description"] = "hexa-tilt", "hexa-x with every rotor tilting forward together (tests)"
    doc["schedule"] = {
        "variables": [{"name": "tilt", "unit": "deg", "min": 0.0, "max": max_tilt, "nominal": 0.0}],
        "terms": [{"factor": "cos", "variable": "tilt", "B": columns((0.0, 0.0, -1.0))},
                  {"factor": "sin", "variable": "tilt", "B": columns((1.0, 0.0, 0.0))}]}
    return doc
