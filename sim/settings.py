"""What a closed-loop run is given: :class:`LoopSpec`, and the rules its settings name.

The rules of the SMC at a frame period (:func:`anti_windup_on`, :func:`boundary_layer_at`)
live here with the names they accept.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from sim.blocks import DEFAULT_DT
from sim.model import TF, Failure, LoopShapedDesign, Pilot, SMCDesign, Vehicle

__all__ = ["LoopSpec", "U_PREV_SOURCES", "BOUNDARY_LAYER_RULES", "ANTI_WINDUP_RULES", "SEED_FRAME_PERIOD",
           "anti_windup_on", "boundary_layer_at"]


@dataclass(frozen=True)
class LoopSpec:
    """Everything one closed-loop run needs (the argument of :func:`sim.engine.simulate`).

    Attributes
    ----------
    scenario : str
        Name recorded in the result.
    vehicle, references, controller, pilots, failure
        The vehicle, the reference models (one transfer function per channel),
        the SMC or loop-shaped design, the pilot models and the failure (or None).
    commands : ndarray (N, k)
        Direct commands into the reference models for channels without a
        pilot (precomputed on the integration grid); pilot channels overwrite
        their column.
    method, method_options
        Allocation method (any registry method, or ``static``) and its options.
    allocator_knows_failure : bool
        Rebuild the allocator on the "told" problem at the failure
        (:func:`sim.allocation.allocation_problem`).
    rate_aware : bool
        Give the allocator ``u_prev`` and ``dt = frame_period`` so seed Eq 1.28
        bounds each command change by ``rate * T``.
    u_prev_source : {"command", "position"}
        What the allocator is told as ``u_prev``: its own previous command (the
        seed's reading of Eq 1.28, ``u_k`` being the last commanded control; the
        seed's controllers have no effector position feedback) or the measured
        actuator positions at the frame.
    actuators : bool
        False replaces the actuator bank by ideal effectors (command = position,
        limits still applied) -- the seed's "SMC without parasitic dynamics".
    noise : bool
        Band-limited sensor noise on the measured outputs (seed gains).
    duration, dt
        Simulated seconds and the integration step of plant and actuators.
    frame_period : float or None
        Period ``T`` of the flight-control computer (pilot sampling, reference
        models, observers, SMC, hedges, allocator); a multiple of ``dt``,
        outputs held between frames.  None: ``T = dt`` (the seed's single-rate loop).
    rate_window : {"binding", "always"}
        When the allocator is given the Eq 1.28 box (:func:`sim.allocation.build_allocator`).
    anti_windup : {"auto", "on", "off"}
        Hold the SMC's integral term in frames the allocator fell short
        (:func:`anti_windup_on`; ``"auto"``: on slower than the seed's rate).
    boundary_layer : {"frame", "fixed"}
        SMC boundary layer at ``T``: scaled to keep the seed's per-frame
        switching gain (``eps * max(1, T / 0.5 ms)``, default) or the seed's
        ``eps`` unchanged (:func:`boundary_layer_at`).
    seed : int
        Noise seed.
    output_bound : float or ndarray
        Divergence bound on ``|controlled output|`` (see :mod:`sim.result`).
    record_every : int
        Record every n-th integration step.
    """

    scenario: str
    vehicle: Vehicle
    references: Sequence[TF]
    controller: SMCDesign | LoopShapedDesign
    commands: np.ndarray
    failure: Failure | None
    method: str
    duration: float
    dt: float
    seed: int
    pilots: Sequence[Pilot] = ()
    method_options: dict | None = None
    allocator_knows_failure: bool = False
    rate_aware: bool = True
    u_prev_source: str = "command"
    #: preferred-position rule for one-sided effectors (:func:`sim.allocation.preferred_positions`)
    preferred: str = "mid"
    #: horizon of the Eq 1.28 rate box, ``"actuator"`` or ``"frame"`` (:func:`sim.allocation.build_allocator`)
    rate_horizon: str = "actuator"
    #: when the allocator is given the Eq 1.28 box, ``"binding"`` or ``"always"`` (:func:`sim.allocation.build_allocator`)
    rate_window: str = "binding"
    #: conditional integration of the SMC integral term, ``"auto"``, ``"on"`` or ``"off"`` (:func:`anti_windup_on`)
    anti_windup: str = "auto"
    #: boundary layer at the frame period, ``"frame"`` or ``"fixed"`` (:func:`boundary_layer_at`)
    boundary_layer: str = "frame"
    actuators: bool = True
    noise: bool = True
    frame_period: float | None = None
    output_bound: float | np.ndarray = 1.0e3
    record_every: int = 10

    def frame_steps(self) -> int:
        """Integration steps per flight-control frame (``T / dt``, an integer >= 1)."""
        if self.frame_period is None:
            return 1
        ratio = self.frame_period / self.dt
        n = int(round(ratio))
        if n < 1 or abs(ratio - n) > 1e-9 * max(1.0, ratio):
            raise ValueError(f"frame_period: {self.frame_period!r} s is not a positive multiple of dt = {self.dt!r} s")
        return n


#: ``u_prev`` the allocator may be told (see :class:`LoopSpec`).
U_PREV_SOURCES = ("command", "position")

#: Rules for the SMC boundary layer at a frame period ``T`` (see :func:`boundary_layer_at`).
BOUNDARY_LAYER_RULES = ("frame", "fixed")

#: Frame period the seed's boundary layers were chosen at: its Simulink step (seed section 4.5,
#: "fixed time step of dt = 0.0005 sec"; section 4.3 step 6 picks eps in that simulation).
SEED_FRAME_PERIOD = DEFAULT_DT


#: Rules for the SMC's integral term when the allocator falls short (see :func:`anti_windup_on`).
ANTI_WINDUP_RULES = ("auto", "on", "off")


def anti_windup_on(rule: str, frame_period: float) -> bool:
    """Whether the SMC integrates its error in a frame where the allocator fell short of ``v``.

    ``sigma = K0 e + K_-1 int(e)`` (seed Eq 4.7) integrates the tracking error of
    the observer, which is driven by the command actually allocated.  When the
    allocator cannot meet the demand (Eq 1.28's rate box binding, position
    limits), ``e`` persists, ``int(e)`` winds up and ``u_c`` rails at ``rho``:
    the seed's hedging is driven by ``u_c`` (Eqs 3.17-3.18), not by the
    allocator's shortfall, so nothing in the seed's loop unwinds it.  ``"on"``
    is conditional integration, the textbook anti-windup: ``int(e)`` is held in
    every frame whose allocation was not exact (``alloc``'s test,
    ``max|v - B u| <= 1e-6 max(1, max|v|)``).  ``"off"`` is the seed's law.
    ``"auto"`` (default): on when the frame period is longer than the seed's
    0.5 ms, off at the seed's rate (seed runs bit-identical).
    """
    if rule not in ANTI_WINDUP_RULES:
        raise ValueError(f"anti_windup: {rule!r}; expected one of {ANTI_WINDUP_RULES}")
    if rule == "auto":
        return frame_period > SEED_FRAME_PERIOD * (1.0 + 1e-9)
    return rule == "on"


def boundary_layer_at(eps: np.ndarray, frame_period: float, rule: str = "frame") -> np.ndarray:
    """Boundary-layer thickness of the SMC at frame period ``T``.

    Sampled at ``T`` and held, the linear region of ``u_c = rho sat(sigma / eps)``
    is a discrete loop ``sigma_{j+1} ~ (1 - T g rho / eps) sigma_j`` (``g``: the
    sliding variable's rate per unit ``u_c``); quasi-sliding is stable only for
    ``T g rho / eps < 2``.  The seed chose ``eps`` at ``T_seed = 0.5 ms``
    (section 4.3 step 6, section 4.5), where that per-frame gain is 0.45-0.51
    on ICE; at 100 Hz it is 9-10 and the loop chatters and diverges.

    ``"frame"`` (default) keeps the seed's per-frame gain:
    ``eps_T = eps * max(1, T / T_seed)`` (``rho`` unchanged, so the
    continuous-time equivalent gain ``rho / eps`` falls as ``1 / T``);
    ``"fixed"`` keeps the seed's ``eps`` at every rate.  At ``T <= T_seed``
    both return ``eps`` itself (seed runs bit-identical).
    """
    if rule not in BOUNDARY_LAYER_RULES:
        raise ValueError(f"boundary_layer: {rule!r}; expected one of {BOUNDARY_LAYER_RULES}")
    ratio = frame_period / SEED_FRAME_PERIOD
    if rule == "fixed" or ratio <= 1.0 + 1e-9:
        return eps
    return eps * ratio
