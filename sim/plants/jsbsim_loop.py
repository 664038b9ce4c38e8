"""A minimal closed loop for the JSBSim F-22: seed section 4.3 SMC, the library's allocator, the plant.

This module flies :class:`sim.plants.jsbsim.JSBSimPlant` on its own (:func:`fly`); ``alloc sim --plant
jsbsim:f22`` flies the same law (:meth:`SMCLoop.demand`, :meth:`SMCLoop.observe`) in the plant loop
(:mod:`sim.plants.jsbsim_run`).  Everything the
controller knows comes from the linearisation (the vehicle file
:data:`sim.plants.jsbsim_linear.VEHICLE_FILE`, or one measured now):

* the design is :func:`sim.autodesign.auto_design` on the model (via
  :func:`sim.user_vehicle.flight_model`), at the frame period ``T`` (one JSBSim step, 1/120 s).
  One option differs from its defaults, and it is stated: ``stability_margin = 0.005`` 1/s,
  because the model's slow airspeed mode under rate control sits at -0.0087 1/s, right of the
  default -0.01 (the next mode of the check is at -0.355 1/s, 40 times further left);
* controller, each frame: reference models (``100 / (s^2 + 20 s + 100)``, from the design) of the
  commands, one full-order observer per channel (seed section 3.3) on all eight measured
  outputs, ``sigma = K0 e + K_-1 int(e)`` with ``e = r - y_hat``, ``u_c = rho sat(sigma / eps)``
  (seed Eq 4.8), ``v = demand_map u_c``, ``u = allocator(v, u_prev, T)`` with method ``qp`` by
  default (rate limits on).  Observers and reference models are exact zero-order-hold
  discretisations at ``T``.  The integral of a channel whose boundary layer is saturated
  stops (anti-windup, our choice; the seed does not give one for this loop);
* failures: at ``failure_time`` the plant gets the failure; a told allocator is rebuilt on the
  problem with the failure's health (:func:`alloc.health.apply_event`), a blind one keeps the
  nominal problem.
* the observers' input (``observer_input``): ``"command"``, the allocator's command, as in the
  seed's loop (its observers model no actuators), or ``"position"``, the effector positions the
  plant reports at the frame's start -- what a blind allocator's jammed surface really does.
"""

from __future__ import annotations

import math
import time as _time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any
from collections.abc import Callable

import numpy as np
import scipy.linalg
import scipy.signal

from alloc.exceptions import AllocError
from sim.plants.jsbsim import JSBSimPlant
from sim.plants.jsbsim_linear import CONTROLLED, VEHICLE_FILE
from sim.plants.jsbsim_model import STATES

__all__ = ["DESIGN_OPTIONS", "OUTPUT_BOUND", "OBSERVER_INPUTS", "Flight", "SMCLoop", "fly", "doublets"]

#: the one design option changed from sim.autodesign's defaults (module docstring says why)
DESIGN_OPTIONS = {"stability_margin": 0.005}
#: divergence: any output deviation beyond these (vt m/s, alpha deg, q deg/s, theta deg, beta deg,
#: p deg/s, r deg/s, phi deg) ends the flight as diverged
OUTPUT_BOUND = np.array([60.0, 15.0, 60.0, 30.0, 10.0, 120.0, 60.0, 60.0])
#: what the observers take as the effectors' input (module docstring)
OBSERVER_INPUTS = ("command", "position")


def doublets(t: np.ndarray, amplitude: tuple[float, float, float] = (2.0, 10.0, 2.0)) -> np.ndarray:
    """Commands (deg/s) per channel q, p, r: 1 s + 1 s doublets; pitch at 2 s and again at 10 s (after a
    failure at the default 5 s), roll at 6 s, yaw at 14 s."""
    t = np.asarray(t, dtype=float)

    def doublet(start: float) -> np.ndarray:
        return ((t >= start) & (t < start + 1)) * 1.0 - ((t >= start + 1) & (t < start + 2))

    out = np.zeros((t.size, len(CONTROLLED)))
    out[:, 0] = amplitude[0] * (doublet(2.0) + doublet(10.0))
    out[:, 1] = amplitude[1] * doublet(6.0)
    out[:, 2] = amplitude[2] * doublet(14.0)
    return out


def _zoh(A: np.ndarray, B: np.ndarray, T: float) -> tuple[np.ndarray, np.ndarray]:
    n, m = B.shape
    M = np.zeros((n + m, n + m))
    M[:n, :n], M[:n, n:] = A, B
    E = scipy.linalg.expm(M * T)
    return E[:n, :n], E[:n, n:]


