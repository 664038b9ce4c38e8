"""The closed loop linearised at an operating point, and its stability margins.

The loop is sampled data: the flight-control computer (pilot sampling, reference models,
observers, hedge, SMC, allocator) runs once per frame ``T`` and holds its command, the plant,
actuator delay and actuators integrate every ``dt`` in between (:mod:`sim.engine`).  The
linear model is therefore a discrete-time system at the frame period ``T``:
:class:`FrameLoop` is one frame of the loop written in numpy on the engine's own matrices
(:func:`sim.engine._pack`: the plant's ZOH matrices at ``dt``, the controller stacked and
discretised at ``T``, the pilot's delay ring in frames), the actuators stepped by the same
:func:`sim.blocks.actuator_heun_step` ``T / dt`` times with the command held, and the allocator
the same :func:`sim.allocation.build_allocator` callable the engine calls.  Its delays are
exact discrete delays (rings of ``dt`` steps for the actuator delay, of frames for the
pilot), not Padé approximations.

:func:`linearise` takes the Jacobian of that frame map by central differences at an
operating point.  Every nonlinearity is then taken as it is *at* that point, frozen:

* the SMC's ``rho sat(sigma / eps)`` is its linear region ``rho / eps`` where
  ``|sigma| < eps`` (seed Eq 4.8) and contributes nothing where it is saturated;
* the allocator is its local linear map ``du/dv`` (and ``du/du_prev``): an effector on a
  position or rate limit, or outside the active set, has a zero column;
* an actuator on its rate or position limit passes no perturbation (its rate clip binds);
* the anti-windup switch keeps the state it has at the point.

The loop can be broken at the actuator inputs (the plant gets the injected ``u``, the
controller keeps its own command for its observers and ``u_prev``) and at the pilot's
command (the reference model gets the injected command).  :func:`margins` then gives
loop-at-a-time gain and phase margins (:func:`gain_phase_margins`, checked against
``control.stability_margins``), the SISO disk margin
of each loop, and for the MIMO loop at the actuator inputs the minimum singular value of the
return difference ``I + L`` over the frequency axis up to Nyquist and the unstructured disk
margin (a lower bound of the structured one: slycot's mu is not installed).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import scipy.linalg

from alloc.exceptions import AllocError
from sim.allocation import build_allocator
from sim.blocks import ActuatorBank, DelayLine, ScheduledPlant, actuator_heun_step
from sim.engine import _pack
from sim.injection import inject_failure
from sim.model import SMCDesign
from sim.packed import FloatSlot, IntSlot, Misc
from sim.settings import LoopSpec

__all__ = ["gain_phase_margins", "FrameLoop", "LinearLoop", "LoopMargins", "LinearisationError", "linearise", "margins",
           "local_map", "operating_point", "after_failure"]

#: Relative step of the central differences (linear parts are exact to round-off at it).
FD_STEP = 1e-6


class LinearisationError(AllocError, ValueError):
    """The loop cannot be linearised as asked (a bad operating point or break point)."""


def local_map(allocator: Any, v: np.ndarray, u_prev: np.ndarray, T: float, *, step: float = FD_STEP,
              ) -> tuple[np.ndarray, np.ndarray]:
    """The allocator's local linear map at ``(v, u_prev)``: ``(du/dv, du/du_prev)`` by central differences.

    A saturated effector (on a position limit, or on the Eq 1.28 rate box) keeps its value under
    a small perturbation of ``v``, so its row is zero; the active set is the one at the point.
    """
    v = np.asarray(v, dtype=float)
    u_prev = np.asarray(u_prev, dtype=float)
    cols_v = []
    for j in range(v.size):
        h = step * max(1.0, abs(v[j]))
        dv = np.zeros(v.size)
        dv[j] = h
        cols_v.append((allocator(v + dv, u_prev, T)[0] - allocator(v - dv, u_prev, T)[0]) / (2 * h))
    cols_p = []
    for j in range(u_prev.size):
        h = step * max(1.0, abs(u_prev[j]))
        dp = np.zeros(u_prev.size)
        dp[j] = h
        cols_p.append((allocator(v, u_prev + dp, T)[0] - allocator(v, u_prev - dp, T)[0]) / (2 * h))
    return np.column_stack(cols_v), np.column_stack(cols_p)


class FrameLoop:
    """One frame of the closed loop as a map of a flat state vector (the engine's matrices).

    ``step(X, cmd, u_in=None, p_in=None)`` advances one frame; ``u_in`` replaces the command the
    actuators get (loop broken at the actuator inputs), ``p_in`` the pilot's command into its
    reference model (loop broken at the pilot).  Returns ``(X_next, outputs)`` with outputs
    ``u`` (the allocator's command), ``p`` (the pilot's command), ``y`` (controlled outputs at
    the frame start), ``v``, ``short`` (the allocator fell short of ``v``).

    ``failed``: the loop after the spec's failure (injected at construction; the allocator told
    of it when the spec's health mode is ``told``).
    """

    def __init__(self, spec: LoopSpec, *, failed: bool = False) -> None:
        if not isinstance(spec.controller, SMCDesign) and spec.pilots and any(p.integrate for p in spec.pilots):
            raise LinearisationError("pilots: an integrating pilot is not modelled")
        self.spec = spec
        v = spec.vehicle
        self.N = spec.frame_steps()
        self.dt = spec.dt
        self.T = self.N * spec.dt
        self.k, self.m, self.ny = len(v.controlled), len(v.actuators), v.C.shape[0]
        f = spec.failure if failed else None
        if failed and f is None:
            raise LinearisationError("failure: the spec has none to linearise after")
        plant = ScheduledPlant(v.A, v.B, v.C, v.D, spec.dt, A_fail=None if f is None else f.A,
                               B_fail=None if f is None else f.B, D_fail=None if f is None else f.D)
        bank = ActuatorBank(v.actuators, spec.dt)
        delay = DelayLine(self.m, spec.dt, 0.0)
        packed = _pack(replace(spec, failure=f), plant, bank, delay, self.N, 1, 2)
        bank.pos, bank.rate = packed.view(FloatSlot.POS), packed.view(FloatSlot.RATE)
        options = dict(rate_aware=spec.rate_aware, preferred=spec.preferred, frame_period=self.T,
                       rate_horizon=spec.rate_horizon, rate_window=spec.rate_window)
        told = None
        if f is not None:
            told = inject_failure(f, plant, bank, delay, packed, np.zeros(self.m))
        self.allocator = build_allocator(v, spec.method, spec.method_options or {},
                                         failure=told if spec.health_mode == "told" else None, **options)
        self.P = {s: packed.view(s).copy() for s in list(FloatSlot) + list(IntSlot)}
        misc = self.P[IntSlot.MISC]
        self.smc = bool(misc[Misc.SMC])
        self.observed = bool(misc[Misc.OBSERVED])
        self.sign = bool(misc[Misc.SIGN])
        self.anti_windup = bool(misc[Misc.ANTI_WINDUP])
        self.actuators = bool(misc[Misc.ACTUATORS])
        self.pfilter = bool(misc[Misc.PFILTER])
        self.dn = self.P[IntSlot.DN].astype(int)
        self.pn = self.P[IntSlot.PN].astype(int)
        self.position_feedback = spec.u_prev_source == "position"
        # flat state layout: name -> (slice, shape)
        P = self.P
        parts = [("x", P[FloatSlot.X].shape), ("pos", (self.m,)), ("rate", (self.m,)), ("uact", (self.m,)),
                 ("dhist", (-(-int(self.dn.max()) // self.N), self.m)), ("xc", P[FloatSlot.XC].shape),
                 ("xk", P[FloatSlot.XK].shape), ("integ", (self.k,)),
                 ("phist", (int(self.pn.max(initial=0)), len(spec.pilots))), ("pxf", P[FloatSlot.PXF].shape),
                 ("uprev", (self.m,))]
        self.layout: dict[str, tuple[slice, tuple[int, ...]]] = {}
        at = 0
        for name, shape in parts:
            size = int(np.prod(shape))
            self.layout[name] = (slice(at, at + size), shape)
            at += size
        self.n_states = at

    def initial_state(self) -> np.ndarray:
        """The state the engine starts from (after the failure, its injected actuator state)."""
        X = np.zeros(self.n_states)
        self.part(X, "pos")[:] = self.P[FloatSlot.POS]
        self.part(X, "rate")[:] = self.P[FloatSlot.RATE]
        self.part(X, "uact")[:] = self.P[FloatSlot.UACT] if not self.actuators else self.P[FloatSlot.POS]
        return X

    def part(self, X: np.ndarray, name: str) -> np.ndarray:
        """The named part of the flat state ``X`` (a view)."""
        sl, shape = self.layout[name]
        return X[sl].reshape(shape)

    def step(self, X: np.ndarray, cmd: np.ndarray, att_cmd: np.ndarray | None = None,
             u_in: np.ndarray | None = None, p_in: np.ndarray | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        """One frame from state ``X`` (see the class docstring); ``cmd`` direct commands, ``att_cmd`` pilots'."""
        P, k = self.P, self.k
        X = X.copy()
        x, pos, rate, uact = (self.part(X, n) for n in ("x", "pos", "rate", "uact"))
        ctrl, meas = P[IntSlot.CTRL].astype(int), P[IntSlot.MEAS].astype(int)
        z = P[FloatSlot.C] @ x + P[FloatSlot.D] @ uact
        cmd = np.array(cmd, dtype=float)
        p_out = np.zeros(len(self.spec.pilots))
        if self.spec.pilots:
            att = P[FloatSlot.PROW] @ z
            err = (np.zeros_like(att) if att_cmd is None else np.asarray(att_cmd, dtype=float)) - att
            hist = self.part(X, "phist")
            delayed = np.array([err[j] if self.pn[j] == 0 else hist[self.pn[j] - 1, j] for j in range(err.size)])
            if hist.shape[0]:
                hist[1:] = hist[:-1].copy()
                hist[0] = err
            out = delayed
            if self.pfilter:
                pxf = self.part(X, "pxf")
                out = P[FloatSlot.PCF] @ pxf + P[FloatSlot.PDF] @ delayed
                pxf[:] = P[FloatSlot.PAF] @ pxf + P[FloatSlot.PBF] @ delayed
            p_out = P[FloatSlot.PGAIN] * out
            chans = P[IntSlot.PCHAN].astype(int)
            cmd[chans] = p_out if p_in is None else np.asarray(p_in, dtype=float)
        xc, integ = self.part(X, "xc"), self.part(X, "integ")
        if self.smc:
            o = P[FloatSlot.CC] @ xc
            y_fb = o[k:2 * k] if self.observed else z[ctrl]
            e = o[:k] - (y_fb + o[2 * k:])
            sigma = P[FloatSlot.K0] * e + P[FloatSlot.KM1] * integ
            rho, eps = P[FloatSlot.RHO], P[FloatSlot.EPS]
            uc = rho * np.sign(sigma) if self.sign else rho * np.clip(sigma / eps, -1.0, 1.0)
        else:
            e = P[FloatSlot.CC] @ xc - z[ctrl]
            xk = self.part(X, "xk")
            uc = P[FloatSlot.CK] @ xk + P[FloatSlot.DK] @ e
            xk[:] = P[FloatSlot.AK] @ xk + P[FloatSlot.BK] @ e
            xc[:] = P[FloatSlot.ADC] @ xc + P[FloatSlot.BDC] @ cmd
        v = P[FloatSlot.DEMAND] @ uc
        u_prev = pos.copy() if self.position_feedback else self.part(X, "uprev").copy()
        u_out, v_ach, _ = self.allocator(v, u_prev, self.T)
        u_out = np.asarray(u_out, dtype=float)
        short = not np.max(np.abs(v_ach - v), initial=0.0) <= 1e-6 * max(1.0, np.max(np.abs(v), initial=0.0))
        if self.smc:
            w = np.concatenate([cmd, u_out, z[meas], uc])  # the observers get the controller's own command
            xc[:] = P[FloatSlot.ADC] @ xc + P[FloatSlot.BDC] @ w
            if not (self.anti_windup and short):
                integ += self.T * e
        self.part(X, "uprev")[:] = u_out
        applied = u_out if u_in is None else np.asarray(u_in, dtype=float)
        self._fast_steps(X, applied)
        return X, {"u": u_out, "p": p_out, "y": z[ctrl], "v": v, "short": short, "z": z}

    def _fast_steps(self, X: np.ndarray, u_cmd: np.ndarray) -> None:
        """``T / dt`` integration steps of plant, delay and actuators with ``u_cmd`` held (engine order).

        The actuator delay of ``n`` steps is kept at frame resolution: with the command held over
        each frame, step ``j`` of this frame gets this frame's command when ``j >= n``, else the
        command of ``ceil((n - j) / N)`` frames ago (exactly the engine's ring of ``dt`` steps).
        """
        P = self.P
        x, pos, rate, uact, hist = (self.part(X, n) for n in ("x", "pos", "rate", "uact", "dhist"))
        rate_out = np.zeros(self.m)
        cols = np.arange(self.m)
        for j in range(self.N):
            x[:] = P[FloatSlot.AD] @ x + P[FloatSlot.BD] @ uact
            udel = u_cmd.copy()
            late = self.dn > j
            if np.any(late):
                udel[late] = hist[-(-(self.dn[late] - j) // self.N) - 1, cols[late]]
            if self.actuators:
                p, r = pos.copy(), rate.copy()
                actuator_heun_step(p, r, rate_out, udel, P[IntSlot.FIRST].astype(np.int64), P[FloatSlot.WN2],
                                   P[FloatSlot.C1], P[FloatSlot.LO], P[FloatSlot.HI], P[FloatSlot.RMAX],
                                   P[IntSlot.JAMMED].astype(np.int64), P[FloatSlot.JAM_POS],
                                   P[IntSlot.HARDOVER].astype(np.int64), P[FloatSlot.HARD_POS], self.dt)
                pos[:], rate[:] = p, r
                uact[:] = p
            else:
                uact[:] = np.clip(udel, P[FloatSlot.LO], P[FloatSlot.HI])
        if hist.shape[0]:
            hist[1:] = hist[:-1].copy()
            hist[0] = u_cmd

    def run(self, X: np.ndarray, n_frames: int, cmd: np.ndarray | None = None,
            att_cmd: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """``n_frames`` frames from ``X``; ``cmd`` (n_frames, k) and ``att_cmd`` (n_frames, pilots) per frame.

        Returns the final state and the controlled outputs at each frame start (n_frames, k).
        """
        ys = np.zeros((n_frames, self.k))
        for i in range(n_frames):
            X, out = self.step(X, np.zeros(self.k) if cmd is None else cmd[i],
                               None if att_cmd is None else att_cmd[i])
            ys[i] = out["y"]
        return X, ys


@dataclass(frozen=True)
class LinearLoop:
    """The loop's frame map linearised at ``X0``: ``dX' = A dX + B_cmd dcmd + B_u du_in + B_p dp_in``.

    ``C_u``, ``C_p``, ``C_y``: the allocator's command, the pilot's command and the controlled outputs
    at the frame start, each ``C dX`` (no feedthrough: a frame's outputs are computed from its
    start state).  ``A`` is the closed loop; ``A_u`` the loop broken at the actuator inputs
    (closed: ``A = A_u + B_u C_u``); ``A_p`` broken at the pilot.
    """

    T: float
    X0: np.ndarray
    A: np.ndarray
    A_u: np.ndarray
    A_p: np.ndarray
    B_cmd: np.ndarray
    B_u: np.ndarray
    B_p: np.ndarray
    C_u: np.ndarray
    C_p: np.ndarray
    C_y: np.ndarray
    #: the allocator's local map at the point, ``du/dv`` and ``du/du_prev``
    J_v: np.ndarray
    J_prev: np.ndarray
    #: ``|F(X0) - X0|`` inf-norm: 0 at an equilibrium
    residual: float
    #: the SMC channels whose boundary layer is saturated at the point
    saturated_channels: tuple[int, ...]

    @property
    def spectral_radius(self) -> float:
        """Largest |eigenvalue| of the closed-loop frame map (< 1: locally stable)."""
        return float(np.max(np.abs(np.linalg.eigvals(self.A))))

    def step_response(self, channel: int, size: float, n_frames: int) -> np.ndarray:
        """Controlled outputs' deviation (n_frames, k) after a step ``size`` on direct command ``channel``."""
        dX = np.zeros(self.A.shape[0])
        out = np.zeros((n_frames, self.C_y.shape[0]))
        for i in range(n_frames):
            out[i] = self.C_y @ dX
            dX = self.A @ dX + self.B_cmd[:, channel] * size
        return out


def _jacobian(fun: Any, x0: np.ndarray, step: float) -> np.ndarray:
    """Central-difference Jacobian of ``fun`` (returning one flat array) at ``x0``."""
    cols = []
    for j in range(x0.size):
        h = step * max(1.0, abs(x0[j]))
        d = np.zeros(x0.size)
        d[j] = h
        cols.append((fun(x0 + d) - fun(x0 - d)) / (2 * h))
    return np.column_stack(cols) if cols else np.zeros((fun(x0).size, 0))


def operating_point(loop: FrameLoop, *, settle: float = 0.0, iterations: int = 4,
                    step: float = FD_STEP) -> np.ndarray:
    """The trim: the loop's equilibrium with zero inputs, ``F(X) = X``.

    Starts with the effectors (and ``u_prev``) at the allocator's answer to ``v = 0`` (the
    one-sided ones at their preferred mid-range; the engine starts them at 0 and the rate
    limits make that move last seconds), a jammed or hard-over effector where its failure holds
    it, flies ``settle`` seconds with zero inputs, then takes chord-Newton steps
    ``X <- X - (A - I)^+ (F(X) - X)`` with ``A`` the frame map's Jacobian at the start (least
    squares: integrators nothing feeds back, ``|eigenvalue| = 1``, leave ``A - I`` singular).
    An unstable loop has an equilibrium too; the simulator never stays at it, the linear model
    says why.  ``LinearLoop.residual`` tells how nearly the point is one.
    """
    X = loop.initial_state()
    pos = loop.part(X, "pos")
    held = (loop.P[IntSlot.JAMMED] != 0) | (loop.P[IntSlot.HARDOVER] != 0)
    u = pos.copy()
    for _ in range(50):  # the rate box around u_prev lets the answer reach its place in steps
        u_next = np.asarray(loop.allocator(np.zeros(loop.k), u, loop.T)[0], dtype=float)
        if np.array_equal(u_next, u):
            break
        u = u_next
    free = ~held
    for name in ("pos", "uact"):
        loop.part(X, name)[free] = np.clip(u, loop.P[FloatSlot.LO], loop.P[FloatSlot.HI])[free]
    loop.part(X, "uprev")[:] = u
    if settle > 0:
        X, _ = loop.run(X, int(round(settle / loop.T)))
    cmd0 = np.zeros(loop.k)
    F = lambda Y: loop.step(Y, cmd0)[0]  # noqa: E731
    J = _jacobian(F, X, step) - np.eye(loop.n_states)
    r = F(X) - X
    for _ in range(iterations):
        if np.max(np.abs(r)) < 1e-12:
            break
        trial = X - np.linalg.lstsq(J, r, rcond=1e-10)[0]
        r_trial = F(trial) - trial
        if not np.max(np.abs(r_trial)) < np.max(np.abs(r)):
            break  # a non-smooth map (a limit, an active-set change) between here and there: keep the point
        X, r = trial, r_trial
    return X


def after_failure(nominal: FrameLoop, failed: FrameLoop, X: np.ndarray, seconds: float = 1.0) -> np.ndarray:
    """The failed loop's state ``seconds`` after its failure struck the nominal loop at state ``X``, no input.

    The failure's actuator changes (a jam's position) come from the failed loop's start state;
    its delay ring starts at the last command (as the engine pre-fills it).
    """
    Y = failed.initial_state()
    held = (failed.P[IntSlot.JAMMED] != 0) | (failed.P[IntSlot.HARDOVER] != 0)
    for name in ("x", "xc", "xk", "integ", "phist", "pxf", "uprev"):
        failed.part(Y, name)[:] = nominal.part(X, name)
    for name in ("pos", "rate", "uact"):
        failed.part(Y, name)[~held] = nominal.part(X, name)[~held]
    failed.part(Y, "dhist")[:] = nominal.part(X, "uprev")
    Y, _ = failed.run(Y, int(round(seconds / failed.T)))
    return Y


def linearise(loop: FrameLoop, X0: np.ndarray, *, step: float = FD_STEP) -> LinearLoop:
    """The frame map's Jacobians at ``X0`` with zero inputs (the module docstring's frozen nonlinearities)."""
    X0 = np.asarray(X0, dtype=float)
    if X0.shape != (loop.n_states,) or not np.all(np.isfinite(X0)):
        raise LinearisationError(f"X0: expected {loop.n_states} finite states, got shape {X0.shape}")
    k, n_x = loop.k, loop.n_states
    cmd0 = np.zeros(k)
    _, out0 = loop.step(X0, cmd0)
    u0, p0 = out0["u"], out0["p"]
    n_u, n_p = u0.size, p0.size

    def closed(X: np.ndarray) -> np.ndarray:
        X1, out = loop.step(X, cmd0)
        return np.concatenate([X1, out["u"], out["p"], out["y"]])

    # one sweep: the closed loop's map and every output row; the broken loops follow from
    # X' = F(X, u_in = g(X)), so A = A_u + B_u C_u (and the same at the pilot)
    J = _jacobian(closed, X0, step)
    A, C_u, C_p, C_y = J[:n_x], J[n_x:n_x + n_u], J[n_x + n_u:n_x + n_u + n_p], J[n_x + n_u + n_p:]
    B_u = _jacobian(lambda u: loop.step(X0, cmd0, u_in=u)[0], u0, step)
    B_cmd = _jacobian(lambda c: loop.step(X0, c)[0], cmd0, step)
    B_p = _jacobian(lambda p: loop.step(X0, cmd0, p_in=p)[0], p0, step) if n_p else np.zeros((n_x, 0))
    A_u, A_p = A - B_u @ C_u, A - B_p @ C_p
    X1, out = loop.step(X0, cmd0)
    u_prev = loop.part(X0, "pos") if loop.position_feedback else loop.part(X0, "uprev")
    J_v, J_prev = local_map(loop.allocator, out["v"], u_prev, loop.T, step=step)
    saturated = ()
    if loop.smc and not loop.sign:
        P = loop.P
        xc, integ = loop.part(X0, "xc"), loop.part(X0, "integ")
        o = P[FloatSlot.CC] @ xc
        y_fb = o[k:2 * k] if loop.observed else out["z"][P[IntSlot.CTRL].astype(int)]
        sigma = P[FloatSlot.K0] * (o[:k] - (y_fb + o[2 * k:])) + P[FloatSlot.KM1] * integ
        saturated = tuple(int(i) for i in np.nonzero(np.abs(sigma) >= P[FloatSlot.EPS])[0])
    return LinearLoop(T=loop.T, X0=X0, A=A, A_u=A_u, A_p=A_p, B_cmd=B_cmd, B_u=B_u, B_p=B_p, C_u=C_u, C_p=C_p,
                      C_y=C_y, J_v=J_v, J_prev=J_prev, residual=float(np.max(np.abs(X1 - X0))),
                      saturated_channels=saturated)


@dataclass(frozen=True)
class LoopMargins:
    """Margins of one linearised loop.

    ``gain_margin_db`` / ``phase_margin_deg``: per actuator channel, loop at a time (that channel
    broken, the others closed), ``inf`` where the loop never crosses (no phase or gain crossover);
    ``disk_margin``: per channel, the SISO balanced disk margin ``alpha`` (0 when the closed loop is
    unstable); ``sigma_min``: min over frequency of the return difference's smallest singular value
    at the actuator inputs; ``mimo_disk_margin``: ``1 / max sigma_max(S - I/2)`` (unstructured);
    ``pilot_*``: the same at the pilot's command.  Channels whose effector passes nothing at the
    point (a zero loop) are ``nan``.
    """

    spectral_radius: float
    gain_margin_db: np.ndarray
    phase_margin_deg: np.ndarray
    disk_margin: np.ndarray
    sigma_min: float
    mimo_disk_margin: float
    pilot_gain_margin_db: float
    pilot_phase_margin_deg: float
    pilot_disk_margin: float

    @property
    def stable(self) -> bool:
        return self.spectral_radius < 1.0

    @property
    def worst_channel_disk_margin(self) -> float:
        d = self.disk_margin[np.isfinite(self.disk_margin)]
        return float(d.min()) if d.size else math.nan


def _frequency_grid(T: float, n: int = 500) -> np.ndarray:
    nyquist = math.pi / T
    return np.logspace(math.log10(min(0.01, nyquist / 100)), math.log10(nyquist * 0.999), n)


def _unit_circle_response(A: np.ndarray, B: np.ndarray, C: np.ndarray, z: np.ndarray) -> np.ndarray:
    """``C (z I - A)^{-1} B`` at every ``z``, shape (len(z), outputs, inputs).

    Through the complex Schur form ``A = Q U Q^H`` (stable with the delay rings' nilpotent
    blocks), then one back substitution over all frequencies at once: ``einsum`` loops in C
    without BLAS threads, which on a loaded machine cost far more than these small products.
    """
    U, Q = scipy.linalg.schur(A.astype(complex), output="complex")
    QB = Q.conj().T @ B
    n = A.shape[0]
    X = np.zeros((z.size, n, B.shape[1]), dtype=complex)
    for i in range(n - 1, -1, -1):
        acc = np.broadcast_to(QB[i], (z.size, B.shape[1])).astype(complex)
        if i + 1 < n:
            acc = acc + np.einsum("j,fjm->fm", U[i, i + 1:], X[:, i + 1:, :])
        X[:, i, :] = acc / (z - U[i, i])[:, None]
    return np.einsum("oj,fjm->fom", C @ Q, X)


def gain_phase_margins(L: np.ndarray, w: np.ndarray) -> tuple[float, float]:
    """Gain margin (dB) and phase margin (deg) of a negative-feedback loop sampled as ``L`` on ``w``.

    At a phase crossover (``L`` real and negative) the gain margin is ``1 / |L|``: of all such
    crossings the one nearest 0 dB, its sign kept (negative: a gain *reduction* by that much
    destabilises a conditionally stable loop).  At a gain crossover (``|L| = 1``) the phase
    margin is ``180 + arg L``, the smallest over the crossings.  ``inf`` where there is no
    crossing.  Crossings are interpolated linearly between samples; the unit test checks the
    result against ``control.stability_margins``.
    """
    gm_db = pm = math.inf
    re, im, mag = L.real, L.imag, np.abs(L)
    for f in np.nonzero(np.sign(im[:-1]) * np.sign(im[1:]) < 0)[0]:
        t = im[f] / (im[f] - im[f + 1])
        x = re[f] + t * (re[f + 1] - re[f])
        if x < 0:
            db = -20 * math.log10(-x)
            gm_db = db if abs(db) < abs(gm_db) else gm_db
    for f in np.nonzero((mag[:-1] - 1.0) * (mag[1:] - 1.0) < 0)[0]:
        t = (mag[f] - 1.0) / (mag[f] - mag[f + 1])
        Lc = L[f] + t * (L[f + 1] - L[f])
        pm = min(pm, abs(math.degrees(np.angle(-Lc))))
    return gm_db, pm


def _siso_margins(L: np.ndarray, w: np.ndarray, closed_stable: bool) -> tuple[float, float, float]:
    """(gain margin dB, phase margin deg, balanced disk margin) of the loop sampled as ``L`` on ``w``."""
    if not np.any(np.abs(L) > 1e-12):
        return math.nan, math.nan, math.nan
    gm_db, pm = gain_phase_margins(L, w)
    alpha = float(1.0 / np.max(np.abs(1.0 / (1.0 + L) - 0.5))) if closed_stable else 0.0
    return gm_db, pm, alpha


def margins(lin: LinearLoop, *, n_frequencies: int = 500) -> LoopMargins:
    """Stability margins of the linearised loop at the actuator inputs and at the pilot (class docstring).

    With ``M(z) = C_u (zI - A_u)^-1 B_u`` (the loop closes ``u_in = u_out = M u_in``), the MIMO
    negative-feedback loop is ``L = -M``; channel ``i`` with the others closed is
    ``M_ii + M_io (I - M_oo)^-1 M_oi``.
    """
    w = _frequency_grid(lin.T, n_frequencies)
    z = np.exp(1j * w * lin.T)
    stable = lin.spectral_radius < 1.0
    m = lin.B_u.shape[1]
    M = _unit_circle_response(lin.A_u, lin.B_u, lin.C_u, z)
    eye = np.eye(m)
    gm, pm, dm = np.full(m, math.nan), np.full(m, math.nan), np.full(m, math.nan)
    for i in range(m):
        o = [j for j in range(m) if j != i]
        closed_others = np.linalg.solve(np.eye(m - 1) - M[:, o][:, :, o], M[:, o, i][:, :, None])[:, :, 0]
        Li = -(M[:, i, i] + np.einsum("fj,fj->f", M[:, i, o], closed_others))
        gm[i], pm[i], dm[i] = _siso_margins(Li, w, stable)
    sig_min = float(min(np.linalg.svd(eye - Mf, compute_uv=False).min() for Mf in M))
    if stable:
        worst = max(np.linalg.svd(np.linalg.inv(eye - Mf) - 0.5 * eye, compute_uv=False).max() for Mf in M)
        mimo_dm = float(1.0 / worst)
    else:
        mimo_dm = 0.0
    if lin.B_p.shape[1]:
        Lp = -_unit_circle_response(lin.A_p, lin.B_p[:, :1], lin.C_p[:1], z)[:, 0, 0]
        pg, pp, pd = _siso_margins(Lp, w, stable)
    else:
        pg = pp = pd = math.nan
    return LoopMargins(spectral_radius=lin.spectral_radius, gain_margin_db=gm, phase_margin_deg=pm,
                       disk_margin=dm, sigma_min=sig_min, mimo_disk_margin=mimo_dm, pilot_gain_margin_db=pg,
                       pilot_phase_margin_deg=pp, pilot_disk_margin=pd)
