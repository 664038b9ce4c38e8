"""Direction-keeping methods about the operating point: a multirotor's thrust is never dropped
for a moment beyond reach (issue 42).

With rotor limits [0, 1] the preferred position ``up = 0`` is the rotors-off corner of the
attainable set: scaling a demand toward it scales the thrust to zero.  A vehicle that declares
its axes' trim (hover thrust) has ``up`` = the trim command, and ``da``, ``da_facet``,
``da_bisect`` and ``pinv_scale`` keep the direction from there: the moment is reduced, the
answer lies on the segment from the trim to the demand, so the thrust stays between the
trim's and the demand's.  Seeded generators of multirotors (4-12 rotors, tilted, any layout)
and quadplanes (4 lift rotors, a pusher, surfaces) check it.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import alloc
from alloc.vehicle_file import vehicle_from_dict

DIRECTION_KEEPING = ("da", "da_facet", "da_bisect", "pinv_scale")
G = 9.81


def _rotor(name: str, position, axis, ct: float, km: float) -> dict:
    return {"name": name, "kind": "rotor", "unit": "1", "min": 0.0, "max": 1.0,
            "rotor": {"position": [float(x) for x in position], "axis": [float(x) for x in axis], "ct": ct, "km": km}}


def _multirotor(rng: np.random.Generator) -> tuple[dict, float]:
    n = int(rng.integers(4, 13))
    radius = rng.uniform(0.15, 0.6)
    ct = rng.uniform(3.0, 10.0)
    effectors = []
    for i in range(n):
        angle = 2 * math.pi * i / n + rng.normal(0, 0.1)
        # tilted up to 10 degrees in a random direction (a consistent tilt sense is a yaw couple
        # that drag torques cannot trim)
        tilt = np.radians(rng.uniform(0, 10)) * rng.normal(size=2) / math.sqrt(2)
        axis = np.array([tilt[0], tilt[1], -1.0])
        effectors.append(_rotor(f"m{i + 1}", radius * np.array([math.cos(angle), math.sin(angle), rng.normal(0, 0.02)]),
                                axis / np.linalg.norm(axis), ct, (-1) ** i * rng.uniform(0.01, 0.06)))
    mass = rng.uniform(0.3, 0.7) * n * ct / G  # hover at 30-70 % of the thrust
    axes = [{"name": "roll", "unit": "N m"}, {"name": "pitch", "unit": "N m"}, {"name": "yaw", "unit": "N m"},
            {"name": "thrust", "unit": "N", "wrench": "fz", "trim": -mass * G}]
    return {"format": "alloc-vehicle/1", "name": f"multirotor-{n}", "axes": axes, "effectors": effectors}, mass


def _quadplane(rng: np.random.Generator) -> tuple[dict, float]:
    ct = rng.uniform(5.0, 12.0)
    arm = rng.uniform(0.3, 0.8)
    effectors = [_rotor(f"lift{i + 1}", arm * np.array([x, y, 0.0]), [0, 0, -1], ct, km)
                 for i, (x, y, km) in enumerate([(1, 1, 0.05), (-1, -1, 0.05), (1, -1, -0.05), (-1, 1, -0.05)])]
    effectors.append(_rotor("pusher", [-0.5, 0, 0], [1, 0, 0], rng.uniform(5, 20), 0.0))
    for name, column in [("aileron", [0, 0.3, 0, 0, 0]), ("elevator", [0, 0, 0.4, 0, 0]),
                         ("rudder", [0, 0, 0, 0.2, 0])]:
        effectors.append({"name": name, "kind": "surface", "unit": "1", "min": -1.0, "max": 1.0,
                          "effectiveness": [c * rng.uniform(0.5, 1.5) for c in column]})
    mass = rng.uniform(0.3, 0.7) * 4 * ct / G
    axes = [{"name": "fx", "unit": "N", "wrench": "fx"}, {"name": "roll", "unit": "N m"},
            {"name": "pitch", "unit": "N m"}, {"name": "yaw", "unit": "N m"},
            {"name": "thrust", "unit": "N", "wrench": "fz", "trim": -mass * G}]
    return {"format": "alloc-vehicle/1", "name": "quadplane", "axes": axes, "effectors": effectors}, mass


def _beyond_reach(rng: np.random.Generator, problem: alloc.Problem, trim: np.ndarray, moments: list[int]) -> np.ndarray:
    """A demand: the trim's thrust scaled by 0.8-1.2, plus a moment 1.5-4x beyond what the
    effectors give in its direction at that thrust."""
    d = np.zeros(problem.k)
    d[moments] = rng.normal(size=len(moments))
    d /= np.linalg.norm(d)
    v = trim.copy()
    v[-1] *= rng.uniform(0.8, 1.2)
    reach = _reach(problem, v, d)
    return v + rng.uniform(1.5, 4.0) * max(reach, 1e-3) * d


def _reach(problem: alloc.Problem, v: np.ndarray, d: np.ndarray) -> float:
    """The largest ``a`` with ``v + a d`` attainable (an LP, independent of the methods)."""
    from scipy.optimize import linprog

    m = problem.m
    res = linprog(np.r_[np.zeros(m), -1.0], A_eq=np.c_[problem.B, -d], b_eq=v,
                  bounds=list(zip(problem.umin, problem.umax)) + [(0, None)], method="highs")
    return float(res.x[-1]) if res.status == 0 else 0.0


def _check_kept(problem: alloc.Problem, trim: np.ndarray, v: np.ndarray, method: str) -> None:
    r = alloc.allocate(problem, v, method)
    got = problem.B @ r.u
    lo, hi = sorted((abs(trim[-1]), abs(v[-1])))
    scale = max(1.0, abs(v[-1]))
    assert lo - 1e-6 * scale <= abs(got[-1]) <= hi + 1e-6 * scale, (method, got, v, trim)
    # on the segment from the trim to the demand: the direction is kept from the operating point
    step, want = got - trim, v - trim
    a = float(step @ want / (want @ want))
    assert -1e-9 <= a <= 1 + 1e-9, (method, a)
    assert np.abs(step - a * want).max() <= 1e-6 * max(1.0, np.abs(v).max()), (method, step, a * want)


@pytest.mark.parametrize("seed", [*range(6), *(pytest.param(s, marks=pytest.mark.slow) for s in range(6, 200))])
def test_multirotors_keep_thrust_for_moments_beyond_reach(seed: int) -> None:
    rng = np.random.default_rng(seed)
    for _ in range(20):  # a vehicle that can hover (random layouts sometimes cannot trim yaw or a moment)
        vehicle = vehicle_from_dict(_multirotor(rng)[0])
        if alloc.allocate(vehicle.problem(), vehicle.trim, "qp").status == alloc.Status.EXACT:
            break
    problem, trim = vehicle.problem(), vehicle.trim
    assert np.allclose(problem.B @ problem.up, trim)  # up is the trim command
    for _ in range(4):
        v = _beyond_reach(rng, problem, trim, [0, 1, 2])
        for method in DIRECTION_KEEPING:
            _check_kept(problem, trim, v, method)


@pytest.mark.parametrize("seed", [*range(4), *(pytest.param(s, marks=pytest.mark.slow) for s in range(4, 100))])
def test_quadplanes_keep_hover_thrust_when_braking_is_beyond_the_pusher(seed: int) -> None:
    rng = np.random.default_rng(100 + seed)
    doc, mass = _quadplane(rng)
    vehicle = vehicle_from_dict(doc)
    problem, trim = vehicle.problem(), vehicle.trim
    v = trim.copy()
    v[0] = -1.0  # 1 N of braking: the pusher only pushes
    for method in DIRECTION_KEEPING:
        r = alloc.allocate(problem, v, method)
        assert abs((problem.B @ r.u)[-1]) >= 0.999 * mass * G, method
    for _ in range(3):
        w = _beyond_reach(rng, problem, trim, [1, 2, 3])
        for method in DIRECTION_KEEPING:
            _check_kept(problem, trim, w, method)


def test_hexa_x_hover_plus_unreachable_yaw_keeps_its_thrust() -> None:
    """The issue's bar: hexa-x at hover with a yaw moment just beyond reach (0 % thrust before)."""
    problem = alloc.load_vehicle("hexa-x").problem()
    v = np.array([0.0, 0.0, 1.5, -19.6])
    for method in DIRECTION_KEEPING + ("qp",):
        r = alloc.allocate(problem, v, method)
        got = problem.B @ r.u
        assert got[3] / v[3] >= 0.9, (method, got)
        assert got[2] >= 0.9, (method, got)  # and about the yaw qp gives (0.97)


def test_declared_preferred_positions_win_over_the_trim() -> None:
    doc, _ = _multirotor(np.random.default_rng(3))
    for e in doc["effectors"]:
        e["preferred"] = 0.25
    problem = vehicle_from_dict(doc).problem()
    assert np.all(problem.up == 0.25)
    doc["effectors"][0].pop("preferred")  # any declared preferred: the others default as before
    assert vehicle_from_dict(doc).problem().up[0] == 0.0