class SMCLoop:
    """The controller and allocator of the module docstring, designed on ``vehicle`` at frame ``T``."""

    def __init__(self, vehicle: str | Path = VEHICLE_FILE, *, T: float, method: str = "qp",
                 design: dict[str, Any] | None = None, observer_input: str = "command") -> None:
        import alloc
        from alloc import vehicles
        from sim.blocks import observer_gain
        from sim.user_vehicle import flight_model

        if observer_input not in OBSERVER_INPUTS:
            raise AllocError(f"observer_input: {observer_input!r}; expected one of {', '.join(OBSERVER_INPUTS)}",
                             field="observer_input")
        self.observer_input = observer_input
        self.fv = vehicles.get_vehicle(vehicle)
        if tuple(self.fv.model.states) != STATES or tuple(self.fv.effector_names) != JSBSimPlant.effectors:
            raise AllocError(f"vehicle: {self.fv.name!r} is not a JSBSim F-22 model (states {STATES}, effectors "
                             f"{JSBSimPlant.effectors})", field="vehicle")
        self.fm = flight_model(self.fv, frame_period=T, design={**DESIGN_OPTIONS, **(design or {})})
        self.T, self.method = float(T), method
        A, B, C, D = self.fv.model.arrays()
        smc = self.fm.design.smc
        self.ctl = [list(self.fv.model.outputs).index(c) for c in self.fv.model.controlled]
        self.rho, self.eps = np.asarray(smc.rho, float), np.asarray(smc.eps, float)
        self.K0, self.Km1 = np.asarray(smc.K0, float), np.asarray(smc.Km1, float)
        self.demand_map = np.asarray(self.fm.design.demand_map, float)
        # observers: xh' = (A - G C) xh + (B - G D) u + G z, one per channel (seed section 3.3)
        self.obs = []
        for poles in smc.observer_poles:
            G = observer_gain(A, C, poles)
            Ad, Bd = _zoh(A - G @ C, np.hstack([B - G @ D, G]), self.T)
            self.obs.append((Ad, Bd))
        # reference models, controllable canonical form, discretised
        self.refs = []
        for num, den in self.fm.design.references:
            a, b, c, d = scipy.signal.tf2ss(num, den)
            Ad, Bd = _zoh(a, b, self.T)
            self.refs.append((Ad, Bd, c, d))
        self.problem = self.fv.problem()
        self.nominal = alloc.make_allocator(self.problem, method)
        self.allocator = self.nominal
        self.reset()

    def reset(self) -> None:
        n = len(STATES)
        self.xh = [np.zeros(n) for _ in self.obs]
        self.xr = [np.zeros(Ad.shape[0]) for Ad, *_ in self.refs]
        self.integ = np.zeros(len(self.ctl))
        self.u = np.zeros(self.problem.m)
        self.r = np.zeros(len(self.ctl))
        self.u_c = np.zeros(len(self.ctl))

    def tell(self, effector: str, kind: str, params: dict[str, float]) -> None:
        """Rebuild the allocator on the problem with this failure's health (a told allocator)."""
        import alloc
        from alloc.health import FailureEvent, apply_event

        i = self.problem.index(effector)
        lo, hi = float(self.problem.umin[i]), float(self.problem.umax[i])
        # the plant's limits are the file's to round-off (both are the stock limit minus the trim)
        params = {k: (min(max(v, lo), hi) if k in ("position", "lo", "hi") else v) for k, v in params.items()}
        _, health = apply_event(self.problem, {}, FailureEvent(effector, kind, **params))
        self.allocator = alloc.make_allocator(self.problem.with_health(health), self.method)

    def demand(self, y: np.ndarray, command: np.ndarray) -> np.ndarray:
        """A frame's control law up to the allocator: reference models, boundary-layer SMC (seed Eq 4.8) on the
        observers' estimates, the integral (frozen where saturated); returns ``v = demand_map u_c``."""
        r = np.empty(len(self.refs))
        for i, (Ad, Bd, c, d) in enumerate(self.refs):
            r[i] = float((c @ self.xr[i])[0] + d[0, 0] * command[i])
            self.xr[i] = Ad @ self.xr[i] + Bd[:, 0] * command[i]
        e = np.array([r[i] - self.xh[i][self.ctl[i]] for i in range(len(self.ctl))])
        sigma = self.K0 * e + self.Km1 * self.integ
        inside = np.abs(sigma) < self.eps
        self.u_c = self.rho * np.clip(sigma / self.eps, -1.0, 1.0)
        self.integ += np.where(inside, e, 0.0) * self.T
        self.r = r
        return self.demand_map @ self.u_c

    def observe(self, u: np.ndarray, y: np.ndarray, positions: np.ndarray | None = None) -> None:
        """A frame's observer update on the effector input (the command, or ``positions``) and outputs ``y``."""
        if self.observer_input == "position":
            if positions is None:
                raise AllocError("positions: observer_input='position' needs the plant's positions", field="positions")
            w = np.concatenate([positions, y])
        else:
            w = np.concatenate([u, y])
        for i, (Ad, Bd) in enumerate(self.obs):
            self.xh[i] = Ad @ self.xh[i] + Bd @ w
        self.u = u

    def step(self, y: np.ndarray, command: np.ndarray, positions: np.ndarray | None = None,
             ) -> tuple[np.ndarray, np.ndarray, str]:
        """One frame: outputs ``y``, channel commands and (``observer_input="position"``) the effector
        positions in; effector commands, ``v`` and the allocator's status out."""
        v = self.demand(y, command)
        res = self.allocator(v, u_prev=self.u, dt=self.T)
        u = np.asarray(res.u, dtype=float)
        self.observe(u, y, positions)
        return u, v, str(res.status.value)


