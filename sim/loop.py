"""Closed-loop engine shared by the MIMO scenarios (ICE, F-18/HARV).

Signal flow per step (seed Figs 3-26, 3-32, 4-85)::

    pilot -> command -> reference models -> r
    plant outputs + noise -> z -> observers (+ hedge) -> y_hat_h
    e = r - y_hat_h,  sigma = K0 e + K_-1 int(e),  u_c = rho sat(sigma/eps)
    v = demand_map u_c  ->  allocator  ->  u_cmd  ->  delay -> actuators -> plant

Linear controller dynamics (reference models, observers, hedge) are stacked
into one continuous system and discretised exactly once, so a step costs a
handful of small matrix-vector products plus the allocator call.  The loop-
shaped baseline replaces the SMC, observers and hedge by one linear
compensator per channel acting on ``r - y_measured``.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
from tqdm import tqdm

from sim.allocation import LoopAllocator, build_allocator
from sim.blocks import (
    ActuatorBank,
    ActuatorFailure,
    ActuatorSpec,
    DelayLine,
    DiscreteLTI,
    HedgeTerm,
    ScheduledPlant,
    band_limited_noise,
    hedge_system,
    observer_gain,
    smc_control,
    stack_lti,
    tf_to_ss,
)
from sim.result import SimResult, divergence_check

__all__ = ["Vehicle", "Failure", "SMCDesign", "LoopShapedDesign", "Pilot", "simulate"]

TF = tuple[Sequence[float], Sequence[float]]


@dataclass(frozen=True)
class Vehicle:
    """Linear vehicle model plus its allocation data.

    ``controlled`` are the output indices of the controlled variables (the
    channels, in the order of the pseudo-commands); ``measured`` the output
    indices fed to the observers.  ``B_alloc`` (k x m) is the effectiveness
    the allocator is given, ``demand_map`` (k x k) turns the SMC's pseudo-
    commands into allocator demands ``v``, ``Bk_seed`` is the seed's printed
    control distribution (for comparison and the ``static`` method).
    """

    name: str
    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    output_names: tuple[str, ...]
    actuators: tuple[ActuatorSpec, ...]
    controlled: tuple[int, ...]
    measured: tuple[int, ...]
    noise_gains: np.ndarray
    B_alloc: np.ndarray
    Bk_seed: np.ndarray
    demand_map: np.ndarray
    Wu: np.ndarray | None = None

    @property
    def channels(self) -> list[str]:
        return [self.output_names[i] for i in self.controlled]

    @property
    def effector_names(self) -> list[str]:
        return [a.name for a in self.actuators]

    @property
    def umin(self) -> np.ndarray:
        return np.array([a.lo for a in self.actuators])

    @property
    def umax(self) -> np.ndarray:
        return np.array([a.hi for a in self.actuators])

    @property
    def rate_max(self) -> np.ndarray:
        return np.array([a.rate for a in self.actuators])


@dataclass(frozen=True)
class Failure:
    """Failure injected at ``time``: plant (A, B) change, actuator failures, added delay."""

    name: str
    time: float
    description: str
    A: np.ndarray | None = None
    B: np.ndarray | None = None
    D: np.ndarray | None = None
    actuators: tuple[ActuatorFailure, ...] = ()
    #: actuator time delay after the failure (s): scalar or one per effector
    delay: float | np.ndarray | None = None


@dataclass(frozen=True)
class SMCDesign:
    """Observer-based SMC with simplified hedging, one channel per controlled variable.

    ``observer_poles[i]`` are the poles of channel ``i``'s full-order
    observer (seed section 3.3.2: one observer per channel), ``None`` to feed
    back the measured output instead (no observer, seed Fig 4-95).
    """

    rho: np.ndarray
    eps: np.ndarray | None
    K0: np.ndarray
    Km1: np.ndarray
    observer_poles: tuple[tuple[float, ...], ...] | None = None
    hedge_terms: tuple[HedgeTerm, ...] = ()
    hedge_gain: np.ndarray | None = None


@dataclass(frozen=True)
class LoopShapedDesign:
    """Diagonal linear compensators ``u_c[i] = G_i(s) (r[i] - y_meas[i])`` (seed Eq 4.28)."""

    compensators: tuple[TF, ...]


@dataclass(frozen=True)
class Pilot:
    """Crossover-model stand-in for the seed's pilot (Figs 4-6, 4-41, 4-86 are images).

    ``command[channel] = gain * (att_cmd(t - delay) - att(t - delay))`` with
    ``att = row @ y_measured`` (integrated if ``integrate``).  Not the seed's
    structural pilot model: its parameters are ours and documented where used.
    """

    channel: int
    row: np.ndarray
    attitude_command: Callable[[np.ndarray], np.ndarray]
    name: str
    gain: float = 2.0
    delay: float = 0.2
    integrate: bool = False


@dataclass
class _Recorder:
    n: int
    k: int
    m: int
    n_extra: int
    t: np.ndarray = field(init=False)

    def __post_init__(self) -> None:
        self.t = np.zeros(self.n)
        self.ref = np.zeros((self.n, self.k))
        self.out = np.zeros((self.n, self.k))
        self.cmd = np.zeros((self.n, self.k))
        self.pseudo = np.zeros((self.n, self.k))
        self.unalloc = np.zeros((self.n, self.k))
        self.eff = np.zeros((self.n, self.m))
        self.rate = np.zeros((self.n, self.m))
        self.extra = np.zeros((self.n, self.n_extra))
        self.lo = np.zeros((self.n, self.m))
        self.hi = np.zeros((self.n, self.m))
        self.rmax = np.zeros((self.n, self.m))
        self.count = 0


def _controller_system(
    vehicle: Vehicle, design: SMCDesign, references: Sequence[TF], dt: float
) -> tuple[DiscreteLTI, int]:
    """Stack reference models, observers and hedge into one discrete LTI.

    Input ``w = [command (k), u_cmd (m), z (nz), u_c (k)]``; output
    ``[r (k), y_hat (k), y_f (k)]``, all strictly proper.
    """
    k = len(vehicle.controlled)
    m = len(vehicle.actuators)
    nz = len(vehicle.measured)
    n_in = k + m + nz + k
    n_out = 3 * k
    systems, ins, outs = [], [], []
    for i, (num, den) in enumerate(references):
        S = np.zeros((1, n_in))
        S[0, i] = 1.0
        P = np.zeros((n_out, 1))
        P[i, 0] = 1.0
        systems.append(tf_to_ss(num, den))
        ins.append(S)
        outs.append(P)
    if design.observer_poles is not None:
        Cz = vehicle.C[list(vehicle.measured)]
        Dz = vehicle.D[list(vehicle.measured)]
        for i, poles in enumerate(design.observer_poles):
            G = observer_gain(vehicle.A, Cz, poles)  # seed section 3.3.2, one observer per channel
            a = vehicle.A - G @ Cz
            b = np.hstack([vehicle.B - G @ Dz, G])
            c = vehicle.C[[vehicle.controlled[i]]]
            S = np.zeros((m + nz, n_in))
            S[:, k : k + m + nz] = np.eye(m + nz)
            P = np.zeros((n_out, 1))
            P[k + i, 0] = 1.0
            systems.append((a, b, c, np.zeros((1, m + nz))))
            ins.append(S)
            outs.append(P)
    if design.hedge_terms:
        a, b, c, d = hedge_system(design.hedge_terms, k, design.hedge_gain)
        S = np.zeros((k, n_in))
        S[:, k + m + nz :] = np.eye(k)
        P = np.zeros((n_out, k))
        P[2 * k :, :] = np.eye(k)
        systems.append((a, b, c, d))
        ins.append(S)
        outs.append(P)
    A, B, C, D = stack_lti(systems, ins, outs, n_in, n_out)
    return DiscreteLTI(A, B, C, D, dt), n_in


def simulate(
    *,
    scenario: str,
    vehicle: Vehicle,
    references: Sequence[TF],
    controller: SMCDesign | LoopShapedDesign,
    commands: np.ndarray,
    pilots: Sequence[Pilot] = (),
    failure: Failure | None,
    method: str,
    method_options: dict | None = None,
    allocator_knows_failure: bool = False,
    rate_aware: bool = False,
    actuators: bool = True,
    noise: bool = True,
    duration: float,
    dt: float,
    seed: int,
    output_bound: float | np.ndarray = 1.0e3,
    record_every: int = 10,
    progress: bool = False,
) -> SimResult:
    """Run one closed loop.

    Parameters
    ----------
    commands : ndarray (N, k)
        Direct commands into the reference models for channels without a
        pilot (precomputed on the integration grid); pilot channels overwrite
        their column.
    actuators : bool
        False replaces the actuator bank by ideal effectors (command = position,
        limits still applied) -- the seed's "SMC without parasitic dynamics".
    output_bound : float
        Divergence bound on ``|controlled output|`` (see :mod:`sim.result`).
    """
    k = len(vehicle.controlled)
    m = len(vehicle.actuators)
    n_steps = int(round(duration / dt))
    rng = np.random.default_rng(seed)
    meas = np.asarray(vehicle.measured)
    ctrl = np.asarray(vehicle.controlled)
    # Noise on the measured outputs only, precomputed (vectorised filtering).
    ny = vehicle.C.shape[0]
    noise_all = np.zeros((n_steps + 1, ny))
    if noise:
        noise_all[:, meas] = band_limited_noise(n_steps + 1, dt, vehicle.noise_gains, rng)

    plant = ScheduledPlant(
        vehicle.A, vehicle.B, vehicle.C, vehicle.D, dt,
        A_fail=None if failure is None else failure.A,
        B_fail=None if failure is None else failure.B,
        D_fail=None if failure is None else failure.D,
    )
    bank = ActuatorBank(vehicle.actuators, dt)
    delay = DelayLine(m, dt, 0.0)
    allocator: LoopAllocator = build_allocator(vehicle, method, method_options or {}, rate_aware=rate_aware)

    smc = isinstance(controller, SMCDesign)
    if smc:
        ctl, n_in = _controller_system(vehicle, controller, references, dt)
        w = np.zeros(n_in)
        s_cmd, s_u, s_z, s_uc = slice(0, k), slice(k, k + m), slice(k + m, k + m + len(meas)), slice(k + m + len(meas), n_in)
        integ = np.zeros(k)
        rho, eps = controller.rho, controller.eps
        K0, Km1 = controller.K0, controller.Km1
        observed = controller.observer_poles is not None
    else:
        ref_sys = stack_lti(
            [tf_to_ss(n, d) for n, d in references],
            [np.eye(k)[[i]] for i in range(k)],
            [np.eye(k)[:, [i]] for i in range(k)],
            k, k,
        )
        ref = DiscreteLTI(*ref_sys, dt=dt)
        comp_sys = stack_lti(
            [tf_to_ss(n, d) for n, d in controller.compensators],
            [np.eye(k)[[i]] for i in range(k)],
            [np.eye(k)[:, [i]] for i in range(k)],
            k, k,
        )
        comp = DiscreteLTI(*comp_sys, dt=dt)

    pilot_delays = [DelayLine(1, dt, p.delay) for p in pilots]
    pilot_att = np.zeros(len(pilots))
    t_grid = np.arange(n_steps + 1) * dt
    pilot_cmds = [p.attitude_command(t_grid) for p in pilots]

    n_rec = n_steps // record_every + 1
    rec = _Recorder(n_rec, k, m, 2 * len(pilots))
    u_act = bank.pos.copy()
    u_cmd = np.zeros(m)
    uc = np.zeros(k)
    cmd = np.zeros(k)
    diverged = False
    t_fail = None if failure is None else failure.time
    failed = False
    iterator = range(n_steps + 1)
    if progress:
        iterator = tqdm(iterator, total=n_steps + 1, unit="step", mininterval=0.5, desc=scenario)
    for step in iterator:
        t = step * dt
        if t_fail is not None and not failed and t >= t_fail - 0.5 * dt:
            failed = True
            _inject(failure, plant, bank, delay)
            if allocator_knows_failure:
                allocator = build_allocator(
                    vehicle, method, method_options or {}, failure=failure, rate_aware=rate_aware
                )
        y_all = plant.output(u_act)
        z_all = y_all + noise_all[step]
        if divergence_check(y_all[ctrl], output_bound, plant.x):
            diverged = True
            break
        # Pilot (outer loop) and commands into the reference models.
        cmd[:] = commands[step]
        for j, p in enumerate(pilots):
            att = p.row @ z_all
            if p.integrate:
                pilot_att[j] += dt * att
                att = pilot_att[j]
            else:
                pilot_att[j] = att
            err = pilot_delays[j].push(np.array([pilot_cmds[j][step] - att]))
            cmd[p.channel] = p.gain * err[0]
        if smc:
            o = ctl.C @ ctl.x
            r = o[:k]
            y_fb = o[k : 2 * k] if observed else z_all[ctrl]
            e = r - (y_fb + o[2 * k :])
            sigma = K0 * e + Km1 * integ
            uc = smc_control(sigma, rho, eps)
        else:
            r = ref.C @ ref.x
            e = r - z_all[ctrl]
            uc = comp.step(e)
            ref.step(cmd)
        v = vehicle.demand_map @ uc
        u_cmd, unalloc = allocator(v, u_cmd, dt)
        if step % record_every == 0:
            i = rec.count
            rec.t[i] = t
            rec.ref[i] = r
            rec.out[i] = y_all[ctrl]
            rec.cmd[i] = cmd
            rec.pseudo[i] = uc
            rec.unalloc[i] = unalloc
            rec.eff[i] = u_act
            rec.rate[i] = bank.rate_out if step else 0.0
            rec.lo[i], rec.hi[i], rec.rmax[i] = bank.lo, bank.hi, bank.rmax
            for j, p in enumerate(pilots):
                rec.extra[i, 2 * j] = pilot_cmds[j][step]
                rec.extra[i, 2 * j + 1] = pilot_att[j]
            rec.count += 1
        if smc:
            w[s_cmd] = cmd
            w[s_u] = u_cmd
            w[s_z] = z_all[meas]
            w[s_uc] = uc
            ctl.x = ctl.Ad @ ctl.x + ctl.Bd @ w
            integ += dt * e
        plant.step(u_act)
        u_del = delay.push(u_cmd)
        u_act = bank.step(u_del) if actuators else np.clip(u_del, bank.lo, bank.hi)
        if not actuators:
            bank.rate_out = np.zeros(m)

    n = rec.count
    extra = {}
    for j, p in enumerate(pilots):
        extra[f"{p.name}_command"] = rec.extra[:n, 2 * j]
        extra[f"{p.name}"] = rec.extra[:n, 2 * j + 1]
    return SimResult(
        scenario=scenario,
        method=method,
        failure=None if failure is None else failure.name,
        t=rec.t[:n],
        channels=vehicle.channels,
        reference=rec.ref[:n],
        output=rec.out[:n],
        command=rec.cmd[:n],
        pseudo=rec.pseudo[:n],
        effectors=rec.eff[:n],
        effector_rates=rec.rate[:n],
        effector_names=vehicle.effector_names,
        # Limits as they were at each sample (failures change them).
        effector_limits=(rec.lo[:n], rec.hi[:n]),
        rate_limits=(-rec.rmax[:n], rec.rmax[:n]),
        failure_time=t_fail,
        diverged=diverged,
        unallocated=rec.unalloc[:n],
        extra=extra,
    )


def _inject(failure: Failure, plant: ScheduledPlant, bank: ActuatorBank, delay: DelayLine) -> None:
    """Apply a failure to the plant, the actuators and the actuator delay."""
    eff = np.ones(bank.m)
    for f in failure.actuators:
        if f.kind == "float":
            eff[f.index] = 0.0
        elif f.kind == "effectiveness":
            eff[f.index] = float(f.fraction)
        else:
            bank.apply_failure(f)
    plant.fail(effectiveness=eff)
    if failure.delay is not None:
        delay.set_delay(failure.delay)
