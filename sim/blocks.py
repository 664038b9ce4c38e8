"""Building blocks of the closed-loop simulator.

Linear blocks are discretised exactly once (zero-order hold, ``scipy.signal.
cont2discrete``) so the hot loop is one matrix-vector product per block;
nonlinear blocks (actuators with rate and position limits) are stepped with
Heun's method (Simulink ODE2, as in the seed: "ODE2 solver using a fixed time
step of dt = 0.0005 sec", seed section 4.5), by a numba-compiled kernel
(:func:`actuator_heun_step`) that the loop engine also calls directly.

Every block here is independent of any vehicle; the vehicles in
:mod:`sim.vehicles` and the engine in :mod:`sim.engine` assemble them.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace

import numpy as np
import alloc._engine._kernel_cache  # noqa: F401 - kernel caches placed before any kernel is decorated
from numba import njit
from scipy import signal

from alloc.exceptions import ProblemError
from alloc.health import Effect, check_parameters, resolve_defaults
from sim.actuator_failure import ActuatorFailure

__all__ = [
    "DEFAULT_DT",
    "DiscreteLTI",
    "tf_to_ss",
    "tf_sum_to_ss",
    "stack_lti",
    "ActuatorSpec",
    "ActuatorFailure",
    "ActuatorBank",
    "actuator_heun_step",
    "DelayLine",
    "ScheduledPlant",
    "smc_control",
    "observer_gain",
    "HedgeTerm",
    "hedge_system",
    "band_limited_noise",
    "sum_of_sines",
    "SUM_OF_SINES_TABLE_4_2",
]

#: Fixed integration step, seed section 4.5 ("dt = 0.0005 sec").
DEFAULT_DT = 0.0005


# --------------------------------------------------------------------------- LTI
def tf_to_ss(num: Sequence[float], den: Sequence[float]) -> tuple[np.ndarray, ...]:
    """State-space (A, B, C, D) of a SISO transfer function ``num/den``."""
    a, b, c, d = signal.tf2ss(np.atleast_1d(num), np.atleast_1d(den))
    return a, b, c, d


def tf_sum_to_ss(terms: Sequence[tuple[Sequence[float], Sequence[float]]]) -> tuple[np.ndarray, ...]:
    """State space of a product of SISO transfer functions given as (num, den) pairs."""
    num = np.array([1.0])
    den = np.array([1.0])
    for n, d in terms:
        num = np.polymul(num, n)
        den = np.polymul(den, d)
    return tf_to_ss(num, den)


def stack_lti(
    systems: Sequence[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]],
    input_maps: Sequence[np.ndarray],
    output_maps: Sequence[np.ndarray],
    n_in: int,
    n_out: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Block-diagonal stack of continuous LTI systems sharing one input and output vector.

    System ``i`` reads ``input_maps[i] @ w`` and adds ``output_maps[i] @ y_i``
    to the stacked output, where ``w`` has ``n_in`` entries and the stacked
    output ``n_out``.
    """
    n = sum(s[0].shape[0] for s in systems)
    A = np.zeros((n, n))
    B = np.zeros((n, n_in))
    C = np.zeros((n_out, n))
    D = np.zeros((n_out, n_in))
    i = 0
    for (a, b, c, d), S, P in zip(systems, input_maps, output_maps, strict=True):
        k = a.shape[0]
        A[i : i + k, i : i + k] = a
        B[i : i + k] = b @ S
        C[:, i : i + k] = P @ c
        D += P @ d @ S
        i += k
    return A, B, C, D