@dataclass
class Flight:
    """A flight's record: named signals per frame, the failure as executed, whether it diverged."""

    t: np.ndarray
    outputs: np.ndarray
    commands: np.ndarray
    u_cmd: np.ndarray
    positions: np.ndarray
    v: np.ndarray
    status: list[str]
    diverged: bool
    wall_seconds: float
    output_names: tuple[str, ...] = STATES
    settings: dict[str, Any] = field(default_factory=dict)

    @property
    def real_time_factor(self) -> float:
        """Simulated seconds per wall-clock second (plant, controller and allocator together)."""
        return float(self.t[-1] / self.wall_seconds) if self.wall_seconds > 0 else math.inf

    def peak(self, name: str, after: float = 0.0) -> float:
        """Largest |deviation| of output ``name`` from time ``after`` on."""
        sel = self.t >= after
        return float(np.max(np.abs(self.outputs[sel, self.output_names.index(name)])))

    def rms_error(self, channel: str, after: float = 0.0) -> float:
        """RMS of command minus output on controlled ``channel`` from ``after`` on (deg/s)."""
        sel = self.t >= after
        i = CONTROLLED.index(channel)
        err = self.commands[sel, i] - self.outputs[sel, self.output_names.index(channel)]
        return float(np.sqrt(np.mean(err * err)))


def fly(*, duration: float = 20.0, method: str = "qp", failure: tuple[str, str, dict[str, float]] | None = None,
        failure_time: float = 5.0, told: bool = True, commands: Callable[[np.ndarray], np.ndarray] | None = doublets,
        plant: JSBSimPlant | None = None, vehicle: str | Path = VEHICLE_FILE, seed: int = 0,
        observer_input: str = "command") -> Flight:
    """Fly the F-22 for ``duration`` s; ``failure = (effector, kind, params)`` at ``failure_time``.

    ``commands(t) -> (len(t), 3)`` deg/s on q, p, r (default :func:`doublets`; None: hold trim).
    The frame is one JSBSim step of the plant.
    """
    if isinstance(duration, bool) or not isinstance(duration, (int, float)) or not 0 < duration <= 600:
        raise AllocError(f"duration: expected (0, 600] s, got {duration!r}", field="duration")
    plant = plant or JSBSimPlant()
    T = plant.h
    loop = SMCLoop(vehicle, T=T, method=method, observer_input=observer_input)
    n = int(round(duration / T))
    t = np.arange(n + 1) * T
    cmd = np.zeros((n + 1, len(CONTROLLED))) if commands is None else np.asarray(commands(t), dtype=float)
    if failure is not None:
        name, kind, params = failure
        if name not in plant.effectors:
            raise AllocError(f"failure: unknown effector {name!r}; effectors: {', '.join(plant.effectors)}",
                             field="failure")
    y = plant.reset(seed=seed)
    m = len(plant.effectors)
    Y, U, P, V = (np.zeros((n + 1, k)) for k in (len(STATES), m, m, len(CONTROLLED)))
    status: list[str] = []
    Y[0] = y
    failed = False
    diverged = False
    start = _time.perf_counter()
    k = 0
    for k in range(n):
        if failure is not None and not failed and t[k] >= failure_time - 1e-12:
            plant.fail(plant.effectors.index(name), kind, dict(params))
            if told:
                # tell what was executed: defaults filled in (a jam's position at the failure)
                executed = {p: v for p, v in plant.failures[-1].items() if p not in ("time", "effector", "kind")}
                loop.tell(name, kind, executed)
            failed = True
        u, v, st = loop.step(Y[k], cmd[k], plant.positions())
        U[k], V[k] = u, v
        status.append(st)
        Y[k + 1] = plant.step(u, T)
        P[k + 1] = plant.positions()
        if not np.all(np.isfinite(Y[k + 1])) or np.any(np.abs(Y[k + 1]) > OUTPUT_BOUND):
            diverged = True
            break
    wall = _time.perf_counter() - start
    end = k + 2 if diverged else n + 1
    return Flight(t=t[:end], outputs=Y[:end], commands=cmd[:end], u_cmd=U[:end], positions=P[:end], v=V[:end],
                  status=status, diverged=diverged, wall_seconds=wall,
                  settings={"method": method, "told": told, "failure": failure, "failure_time": failure_time,
                            "observer_input": observer_input,
                            "duration": duration, "frame": T, "plant": plant.describe(),
                            "design": {"K_rho": loop.fm.design.report["switching"]["K_rho"],
                                       "rho": loop.rho.tolist(), "eps": loop.eps.tolist(),
                                       "options": DESIGN_OPTIONS}})
