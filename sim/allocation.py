"""The control distribution in the loop: any method of the allocation registry.

The simulator calls the same :func:`alloc.make_allocator` a user would, on the
vehicle's allocation :class:`alloc.Problem` (effectiveness ``B_alloc``,
Table limits, rate limits, seed weights).  When the scenario says the
allocator knows the failure, the failed effectors' new limits (jam position,
reduced position and rate limits, lost effectiveness) go into the Problem.

One extra method lives here because it is not an allocation algorithm: the
seed's printed static distribution matrix, ``static`` (``u = B_k u_c``, seed
Eq 4.12, 4.19, 4.24), used to reproduce the seed's designs exactly.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from sim.loop import Failure, Vehicle

__all__ = ["LoopAllocator", "STATIC", "allocation_problem", "build_allocator"]

#: Name of the seed's printed static distribution (not a registry method).
STATIC = "static"

#: ``(v, u_prev, dt) -> (u_cmd, v_achieved)``; the loop records ``v - v_achieved`` as unallocated.
LoopAllocator = Callable[[np.ndarray, np.ndarray, float], tuple[np.ndarray, np.ndarray]]


def allocation_problem(vehicle: Vehicle, failure: Failure | None = None) -> Any:
    """The vehicle's :class:`alloc.Problem`; with ``failure``, as told of the failed effectors.

    Plant-level failures (A, B scaling) are unknown to the allocator by
    design (seed: "sudden, unknown failure"); effector failures are told as:
    jam -> ``umin = umax = position``; hard-over -> jam at the hard-over
    position; float -> zero effectiveness; limits -> new position/rate limits;
    effectiveness -> scaled column.  Reduced bandwidth and delays are not
    expressible in a static Problem and are not told.
    """
    import alloc

    problem = alloc.Problem(
        vehicle.B_alloc,
        vehicle.umin,
        vehicle.umax,
        Wu=None if vehicle.Wu is None else np.asarray(vehicle.Wu, dtype=float),
        rate_min=-vehicle.rate_max,
        rate_max=vehicle.rate_max,
        names=vehicle.effector_names,
        axes=vehicle.channels,
    )
    if failure is None:
        return problem
    for f in failure.actuators:
        i = f.index
        if f.kind in ("jam", "hardover"):
            pos = f.position if f.position is not None else vehicle.umax[i]
            problem = problem.with_jam(i, pos)
        elif f.kind == "float":
            problem = problem.with_effectiveness(i, 0.0)
        elif f.kind == "effectiveness":
            problem = problem.with_effectiveness(i, float(f.fraction))
        elif f.kind == "limits":
            if f.lo is not None or f.hi is not None:
                lo = problem.umin[i] if f.lo is None else f.lo
                hi = problem.umax[i] if f.hi is None else f.hi
                problem = problem.with_limits(i, lo, hi)
            if f.rate is not None:
                rmin, rmax = problem.rate_min.copy(), problem.rate_max.copy()
                rmin[i], rmax[i] = -f.rate, f.rate
                problem = problem.replace(rate_min=rmin, rate_max=rmax)
    return problem


def build_allocator(
    vehicle: Vehicle,
    method: str,
    options: dict[str, Any],
    *,
    failure: Failure | None = None,
    u_prev: np.ndarray | None = None,
    rate_aware: bool = False,
) -> LoopAllocator:
    """Allocator callable for the loop.

    ``static`` ignores the failure (a fixed matrix cannot be told anything).
    For ``ganging`` the seed's distribution ``B_k`` (in demand units) is the default gang.

    With ``rate_aware`` the allocator gets ``u_prev`` (its previous command)
    and the integration step, so Eq 1.28 limits each command change to
    ``rate * dt``.  Off by default: at dt = 0.5 ms this turns the allocator
    into a command rate limiter ahead of actuators that already enforce their
    rate limits, and measured tracking collapses (HARV lat-dir ps RMS 0.7 ->
    17.9 deg/s with ganging); the seed's static distribution has no such stage.
    """
    if method == STATIC:
        if options:
            raise TypeError(f"method {STATIC!r} takes no options, got {sorted(options)}")
        # v = demand_map u_c, so u = B_k u_c = B_k demand_map^-1 v.
        Bk = vehicle.Bk_seed @ np.linalg.inv(vehicle.demand_map)
        B = vehicle.B_alloc

        def static(v: np.ndarray, u_prev: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
            u = Bk @ v
            return u, B @ u

        return static

    import alloc

    opts = dict(options)
    if method == "ganging" and "G" not in opts:
        # alloc's gang acts on the demand v = demand_map u_c: G = B_k demand_map^-1.
        opts["G"] = vehicle.Bk_seed @ np.linalg.inv(vehicle.demand_map)
    problem = allocation_problem(vehicle, failure)
    solve = alloc.make_allocator(problem, method, **opts)
    lo, hi = problem.umin, problem.umax

    def registry(v: np.ndarray, u_prev: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
        res = solve(v)
        return res.u, res.v_achieved

    def registry_rate_aware(v: np.ndarray, u_prev: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
        # A jammed effector's previous command may lie outside its new (point) limits.
        res = solve(v, u_prev=np.minimum(np.maximum(u_prev, lo), hi), dt=dt)
        return res.u, res.v_achieved

    return registry_rate_aware if rate_aware else registry