@dataclass
class DiscreteLTI:
    """Exact (zero-order-hold) discretisation of ``x' = A x + B u, y = C x + D u``.

    Examples
    --------
    >>> lti = DiscreteLTI.from_tf([100.0], [1.0, 20.0, 100.0], dt=0.0005)
    >>> y = lti.step(np.array([1.0]))
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    dt: float
    x: np.ndarray = field(init=False)

    def __post_init__(self) -> None:
        self.A = np.atleast_2d(np.asarray(self.A, dtype=float))
        n = self.A.shape[0]
        self.B = np.asarray(self.B, dtype=float).reshape(n, -1)
        self.C = np.asarray(self.C, dtype=float).reshape(-1, n)
        self.D = np.asarray(self.D, dtype=float).reshape(self.C.shape[0], self.B.shape[1])
        if n:
            ad, bd, *_ = signal.cont2discrete((self.A, self.B, self.C, self.D), self.dt, method="zoh")
        else:
            ad, bd = self.A, self.B
        self.Ad = np.ascontiguousarray(ad)
        self.Bd = np.ascontiguousarray(bd)
        self.x = np.zeros(n)

    @classmethod
    def from_tf(cls, num: Sequence[float], den: Sequence[float], dt: float) -> DiscreteLTI:
        return cls(*tf_to_ss(num, den), dt=dt)

    def output(self, u: np.ndarray) -> np.ndarray:
        """``C x + D u`` at the current state."""
        return self.C @ self.x + self.D @ u

    def step(self, u: np.ndarray) -> np.ndarray:
        """Return the output at the current sample, then advance one step with ``u`` held."""
        y = self.C @ self.x + self.D @ u
        self.x = self.Ad @ self.x + self.Bd @ u
        return y

    def reset(self) -> None:
        self.x[:] = 0.0


# --------------------------------------------------------------------- actuators
@dataclass(frozen=True)
class ActuatorSpec:
    """One actuator: linear dynamics, position limits [lo, hi], symmetric rate limit.

    ``order == 2``: ``wn2 / (s^2 + c1 s + wn2)`` (the seed's ``(a)(b)/((s+a)(s+b))``
    of Table 4-5 is ``wn2 = a b``, ``c1 = a + b``); ``order == 1``:
    ``a / (s + a)`` with ``a = c1``.
    """

    name: str
    order: int
    wn2: float
    c1: float
    lo: float
    hi: float
    rate: float

    @classmethod
    def two_real_poles(cls, name: str, a: float, b: float, lo: float, hi: float, rate: float) -> ActuatorSpec:
        """``a b / ((s + a)(s + b))`` (seed Table 4-5 form)."""
        return cls(name, 2, a * b, a + b, lo, hi, rate)

    @classmethod
    def second_order(cls, name: str, wn: float, zeta: float, lo: float, hi: float, rate: float) -> ActuatorSpec:
        """``wn^2 / (s^2 + 2 zeta wn s + wn^2)`` (seed Tables 4-1, 4-3 form)."""
        return cls(name, 2, wn * wn, 2.0 * zeta * wn, lo, hi, rate)

    @classmethod
    def first_order(cls, name: str, a: float, lo: float, hi: float, rate: float) -> ActuatorSpec:
        return cls(name, 1, 0.0, a, lo, hi, rate)

    @property
    def wn(self) -> float:
        """Undamped natural frequency (rad/s); the pole for first order."""
        return float(np.sqrt(self.wn2)) if self.order == 2 else self.c1

    def with_bandwidth(self, wn: float) -> ActuatorSpec:
        """Same damping, natural frequency ``wn`` (seed section 4.7 failure list)."""
        if self.order == 1:
            return replace(self, c1=wn)
        scale = wn / self.wn
        return replace(self, wn2=self.wn2 * scale * scale, c1=self.c1 * scale)


class ActuatorBank:
    """Vectorised bank of rate- and position-limited actuators, Heun-stepped.

    State per effector: position and rate.  For second-order actuators
    ``pos'' = wn2 (u - pos) - c1 pos'``; the rate state is clipped to the rate
    limit and the position to the position limits (a limited actuator stops,
    it does not bounce).  For first-order actuators the rate is algebraic,
    ``pos' = sat_rate(c1 (u - pos))``.
    """

    def __init__(self, specs: Sequence[ActuatorSpec], dt: float) -> None:
        self.dt = float(dt)
        self.names = [s.name for s in specs]
        self.m = len(specs)
        self.pos = np.zeros(self.m)
        self.rate = np.zeros(self.m)
        self.jammed = np.zeros(self.m, dtype=bool)
        self.jam_pos = np.zeros(self.m)
        self.hardover = np.zeros(self.m, dtype=bool)
        self.hard_pos = np.zeros(self.m)
        self.rate_out = np.zeros(self.m)
        #: control power left per effector (the plant scales its columns of B and D by it)
        self.effectiveness = np.ones(self.m)
        self.nominal = list(specs)
        self.set_specs(specs)

    def set_specs(self, specs: Sequence[ActuatorSpec]) -> None:
        self.specs = list(specs)
        self.first = np.array([s.order == 1 for s in specs])
        self.wn2 = np.array([s.wn2 for s in specs], dtype=float)
        self.c1 = np.array([s.c1 for s in specs], dtype=float)
        self.lo = np.array([s.lo for s in specs], dtype=float)
        self.hi = np.array([s.hi for s in specs], dtype=float)
        self.rmax = np.array([s.rate for s in specs], dtype=float)

    @property
    def limits(self) -> tuple[np.ndarray, np.ndarray]:
        return self.lo.copy(), self.hi.copy()

    def apply_failure(self, f: ActuatorFailure) -> ActuatorFailure:
        """Execute the effects of ``f``'s kind on its actuator, in order; return ``f`` as executed.

        Positions and rate limits are checked against the actuator's nominal ones (ProblemError
        naming the parameter), as the library checks what it is told.

        The returned failure has every default filled in (a jam without ``position`` holds the
        position the actuator has now, a hard-over runs to its nominal upper limit), so a told
        allocator is told the same numbers.  Effectiveness (``trail``, ``scale``) is
        :attr:`effectiveness`, which the plant applies.
        """
        i = f.index
        if not 0 <= i < self.m:
            raise ProblemError(f"index: effector {i} out of range for {self.m} actuators")
        nominal = self.nominal[i]
        params = resolve_defaults(f.spec, f.params, limits=(nominal.lo, nominal.hi), position=float(self.pos[i]))
        check_parameters(f.kind, params, effector=nominal.name, limits=(nominal.lo, nominal.hi),
                         rate_limits=(-nominal.rate, nominal.rate))
        for effect in f.spec.effects:
            _EFFECTS[effect](self, i, params)
        self.set_specs(self.specs)
        return ActuatorFailure(i, f.kind, **params)

    def _hold(self, i: int, p: dict[str, float]) -> None:
        self.jammed[i] = True
        self.jam_pos[i] = p["position"]
        self.pos[i] = self.jam_pos[i]
        self.rate[i] = 0.0

    def _run_to_stop(self, i: int, p: dict[str, float]) -> None:
        self.hardover[i] = True
        self.hard_pos[i] = p["position"]

    def _trail(self, i: int, p: dict[str, float]) -> None:
        self.effectiveness[i] = 0.0

    def _scale(self, i: int, p: dict[str, float]) -> None:
        self.effectiveness[i] = p["fraction"]

    def _limits(self, i: int, p: dict[str, float]) -> None:
        self.specs[i] = replace(self.specs[i], lo=p["lo"], hi=p["hi"])

    def _rate_limits(self, i: int, p: dict[str, float]) -> None:
        self.specs[i] = replace(self.specs[i], rate=p["rate_max"])  # symmetric (ActuatorFailure checks)

    def _repair(self, i: int, p: dict[str, float]) -> None:
        self.specs[i] = self.nominal[i]
        self.jammed[i] = self.hardover[i] = False
        self.effectiveness[i] = 1.0

    def _bandwidth(self, i: int, p: dict[str, float]) -> None:
        self.specs[i] = self.specs[i].with_bandwidth(p["wn"])

    def step(self, u: np.ndarray) -> np.ndarray:
        """Advance one step with command ``u`` held; return the new positions."""
        self.rate_out = np.empty(self.m)
        actuator_heun_step(
            self.pos, self.rate, self.rate_out, np.asarray(u, dtype=float), self.first, self.wn2, self.c1,
            self.lo, self.hi, self.rmax, self.jammed, self.jam_pos, self.hardover, self.hard_pos, self.dt,
        )
        return self.pos.copy()


#: how the bank executes each per-actuator effect (``delay`` acts on the whole failure: the injection's)
_EFFECTS: dict[Effect, Callable[[ActuatorBank, int, dict[str, float]], None]] = {
    Effect.HOLD: ActuatorBank._hold, Effect.RUN_TO_STOP: ActuatorBank._run_to_stop, Effect.TRAIL: ActuatorBank._trail,
    Effect.SCALE: ActuatorBank._scale, Effect.LIMITS: ActuatorBank._limits, Effect.RATE_LIMITS: ActuatorBank._rate_limits,
    Effect.REPAIR: ActuatorBank._repair, Effect.BANDWIDTH: ActuatorBank._bandwidth,
}
if set(_EFFECTS) != set(Effect) - {Effect.DELAY}:  # a new effect without its execution fails at import
    raise ImportError(f"sim.blocks: no actuator execution for {sorted(e.name for e in set(Effect) - set(_EFFECTS))}")


@njit(cache=True, inline="always")
def _actuator_slope(first: bool, c1: float, wn2: float, u: float, p: float, r: float, rm: float) -> tuple[float, float]:
    """Heun stage of one actuator: (rate-limited ``pos'``, ``rate'``) at position ``p``, rate ``r``."""
    if first:
        return min(max(c1 * (u - p), -rm), rm), 0.0
    return min(max(r, -rm), rm), wn2 * (u - p) - c1 * r


@njit(cache=True)
def actuator_heun_step(
    pos: np.ndarray,
    rate: np.ndarray,
    rate_out: np.ndarray,
    u: np.ndarray,
    first: np.ndarray,
    wn2: np.ndarray,
    c1: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    rmax: np.ndarray,
    jammed: np.ndarray,
    jam_pos: np.ndarray,
    hardover: np.ndarray,
    hard_pos: np.ndarray,
    dt: float,
) -> None:
    """One Heun (ODE2) step of a bank of limited actuators, in place on ``pos``, ``rate``, ``rate_out``.

    Second order: ``pos' = sat_rate(rate)``, ``rate' = wn2 (u - pos) - c1 rate``
    with the rate state clipped to ``+-rmax``; first order: ``pos' =
    sat_rate(c1 (u - pos))``.  After the step the position is clipped to
    ``[lo, hi]`` and a rate pushing outwards is zeroed (a limited actuator
    stops, it does not bounce).  A hard-over effector follows ``hard_pos``
    instead of ``u``; a jammed one stays at ``jam_pos`` with zero rate.
    ``rate_out`` is the reported rate (algebraic for first order).  The
    arithmetic is elementwise in the order of the numpy formulation, so the
    result is identical to it to the last bit.
    """
    for i in range(pos.size):
        ui = hard_pos[i] if hardover[i] else u[i]
        p0 = pos[i]
        r0 = rate[i]
        rm = rmax[i]
        v1, a1 = _actuator_slope(first[i], c1[i], wn2[i], ui, p0, r0, rm)
        p1 = p0 + dt * v1
        r1 = min(max(r0 + dt * a1, -rm), rm)
        v2, a2 = _actuator_slope(first[i], c1[i], wn2[i], ui, p1, r1, rm)
        p2 = p0 + 0.5 * dt * (v1 + v2)
        r2 = min(max(r0 + 0.5 * dt * (a1 + a2), -rm), rm)
        if (p2 <= lo[i] and r2 < 0.0) or (p2 >= hi[i] and r2 > 0.0):
            r2 = 0.0
        p2 = min(max(p2, lo[i]), hi[i])
        if jammed[i]:
            p2 = jam_pos[i]
            r2 = 0.0
        rate_out[i] = (p2 - p0) / dt if first[i] else r2
        pos[i] = p2
        rate[i] = r2


class DelayLine:
    """Pure time delay of ``round(delay / dt)`` steps on a vector signal (ring buffer).

    ``delay`` may be a scalar or one value per component.
    """

    def __init__(self, width: int, dt: float, delay: float | np.ndarray = 0.0) -> None:
        self.width = width
        self.dt = dt
        self._last = np.zeros(width)
        self.set_delay(delay)

    def set_delay(self, delay: float | np.ndarray) -> None:
        """Change the delay; the buffer is pre-filled with the last value pushed."""
        self.n = np.broadcast_to(np.rint(np.asarray(delay, dtype=float) / self.dt).astype(int), (self.width,)).copy()
        self._len = int(self.n.max()) + 1
        self._buf = np.tile(self._last, (self._len, 1))
        self._cols = np.arange(self.width)
        self._i = 0

    def push(self, u: np.ndarray) -> np.ndarray:
        """Store ``u`` and return, per component, the value pushed ``n`` steps ago."""
        self._last = u
        if self._len == 1:
            return u
        self._buf[self._i] = u
        out = self._buf[(self._i - self.n) % self._len, self._cols]
        self._i = (self._i + 1) % self._len
        return out


# ------------------------------------------------------------------------- plant
class ScheduledPlant:
    """LTI plant ``x' = A x + B u`` whose (A, B) switch once at a failure time.

    Outputs ``y = C x + D u`` use the nominal C and the (possibly failed) D.
    Both models are discretised exactly with ZOH on ``u``.
    """

    def __init__(
        self,
        A: np.ndarray,
        B: np.ndarray,
        C: np.ndarray,
        D: np.ndarray,
        dt: float,
        A_fail: np.ndarray | None = None,
        B_fail: np.ndarray | None = None,
        D_fail: np.ndarray | None = None,
    ) -> None:
        self.C = np.asarray(C, dtype=float)
        self.D = np.asarray(D, dtype=float)
        self._nominal = DiscreteLTI(A, B, C, D, dt)
        self.A_fail = A if A_fail is None else A_fail
        self.B_fail = B if B_fail is None else B_fail
        self.D_fail = D if D_fail is None else D_fail
        self._failed: DiscreteLTI | None = None
        self.x = np.zeros(np.asarray(A).shape[0])
        self._cur = self._nominal

    def fail(self, effectiveness: np.ndarray | None = None) -> None:
        """Switch to the failed model; ``effectiveness`` scales B and D columns."""
        B = np.array(self.B_fail, dtype=float)
        D = np.array(self.D_fail, dtype=float)
        if effectiveness is not None:
            B = B * effectiveness
            D = D * effectiveness
        self._failed = DiscreteLTI(self.A_fail, B, self.C, D, self._nominal.dt)
        self.D = D
        self._cur = self._failed

    @property
    def Ad(self) -> np.ndarray:
        """Discrete state matrix of the current (nominal or failed) model."""
        return self._cur.Ad

    @property
    def Bd(self) -> np.ndarray:
        """Discrete input matrix of the current (nominal or failed) model."""
        return self._cur.Bd

    def output(self, u: np.ndarray) -> np.ndarray:
        return self.C @ self.x + self.D @ u

    def step(self, u: np.ndarray) -> None:
        self.x = self._cur.Ad @ self.x + self._cur.Bd @ u


# ---------------------------------------------------------------- sliding mode
def smc_control(sigma: np.ndarray, rho: np.ndarray, eps: np.ndarray | None) -> np.ndarray:
    """Sliding-mode control law, seed Eq 4.2 / 4.8.

    ``rho * sat(sigma / eps)`` with a boundary layer, ``rho * sign(sigma)``
    when ``eps`` is None.  ``sigma = K0 e + K_-1 int(e)`` (seed Eq 4.7, 4.20,
    4.25 for relative degree one) is formed by the caller.
    """
    if eps is None:
        return rho * np.sign(sigma)
    return rho * np.clip(sigma / eps, -1.0, 1.0)


def observer_gain(A: np.ndarray, C: np.ndarray, poles: Sequence[float]) -> np.ndarray:
    """Luenberger gain G with eig(A - G C) = poles (seed section 3.3, by duality)."""
    res = signal.place_poles(np.asarray(A).T, np.asarray(C).T, np.asarray(poles, dtype=float))
    return res.gain_matrix.T


# ------------------------------------------------------------------------ hedge
@dataclass(frozen=True)
class HedgeTerm:
    """One simplified hedge path (seed Eqs 3.17-3.18, Table 4-6).

    ``out`` receives ``gain * s/(s + a_f) * b_h/(s^2 + a_h s + b_h) * u_c[inp]``;
    ``gain`` includes any cross-term factor printed in the seed's table but not
    the per-channel hedge gain K_h, which :func:`hedge_system` applies.
    """

    out: int
    inp: int
    a_f: float
    a_h: float
    b_h: float
    gain: float = 1.0


def hedge_system(terms: Sequence[HedgeTerm], k: int, hedge_gain: Sequence[float]) -> tuple[np.ndarray, ...]:
    """Continuous state space from pseudo-commands ``u_c`` (k) to hedge signals ``y_f`` (k).

    Channel ``i`` output is ``K_h[i] * sum(terms with out == i)`` (seed
    section 3.4.3: the cross-term hedge signal is added to the primary one;
    Eq 3.16: ``y_f = G_f K_h y_h``).
    """
    systems, ins, outs = [], [], []
    for term in terms:
        a, b, c, d = tf_sum_to_ss([([1.0, 0.0], [1.0, term.a_f]), ([term.b_h], [1.0, term.a_h, term.b_h])])
        S = np.zeros((1, k))
        S[0, term.inp] = 1.0
        P = np.zeros((k, 1))
        P[term.out, 0] = term.gain * hedge_gain[term.out]
        systems.append((a, b, c, d))
        ins.append(S)
        outs.append(P)
    if not systems:
        return np.zeros((0, 0)), np.zeros((0, k)), np.zeros((k, 0)), np.zeros((k, k))
    return stack_lti(systems, ins, outs, k, k)


# ------------------------------------------------------------------ excitations
def band_limited_noise(
    n_steps: int,
    dt: float,
    gains: np.ndarray,
    rng: np.random.Generator,
    *,
    power: float = 0.1,
    sample_time: float = 0.01,
) -> np.ndarray:
    """Measurement noise: band-limited white noise through ``100/(s^2 + 20 s + 100)``, times gains.

    Models Simulink's Band-Limited White Noise block (Gaussian samples of
    variance ``power / sample_time`` held for ``sample_time``) followed by the
    seed's shaping filter (section 4.5, 4.6, 4.7).  ``power = 0.1`` (the
    block's default) reproduces the seed's printed RMS: gain 0.1414 gives
    about 0.07 and gain 0.0707 about 0.035 (seed section 4.6).

    Returns an array (n_steps, len(gains)).
    """
    gains = np.asarray(gains, dtype=float)
    hold = max(1, int(round(sample_time / dt)))
    n_samples = n_steps // hold + 2
    white = rng.standard_normal((n_samples, gains.size)) * np.sqrt(power / sample_time)
    held = np.repeat(white, hold, axis=0)[:n_steps]
    num, den, _ = signal.cont2discrete(([100.0], [1.0, 20.0, 100.0]), dt, method="zoh")
    filtered = signal.lfilter(np.ravel(num), den, held, axis=0)
    return filtered * gains


#: Sum-of-sines amplitudes and frequencies (rad/s), seed Table 4-2.
SUM_OF_SINES_TABLE_4_2 = (
    (-1.00, 0.19947),
    (1.00, 0.49867),
    (1.00, 0.89760),
    (0.50, 1.39626),
    (-0.20, 2.39359),
    (0.20, 4.19970),
    (-0.08, 8.97598),
)


def sum_of_sines(t: np.ndarray, xi: float, *, phase_step: float = 0.0) -> np.ndarray:
    """Pilot command, seed Eq 4.13 with Table 4-2, faded in by ``0.8/(s + 0.8)``.

    ``xi * sum_i A_i sin(w_i t + i * phase_step) * (1 - exp(-0.8 t))``; the
    factor is a unit step through ``0.8/(s + 0.8)`` (seed section 4.5).  The
    ICE roll channel uses ``phase_step = pi/4`` (seed section 4.7).
    """
    t = np.asarray(t, dtype=float)
    total = np.zeros_like(t)
    for i, (amp, w) in enumerate(SUM_OF_SINES_TABLE_4_2, start=1):
        total += amp * np.sin(w * t + i * phase_step)
    return xi * total * (1.0 - np.exp(-0.8 * t))
