"""Open-loop measures of one method on one problem (one CSV row per spec).

* ``coverage`` -- Bordignon-Durham fraction of the AMS volume reached exactly
  (:func:`alloc.ams.coverage`: exact polytope volume for the pseudo-inverse family,
  seeded Monte Carlo with ``samples`` otherwise; Wilson 95 % interval).
* ``unatt_err_mean`` / ``unatt_err_max`` -- ``|v - B u|`` (2-norm) over ``demands``
  seeded demands outside the AMS: ``v = B u0 + s a* d`` with ``d`` uniform on the sphere,
  ``a*`` the ray exit of Eq 1.15 and ``s`` uniform in [1.1, 2]; ``unatt_angle_mean`` is the
  mean angle (deg) between ``B u`` and ``v - B u0`` (0 for direction-preserving methods).
* ``effort_mean`` -- mean ``|u - up|`` (2-norm, effector units) over ``demands`` demands
  drawn uniformly in the AMS.
* ``rate_violation_max`` -- along a smooth sum-of-sines demand trajectory (``steps`` of
  ``TRAJ_DT`` s, amplitude 1.2 x the AMS extent per axis, so it saturates), allocated with
  ``u_prev`` and ``dt`` (Eq 1.28): the largest ``|du/dt|`` beyond the rate limits
  (effector units/s; 0 means compliant).  ``traj_err_mean`` is the mean ``|v - B u|`` there.
* ``fallbacks`` -- allocations with status ``fallback`` over all of the above.
* Timings (in the timings CSV): the run's wall time only.  Per-call latency is not measured
  here, among the sweep's other processes: :mod:`.timing` measures it in a dedicated, quiet,
  single-process pass.
"""

from __future__ import annotations

import time
import zlib
from typing import Any

import numpy as np

import alloc
from alloc import vehicles
from alloc.ams import AttainableSet, coverage, sample_ams
from alloc.exceptions import AllocError
from alloc.testing import random_problem
from alloc.vehicle_file import Vehicle

from .sweep import Spec

__all__ = ["problem_by_name", "vehicle_by_name", "method_options", "run_open", "unattainable_demands", "TRAJ_DT"]

TRAJ_DT = 0.01
#: seed of the random problem suite (problem ``random<i>`` uses ``[RANDOM_SUITE_SEED, i]``)
RANDOM_SUITE_SEED = 2024

#: the sweep's ICE rows use the problem the ICE loop's allocator is given (Eq 4.24)
_CATALOGUE_NAME = {"ice": "ice-design"}


def _random_index(name: str) -> int | None:
    return int(name[6:]) if name.startswith("random") and name[6:].isdigit() else None


def vehicle_by_name(name: str) -> Vehicle | None:
    """The vehicle a sweep's problem name reads: ``ice`` (the design problem of Eq 4.24, which
    the ICE loop's allocator is given: catalogue ``ice-design``), any other catalogue name
    (``harv_latdir``) or a vehicle file; ``None`` for the random suite, which is no vehicle."""
    if _random_index(name) is not None:
        return None
    try:
        return vehicles.get_vehicle(_CATALOGUE_NAME.get(name, name))
    except AllocError as exc:
        raise KeyError(f"problem: {exc}; or random<i>") from None


def _spec_vehicle(spec: Spec) -> Vehicle | None:
    """A spec's vehicle: ``spec["vehicle"]`` as ``--vehicle`` reads it (``alloc bench openloop``), else by its problem name."""
    if "vehicle" in spec:
        return vehicles.get_vehicle(spec["vehicle"])
    return vehicle_by_name(spec["problem"])


def problem_by_name(name: str) -> alloc.Problem:
    """The problem of a sweep's problem name (:func:`vehicle_by_name`), or ``random<i>`` (3 x 8,
    general position, with limits, preferences, weights and rate limits; ``Wv`` reduced to its
    diagonal because ``lp`` accepts only weight vectors, Eqs 1.18-1.19)."""
    i = _random_index(name)
    if i is not None:
        rng = np.random.default_rng([RANDOM_SUITE_SEED, i])
        p = random_problem(rng, 3, 8, "general")
        return p.replace(Wv=np.diag(np.diag(p.Wv)))
    vehicle = vehicle_by_name(name)
    assert vehicle is not None
    return vehicle.problem()


def _options(vehicle: Vehicle | None, method: str) -> dict[str, Any]:
    # The random suite is no vehicle and declares no groups: daisy runs there as one group
    # (pinv_scale's answer), as the committed rows were measured; every vehicle gets its own.
    return {} if vehicle is None else vehicles.method_options(vehicle, method)


def method_options(problem: str, method: str) -> dict[str, Any]:
    """The options ``method`` runs with on a sweep's problem: the vehicle's defaults
    (:func:`alloc.vehicles.method_options`; ICE's and the HARV's daisy groups), none on the random suite."""
    return _options(vehicle_by_name(problem), method)


