"""The control distribution in the loop: any method of the allocation registry.

The simulator calls the same :func:`alloc.make_allocator` a user would, on the
vehicle's allocation :class:`alloc.Problem` (effectiveness ``B_alloc``,
Table limits, rate limits, seed weights).  When the scenario says the
allocator knows the failure, it is told each effector failure by the kind's told
rule (:data:`alloc.health.FAILURE_KINDS`) through :meth:`alloc.Problem.with_health`.

One extra method lives here because it is not an allocation algorithm: the
seed's printed static distribution matrix, ``static`` (``u = B_k u_c``, seed
Eq 4.12, 4.19, 4.24), used to reproduce the seed's designs exactly.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any

import numpy as np
import alloc._engine._kernel_cache  # noqa: F401 - kernel caches placed before any kernel is decorated
from numba import njit

from sim.result import STATUS_NAMES

if TYPE_CHECKING:
    from sim.model import Failure, PlantModel

__all__ = ["LoopAllocator", "STATIC", "PREFERRED_POSITIONS", "RATE_HORIZONS", "actuator_lag", "allocation_problem",
           "build_allocator", "health_events", "hold_commands", "preferred_positions", "rate_horizon_scale",
           "RATE_WINDOWS", "stuck_effectors"]

#: Name of the seed's printed static distribution (not a registry method).
STATIC = "static"

_STATUS_CODE = {name: code for code, name in enumerate(STATUS_NAMES)}

#: ``(v, u_prev, dt) -> (u_cmd, v_achieved, status code)``; the loop records ``v - v_achieved``
#: as unallocated and the code (:data:`STATUS_NAMES`) per frame.
LoopAllocator = Callable[[np.ndarray, np.ndarray, float], tuple[np.ndarray, np.ndarray, int]]

#: Preferred-position rules for effectors with a limit at 0 (one-sided: ICE tips and
#: spoiler-slot deflectors, 0..60 deg): ``"mid"`` (default) mid-range, ``"zero"`` the
#: seed's ``up = 0`` (on ICE, ``daisy`` and ``pinv_scale`` then have no room and fly u = 0).
PREFERRED_POSITIONS = ("mid", "zero")


def preferred_positions(vehicle: PlantModel, rule: str = "mid") -> np.ndarray:
    """Preferred positions ``up``: 0 for two-sided effectors; one-sided ones by ``rule``.

    A one-sided effector (a position limit at 0) preferred at that limit can
    only move one way from it; direction-preserving methods (``pinv_scale``,
    ``daisy``) then scale every command to the base point.  Mid-range gives
    them room both ways (the remedy the README recommends since the AMS study).
    """
    if rule not in PREFERRED_POSITIONS:
        raise ValueError(f"preferred: {rule!r}; expected one of {PREFERRED_POSITIONS}")
    lo, hi = vehicle.umin, vehicle.umax
    up = np.clip(np.zeros_like(lo), lo, hi)
    if rule == "mid":
        one_sided = (lo == 0.0) | (hi == 0.0)
        up[one_sided] = 0.5 * (lo[one_sided] + hi[one_sided])
    return up


def health_events(vehicle: PlantModel, failure: Failure) -> list[Any]:
    """The failure's effector events in the one health vocabulary (:mod:`alloc.health`).

    Each :class:`sim.blocks.ActuatorFailure` of a told kind is the :class:`alloc.health.FailureEvent`
    of the same kind and parameters; the simulator-only kinds (:data:`alloc.health.SIMULATOR_ONLY`:
    ``bandwidth``, and the failure's added delay) change actuator *dynamics*, which a static
    problem cannot express, and are never told.  A jam without a position is told the position
    the actuator held when the failure was injected (the engine passes the failure as injected,
    :meth:`sim.blocks.ActuatorBank.apply_failure`); before injection it has none, and telling it
    raises ProblemError naming ``position``.
    """
    from alloc.health import SIMULATOR_ONLY, FailureEvent

    return [FailureEvent(vehicle.effector_names[f.index], f.kind, **f.params)
            for f in failure.actuators if f.kind not in SIMULATOR_ONLY]


def allocation_problem(vehicle: PlantModel, failure: Failure | None = None, *, preferred: str = "mid",
                       health: Mapping[str, Any] | None = None) -> Any:
    """The vehicle's :class:`alloc.Problem`; with ``failure``, as told of the failed effectors.

    Plant-level failures (A, B scaling) are unknown to the allocator by
    design (seed: "sudden, unknown failure"); effector failures are told
    through :meth:`alloc.Problem.with_health` by each kind's told rules
    (:data:`alloc.health.FAILURE_KINDS`, see :func:`health_events`).  Bandwidth
    and delay failures are never told.
    ``preferred``: rule for the preferred positions (:func:`preferred_positions`).
    ``health``: effector name -> :class:`alloc.health.EffectorHealth` instead of a failure
    (a detector's belief, :mod:`sim.detection`); giving both raises ValueError.
    """
    import alloc
    from alloc.health import apply_event

    problem = alloc.Problem(
        vehicle.B_alloc,
        vehicle.umin,
        vehicle.umax,
        up=preferred_positions(vehicle, preferred),
        Wu=None if vehicle.Wu is None else np.asarray(vehicle.Wu, dtype=float),
        rate_min=-vehicle.rate_max,
        rate_max=vehicle.rate_max,
        names=vehicle.effector_names,
        axes=vehicle.channels,
    )
    if failure is not None and health is not None:
        raise ValueError("allocation_problem: give a failure (told) or a health (detected), not both")
    if health is not None:
        return problem.with_health(dict(health)) if health else problem
    if failure is None:
        return problem
    told: dict[str, Any] = {}
    for event in health_events(vehicle, failure):
        _, told = apply_event(problem, told, event)
    return problem.with_health(told)


#: Horizons of the Eq 1.28 rate box (see :func:`build_allocator`).
RATE_HORIZONS = ("actuator", "frame")

#: When the Eq 1.28 rate box is given to the method (see :func:`build_allocator`).
RATE_WINDOWS = ("binding", "always")

#: Hz: the band of the in-loop null-space excitation (``excitation`` > 0; seed 1.3.2.5).
#: Chosen from the detector's time scales, not from a verdict: its lowest tone turns
#: through 0.4 of a period in the detector's 0.4 s window (sim.detection.DEFAULT_DESIGN), its
#: highest stays below the 5 Hz Nyquist rate of the detector's 0.1 s samples and the ICE
#: actuators' 4.5 Hz corner (a 35 ms lag).
EXCITATION_BAND = (1.0, 4.0)


@njit(cache=True)
def _inside_rate_window(u: np.ndarray, u_prev: np.ndarray, limits: np.ndarray, dt: float, base: np.ndarray) -> bool:
    """``base = clip(u_prev, lo, hi)``; True when ``u`` (inside ``[lo, hi]``) is inside its Eq 1.28 box.

    ``limits`` rows: ``lo, hi, rate_min, rate_max`` (one array: one argument to unbox per call).
    """
    inside = True
    for j in range(u.size):
        b = min(max(u_prev[j], limits[0, j]), limits[1, j])
        base[j] = b
        if u[j] < b + limits[2, j] * dt or u[j] > b + limits[3, j] * dt:
            inside = False
    return inside


def actuator_lag(vehicle: PlantModel) -> np.ndarray:
    """Ramp-following lag (s) of each nominal actuator: ``c1 / wn2`` (second order), ``1 / a`` (first)."""
    return np.array([a.c1 / a.wn2 if a.order == 2 else 1.0 / a.c1 for a in vehicle.actuators])


def rate_horizon_scale(vehicle: PlantModel, frame_period: float, horizon: str) -> np.ndarray:
    """Factor on each rate limit so the Eq 1.28 box at ``dt = T`` spans ``max(T, lag)`` (``horizon="actuator"``)."""
    if horizon not in RATE_HORIZONS:
        raise ValueError(f"rate_horizon: {horizon!r}; expected one of {RATE_HORIZONS}")
    if horizon == "frame":
        return np.ones(len(vehicle.actuators))
    return np.maximum(1.0, actuator_lag(vehicle) / frame_period)


def build_allocator(
    vehicle: PlantModel,
    method: str,
    options: dict[str, Any],
    *,
    failure: Failure | None = None,
    health: Mapping[str, Any] | None = None,
    rate_aware: bool = True,
    preferred: str = "mid",
    frame_period: float | None = None,
    rate_horizon: str = "actuator",
    rate_window: str = "binding",
    excitation: float = 0.0,
    excitation_seed: int = 0,
    first_call: int = 0,
) -> LoopAllocator:
    """Allocator callable for the loop.

    ``static`` ignores the failure and the health (a fixed matrix cannot be told anything).
    ``health`` (a detector's belief) replaces ``failure`` (see :func:`allocation_problem`).
    A method that takes a static distribution matrix (its declared
    :attr:`~alloc.method.Method.distribution_option`: ``ganging``'s ``G``) gets the seed's
    distribution ``B_k`` (in demand units) unless the options give one.

    With ``rate_aware`` (default) every call passes ``u_prev`` and the frame
    period ``dt = T`` (seed Eq 1.28); ``u_prev`` is clipped into the (told)
    position limits first, since a jammed effector's previous command may lie
    outside its point limits.

    ``rate_horizon``: Eq 1.28 bounds what the *surface* can reach before the
    allocator acts again, and assumes the actuator reaches its command within
    the frame.  A linear actuator follows a command ramp only after its lag
    (:func:`actuator_lag`: 35 ms for the ICE surfaces); with ``T`` shorter than
    that, a box of ``rate * T`` around the previous command turns the allocator
    into a command rate limiter in series with the actuator's own rate limit,
    which adds the actuator lag once more in every saturated episode (the cause
    of the ICE divergence with rate-aware ``pinv``/``qp`` told of the failure).
    ``"actuator"`` (default) spans ``max(T, lag)`` per effector (rate limits
    scaled by :func:`rate_horizon_scale`); ``"frame"`` is Eq 1.28 with ``dt = T``
    literally.  With ``T >= lag`` the two coincide.

    ``rate_window``: Eq 1.28 is a constraint on the next command.  ``"binding"``
    (default) first allocates within the position limits and keeps that answer
    when it lies inside the rate box around ``u_prev``; only an answer that
    would break a rate limit is replaced by the method's answer within the box.
    ``"always"`` gives every call the box.  The two agree for ``pinv`` (a clip)
    and for the methods that optimise over the box (``qp``, ``wls``: the unique
    optimum does not move when a constraint is inactive), but not for the heuristics (``cgi``,
    ``daisy``, ``pinv_scale``, ``da``, ``lp``, ...): their answer depends on the box
    even where it does not bind (``cgi`` starts from the preferred point clipped
    to it, ``pinv_scale``/``daisy`` scale from that clipped point), so with
    ``"always"`` the allocator gets a memory of ``u_prev`` and the command
    drifts in the null space of ``B`` (ICE ``cgi``: pitch flap 14 deg from its
    preferred position against 4 rate-blind, at every frame rate).

    ``excitation`` (effector units, peak per effector; 0: none) adds the library's null-space
    multisine (:class:`alloc.estimation.NullSpaceExcitation`, band :data:`EXCITATION_BAND`,
    seeded by ``excitation_seed``) to every answer, within the position limits and the rate
    box the answer was held to, ``B e = 0`` for the allocation problem as the allocator knows
    it: commands an estimator can tell apart (seed 1.3.2.5) at the same moments.  Its
    signal is a function of the call's index, so a rebuilt allocator (a health change)
    continues it when given ``first_call``, the index of its first call.
    """
    if method == STATIC:
        if options or excitation:
            raise TypeError(f"method {STATIC!r} takes no options and no excitation, got "
                            f"{sorted(options) + (['excitation'] if excitation else [])}")
        # v = demand_map u_c, so u = B_k u_c = B_k demand_map^-1 v.
        Bk = vehicle.Bk_seed @ np.linalg.inv(vehicle.demand_map)
        B = vehicle.B_alloc

        def static(v: np.ndarray, u_prev: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray, int]:
            u = Bk @ v
            return u, B @ u, 0  # a fixed matrix, no limits: exact by construction (B Bk = I)

        return static

    import alloc
    from alloc.result import Status

    opts = dict(options)
    gang = alloc.registry.get_method(method).distribution_option if method in alloc.methods() else None
    if gang is not None and gang not in opts:
        # the allocator's distribution acts on the demand v = demand_map u_c: G = B_k demand_map^-1
        opts[gang] = vehicle.Bk_seed @ np.linalg.inv(vehicle.demand_map)
    problem = allocation_problem(vehicle, failure, preferred=preferred, health=health)
    if rate_aware and frame_period is not None:
        scale = rate_horizon_scale(vehicle, frame_period, rate_horizon)
        problem = problem.replace(rate_min=scale * problem.rate_min, rate_max=scale * problem.rate_max)
    if rate_window not in RATE_WINDOWS:
        raise ValueError(f"rate_window: {rate_window!r}; expected one of {RATE_WINDOWS}")
    solve = alloc.make_allocator(problem, method, **opts)
    lo, hi = problem.umin, problem.umax
    limits = np.array([lo, hi, problem.rate_min, problem.rate_max])
    base = np.empty(problem.m)
    # status member -> STATUS_NAMES code, looked up by identity (cheaper per call than .value)
    code = {status: _STATUS_CODE[status.value] for status in Status}

    def registry(v: np.ndarray, u_prev: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray, int]:
        res = solve(v)
        return res.u, res.v_achieved, code[res.status]

    def registry_rate_aware(v: np.ndarray, u_prev: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray, int]:
        res = solve(v, u_prev=np.minimum(np.maximum(u_prev, lo), hi), dt=dt)  # seed Eq 1.28
        return res.u, res.v_achieved, code[res.status]

    def registry_rate_binding(v: np.ndarray, u_prev: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray, int]:
        res = solve(v)
        if not _inside_rate_window(res.u, u_prev, limits, dt, base):
            res = solve(v, u_prev=base, dt=dt)  # seed Eq 1.28, where it binds
        return res.u, res.v_achieved, code[res.status]

    chosen = registry if not rate_aware else registry_rate_binding if rate_window == "binding" else registry_rate_aware
    if not excitation:
        return chosen
    return _excited(chosen, solve, problem, frame_period, excitation, excitation_seed, first_call, rate_aware, code)


def _excited(chosen: LoopAllocator, solve: Any, problem: Any, frame_period: float | None, amplitude: float,
             seed: int, first_call: int, rate_aware: bool, code: Mapping[Any, int]) -> LoopAllocator:
    """``chosen`` with the null-space excitation of call ``first_call + n`` added to its n-th
    answer, held to the bounds that answer was held to (Eq 1.28 whenever the loop is
    rate-aware: the box of ``u_prev`` clipped into the limits)."""
    from alloc.estimation import NullSpaceExcitation
    from alloc.result import Result

    if frame_period is None:  # the signal's clock is the loop's frame; there is no default to guess
        raise ValueError("excitation: needs frame_period (the seconds between the allocator's calls)")
    wrapper = NullSpaceExcitation(solve, frame_period, amplitude=amplitude, band=EXCITATION_BAND, seed=seed)
    lo, hi = problem.umin, problem.umax
    status_of = {c: s for s, c in code.items()}
    calls = [first_call]

    def excited(v: np.ndarray, u_prev: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray, int]:
        u, v_achieved, status = chosen(v, u_prev, dt)
        answer = Result(u, v, v_achieved, status_of[status], "loop")
        n = calls[0]
        calls[0] += 1
        if rate_aware:
            out = wrapper.excite(answer, n, np.minimum(np.maximum(u_prev, lo), hi), dt)  # seed Eq 1.28
        else:
            out = wrapper.excite(answer, n)
        return out.u, out.v_achieved, code[out.status]

    return excited


def stuck_effectors(vehicle: PlantModel, health: Mapping[str, Any]) -> list[int]:
    """Indices of the effectors a belief says are stuck: jammed, hard-over (a jam at a stop) or floating."""
    names = list(vehicle.effector_names)
    return sorted(names.index(name) for name, h in health.items() if h.jam_position is not None or h.floating)


def hold_commands(allocator: LoopAllocator, held: Mapping[int, float]) -> LoopAllocator:
    """``allocator`` whose command to each effector of ``held`` (index -> command) is that value.

    A belief that an effector is stuck is never enforced by commanding it.  The allocator
    solves with the believed position (its moment is accounted for in ``v_achieved``), but the
    command sent is the one the effector had before the belief: if the surface really is stuck
    the command does nothing; if it is not, the surface stays where it was, instead of being
    driven to the believed position, which would make a false belief self-fulfilling (the
    residual of "jammed at p" and of "healthy, commanded to p" are the same, so the detector
    could never see the contradiction, and a healthy surface driven to a stop loses its
    authority).  Held where it was, a healthy surface keeps responding as commanded in the
    detector's nominal copy, and the detector, which tests every effector against its current
    model, sees the difference between its position and the believed one.  Flight software
    does the same: PX4's ``ControlAllocator::check_for_motor_failures`` removes a motor reported
    failed from the effectiveness matrix and ArduPilot's ``AP_MotorsMatrix::check_for_failed_motor``
    boosts the others (``thrust_boost``); neither drives the failed motor to a believed state.
    Wells (2002, section 1.3.4) treats a failed effector as a known contribution to the moment
    that the healthy ones compensate, not as a position to be commanded.
    """
    if not held:
        return allocator
    index = np.fromiter(held.keys(), dtype=np.int64)
    values = np.fromiter(held.values(), dtype=float)

    def holding(v: np.ndarray, u_prev: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray, int]:
        u, v_achieved, status = allocator(v, u_prev, dt)
        u = np.array(u, dtype=float)
        u[index] = values
        return u, v_achieved, status

    return holding