def _rng(spec: Spec, purpose: str) -> np.random.Generator:
    # crc32, not hash(): str hashes are salted per process and would differ between workers
    return np.random.default_rng([spec["seed"], zlib.crc32(spec["problem"].encode()), zlib.crc32(purpose.encode())])


def unattainable_demands(ams: AttainableSet, u0: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
    """``n`` demands outside the AMS: ``B u0 + s a*(d) d``, ``s`` in [1.1, 2] (Eq 1.15's ``a*``)."""
    B = ams.problem.B
    out = []
    while len(out) < n:
        d = rng.normal(size=B.shape[0])
        d /= np.linalg.norm(d)
        a, _ = ams.max_in_direction(d)
        s = rng.uniform(1.1, 2.0)
        if np.isfinite(a) and a > 0:
            out.append(B @ u0 + s * a * d)
    return np.array(out)


def demand_trajectory(ams: AttainableSet, u0: np.ndarray, steps: int) -> np.ndarray:
    """Smooth sum-of-sines demands, 1.2 x the AMS extent along each axis (so they saturate)."""
    k = ams.problem.k
    eye = np.eye(k)
    extent = np.array([min(ams.max_in_direction(eye[j])[0], ams.max_in_direction(-eye[j])[0]) for j in range(k)])
    t = np.arange(steps)[:, None] * TRAJ_DT
    freq = 0.4 + 0.3 * np.arange(k)  # Hz, incommensurate enough
    phase = np.pi / 3 * np.arange(k)
    # two sines of amplitude 0.6 each: peaks up to 1.2 x the extent
    wave = 0.6 * np.sin(2 * np.pi * freq * t + phase) + 0.6 * np.sin(2 * np.pi * 2.3 * freq * t)
    return ams.problem.B @ u0 + extent * wave


def _angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    na, nb = np.linalg.norm(a), np.linalg.norm(b)
    if na == 0 or nb == 0:
        return 90.0
    return float(np.degrees(np.arccos(np.clip(a @ b / (na * nb), -1.0, 1.0))))


def run_open(spec: Spec) -> tuple[dict[str, Any], dict[str, Any]]:
    """Row and timings of one open-loop spec (see the module docstring for the measures)."""
    t0 = time.perf_counter()
    vehicle = _spec_vehicle(spec)
    problem = problem_by_name(spec["problem"]) if vehicle is None else vehicle.problem()
    method = spec["method"]
    options = _options(vehicle, method)
    allocate = alloc.make_allocator(problem, method, **options)
    ams = AttainableSet(problem)
    u0 = np.clip(problem.up, problem.umin, problem.umax)
    B = problem.B

    cov = coverage(problem, method, samples=spec["samples"], seed=spec["seed"], **options)

    V_out = unattainable_demands(ams, u0, spec["demands"], _rng(spec, "unattainable"))
    res_out = [allocate(v) for v in V_out]
    err_out = np.array([r.moment_error for r in res_out])
    angle_out = np.array([_angle_deg(r.v_achieved - B @ u0, v - B @ u0) for r, v in zip(res_out, V_out)])

    V_in = sample_ams(ams, spec["demands"], _rng(spec, "attainable"))
    res_in = [allocate(v) for v in V_in]
    effort = np.array([np.linalg.norm(r.u - problem.up) for r in res_in])

    traj = demand_trajectory(ams, u0, spec["steps"])
    u = u0.copy()
    rate_excess, traj_err, traj_fallbacks = 0.0, [], 0
    for v in traj:
        r = allocate(v, u_prev=u, dt=TRAJ_DT)
        rate = (r.u - u) / TRAJ_DT
        rate_excess = max(rate_excess, float(np.max(rate - problem.rate_max)), float(np.max(problem.rate_min - rate)))
        traj_err.append(r.moment_error)
        traj_fallbacks += r.fallback
        u = r.u

    fallbacks = sum(r.fallback for r in res_out) + sum(r.fallback for r in res_in) + traj_fallbacks
    row = {
        "id": spec["id"], "problem": spec["problem"], "method": method,
        "coverage": cov.fraction, "coverage_lo": cov.ci95[0], "coverage_hi": cov.ci95[1],
        "coverage_estimator": cov.estimator,
        "unatt_err_mean": float(err_out.mean()), "unatt_err_max": float(err_out.max()),
        "unatt_angle_mean": float(angle_out.mean()),
        "effort_mean": float(effort.mean()),
        "rate_violation_max": max(0.0, rate_excess),
        "traj_err_mean": float(np.mean(traj_err)),
        "fallbacks": int(fallbacks), "calls": len(res_out) + len(res_in) + len(traj),
    }
    return row, {"id": spec["id"], "wall_s": time.perf_counter() - t0}
