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

Speed: everything but the allocator runs in two numba-compiled functions on
packed state (:class:`_Packed`): :func:`_observe` (outputs, divergence check,
pilots, controller, demand ``v``) and :func:`_advance` (record, integrate the
controller, plant, delay and actuators, then observe the next step).  The
Python loop is ``allocator(v)`` then one ``_advance`` call per step; failure
injection and allocator rebuilds stay in Python.  The compiled step repeats
the numpy formulation operation for operation (``np.dot`` is the BLAS call
numpy's ``@`` makes), so results are identical to the last bit.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np
from numba import njit
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
    actuator_heun_step,
    band_limited_noise,
    hedge_system,
    observer_gain,
    stack_lti,
    tf_to_ss,
)
from sim.result import SimResult

__all__ = ["Vehicle", "Failure", "SMCDesign", "LoopShapedDesign", "Pilot", "simulate", "step_timer"]

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


# ------------------------------------------------------------- packed state
# Every array the compiled step touches lives in one float64 buffer ``F`` or
# one int64 buffer ``I``: numba unboxes each call argument (about 0.2 us per
# array), so the step takes two buffers instead of some fifty arrays.  Slot
# ``s`` is described by ``I[3 s : 3 s + 3] = (offset, rows, cols)``; float
# slots index ``F``, int slots (numbered after them) index ``I``.

# plant: state, ZOH matrices, output matrices, effector positions it sees
(_F_X, _F_AD, _F_BD, _F_C, _F_D, _F_UACT,
 # controller: SMC system (reference models, observers, hedge) or, loop-shaped,
 # the reference models (XC..CC) and the compensators (XK..DK)
 _F_XC, _F_ADC, _F_BDC, _F_CC, _F_XK, _F_AK, _F_BK, _F_CK, _F_DK,
 _F_INTEG, _F_K0, _F_KM1, _F_RHO, _F_EPS, _F_DEMAND, _F_BOUND, _F_DT,
 # actuator bank (ActuatorBank arrays) and the actuator delay ring buffer
 _F_POS, _F_RATE, _F_RATE_OUT, _F_WN2, _F_C1, _F_LO, _F_HI, _F_RMAX, _F_JAM_POS, _F_HARD_POS, _F_DBUF,
 # pilots: output rows, gains, attitudes, delay ring buffers (one column each)
 _F_PROW, _F_PGAIN, _F_PATT, _F_PBUF,
 # signals of the current step
 _F_Y, _F_Z, _F_CMD, _F_R, _F_E, _F_UC, _F_V, _F_W, _F_UDEL,
 # controller outputs [r, y_hat, y_f]; two scratch rows for matrix-vector products
 _F_O, _F_SCRATCH,
 _N_FLOAT_SLOTS) = range(50)

(_I_FIRST, _I_JAMMED, _I_HARDOVER, _I_DN, _I_DSTATE,
 _I_PN, _I_PLEN, _I_PIDX, _I_PCHAN, _I_PINT, _I_MEAS, _I_CTRL, _I_MISC,
 _N_SLOTS) = range(_N_FLOAT_SLOTS, _N_FLOAT_SLOTS + 14)

# _I_MISC entries
(_M_N_STEPS, _M_RECORD_EVERY, _M_FAIL_STEP, _M_SMC, _M_OBSERVED, _M_SIGN, _M_ACTUATORS, _N_MISC) = range(8)
# _I_DSTATE entries: ring index, ring length (DelayLine semantics)
_D_INDEX, _D_LENGTH = 0, 1

# step status
_OK, _DIVERGED, _PENDING = 0, 1, 2


class _Packed:
    """The two buffers of the compiled step, with named numpy views for Python.

    ``floats`` and ``ints`` map slot -> array; ``view(slot)`` is a writable
    view with the array's shape (failure injection writes through it).
    """

    def __init__(self, floats: dict[int, np.ndarray], ints: dict[int, np.ndarray]) -> None:
        arrays = {**floats, **ints}
        if sorted(floats) != list(range(_N_FLOAT_SLOTS)) or sorted(arrays) != list(range(_N_SLOTS)):
            raise ValueError("every slot must be given exactly once")
        self._shapes = {slot: np.shape(a) for slot, a in arrays.items()}
        header = 3 * _N_SLOTS
        table = np.zeros((_N_SLOTS, 3), dtype=np.int64)
        end = [0, header]  # next free offset in F, in I
        for slot in range(_N_SLOTS):
            shape = self._shapes[slot]
            rows, cols = (shape + (1, 1))[:2] if len(shape) < 2 else shape
            which = int(slot >= _N_FLOAT_SLOTS)
            table[slot] = end[which], rows, cols
            end[which] += rows * cols
        self.F = np.zeros(end[0])
        self.I = np.zeros(end[1], dtype=np.int64)
        self.I[:header] = table.ravel()
        for slot, a in arrays.items():
            self.view(slot)[...] = a

    def view(self, slot: int) -> np.ndarray:
        off, rows, cols = self.I[3 * slot : 3 * slot + 3]
        buf = self.F if slot < _N_FLOAT_SLOTS else self.I
        return buf[off : off + rows * cols].reshape(self._shapes[slot])


@njit(cache=True, inline="always")
def _vec(buf: np.ndarray, I: np.ndarray, slot: int) -> np.ndarray:
    """Slot ``slot`` of ``buf`` (F or I) as a flat view."""
    off = I[3 * slot]
    return buf[off : off + I[3 * slot + 1] * I[3 * slot + 2]]


@njit(cache=True, inline="always")
def _mat(buf: np.ndarray, I: np.ndarray, slot: int) -> np.ndarray:
    """Slot ``slot`` of ``buf`` as a (rows, cols) view."""
    off, rows, cols = I[3 * slot], I[3 * slot + 1], I[3 * slot + 2]
    return buf[off : off + rows * cols].reshape((rows, cols))


@njit(cache=True)
def _matvec(A: np.ndarray, x: np.ndarray, out: np.ndarray) -> None:
    """``out = A @ x`` bit for bit as numpy computes it: BLAS gemv, or dot for a single row."""
    if A.shape[0] == 1:
        out[0] = np.dot(A[0], x)
    else:
        np.dot(A, x, out)


@njit(cache=True)
def _affine(A: np.ndarray, x: np.ndarray, B: np.ndarray, u: np.ndarray, out: np.ndarray, scratch: np.ndarray) -> None:
    """``out = A @ x + B @ u`` as numpy computes it; ``out`` may be ``x`` (scratch: 2 rows)."""
    n = out.size
    ax, bu = scratch[0, :n], scratch[1, :n]
    _matvec(A, x, ax)
    _matvec(B, u, bu)
    for i in range(n):
        out[i] = ax[i] + bu[i]


@njit(cache=True)
def _observe(step: int, F: np.ndarray, I: np.ndarray, inputs: np.ndarray) -> int:
    """Everything up to the allocator demand at ``step``: outputs, divergence, pilots, SMC, ``v``.

    Matrix products go through ``np.dot`` (the BLAS call numpy's ``@`` makes)
    in the order of the reference formulation, so results match it exactly.
    Returns ``_DIVERGED`` (see :func:`sim.result.divergence_check`) or ``_OK``.
    """
    misc = _vec(I, I, _I_MISC)
    dt = F[I[3 * _F_DT]]
    x = _vec(F, I, _F_X)
    y = _vec(F, I, _F_Y)
    z = _vec(F, I, _F_Z)
    ctrl = _vec(I, I, _I_CTRL)
    bound = _vec(F, I, _F_BOUND)
    cmd = _vec(F, I, _F_CMD)
    k = ctrl.size
    ny = y.size
    scratch = _mat(F, I, _F_SCRATCH)
    _affine(_mat(F, I, _F_C), x, _mat(F, I, _F_D), _vec(F, I, _F_UACT), y, scratch)
    for i in range(ny):
        z[i] = y[i] + inputs[step, k + i]
    for i in range(k):
        yi = y[ctrl[i]]
        if not np.isfinite(yi) or abs(yi) > bound[i]:
            return _DIVERGED
    for xi in x:
        if not np.isfinite(xi):
            return _DIVERGED
    for i in range(k):
        cmd[i] = inputs[step, i]
    # Pilots: crossover model on the measured outputs, through their delay lines.
    prow = _mat(F, I, _F_PROW)
    patt = _vec(F, I, _F_PATT)
    pbuf = _mat(F, I, _F_PBUF)
    pgain = _vec(F, I, _F_PGAIN)
    pn, plen, pidx = _vec(I, I, _I_PN), _vec(I, I, _I_PLEN), _vec(I, I, _I_PIDX)
    pchan, pint = _vec(I, I, _I_PCHAN), _vec(I, I, _I_PINT)
    for j in range(patt.size):
        att = np.dot(prow[j], z)
        if pint[j]:
            patt[j] += dt * att
            att = patt[j]
        else:
            patt[j] = att
        err = inputs[step, k + ny + j] - att
        if plen[j] > 1:
            i0 = pidx[j]
            pbuf[i0, j] = err
            err = pbuf[(i0 - pn[j]) % plen[j], j]
            pidx[j] = (i0 + 1) % plen[j]
        cmd[pchan[j]] = pgain[j] * err
    r = _vec(F, I, _F_R)
    e = _vec(F, I, _F_E)
    uc = _vec(F, I, _F_UC)
    xc = _vec(F, I, _F_XC)
    if misc[_M_SMC]:
        # sigma = K0 e + K_-1 int(e), u_c = rho sat(sigma / eps) (seed Eq 4.2, 4.8)
        o = _vec(F, I, _F_O)
        _matvec(_mat(F, I, _F_CC), xc, o)
        integ = _vec(F, I, _F_INTEG)
        K0, Km1 = _vec(F, I, _F_K0), _vec(F, I, _F_KM1)
        rho, eps = _vec(F, I, _F_RHO), _vec(F, I, _F_EPS)
        for i in range(k):
            y_fb = o[k + i] if misc[_M_OBSERVED] else z[ctrl[i]]
            r[i] = o[i]
            e[i] = o[i] - (y_fb + o[2 * k + i])
            sigma = K0[i] * e[i] + Km1[i] * integ[i]
            if misc[_M_SIGN]:
                uc[i] = rho[i] * np.sign(sigma)
            else:
                uc[i] = rho[i] * min(max(sigma / eps[i], -1.0), 1.0)
    else:
        _matvec(_mat(F, I, _F_CC), xc, r)
        for i in range(k):
            e[i] = r[i] - z[ctrl[i]]
        xk = _vec(F, I, _F_XK)
        _affine(_mat(F, I, _F_CK), xk, _mat(F, I, _F_DK), e, uc, scratch)
        _affine(_mat(F, I, _F_AK), xk, _mat(F, I, _F_BK), e, xk, scratch)
        _affine(_mat(F, I, _F_ADC), xc, _mat(F, I, _F_BDC), cmd, xc, scratch)
    _matvec(_mat(F, I, _F_DEMAND), uc, _vec(F, I, _F_V))
    # A reference that leaves the same validity bound is a pilot-loop runaway (the pilot
    # keeps asking for more while the plant output stays bounded): loss of control too.
    for i in range(k):
        if not np.isfinite(r[i]) or abs(r[i]) > bound[i]:
            return _DIVERGED
    return _OK


@njit(cache=True)
def _advance(
    step: int, u_cmd: np.ndarray, v_achieved: np.ndarray, F: np.ndarray, I: np.ndarray,
    inputs: np.ndarray, rec: np.ndarray,
) -> int:
    """Record ``step``, integrate to ``step + 1`` with ``u_cmd`` and observe it (unless a failure is due).

    ``v_achieved = B u_cmd`` as the allocator sees it; ``v - v_achieved`` is
    recorded as unallocated.

    Returns the status of :func:`_observe`, or ``_PENDING`` when the next
    step is past the end or is the failure step (Python injects it first).
    """
    misc = _vec(I, I, _I_MISC)
    dt = F[I[3 * _F_DT]]
    ctrl = _vec(I, I, _I_CTRL)
    k = ctrl.size
    y = _vec(F, I, _F_Y)
    uact = _vec(F, I, _F_UACT)
    cmd, r, e, uc = _vec(F, I, _F_CMD), _vec(F, I, _F_R), _vec(F, I, _F_E), _vec(F, I, _F_UC)
    rate_out = _vec(F, I, _F_RATE_OUT)
    lo, hi, rmax = _vec(F, I, _F_LO), _vec(F, I, _F_HI), _vec(F, I, _F_RMAX)
    patt = _vec(F, I, _F_PATT)
    m = uact.size
    if step % misc[_M_RECORD_EVERY] == 0:
        # column order of _record_columns
        row = rec[step // misc[_M_RECORD_EVERY]]
        row[0] = step * dt
        c = 1
        v = _vec(F, I, _F_V)
        for i in range(k):
            row[c + i] = r[i]
            row[c + k + i] = y[ctrl[i]]
            row[c + 2 * k + i] = cmd[i]
            row[c + 3 * k + i] = uc[i]
            row[c + 4 * k + i] = v[i] - v_achieved[i]
        c += 5 * k
        for i in range(m):
            row[c + i] = uact[i]
            row[c + m + i] = rate_out[i] if step else 0.0
            row[c + 2 * m + i] = lo[i]
            row[c + 3 * m + i] = hi[i]
            row[c + 4 * m + i] = rmax[i]
        c += 5 * m
        ny = y.size
        for j in range(patt.size):
            row[c + 2 * j] = inputs[step, k + ny + j]
            row[c + 2 * j + 1] = patt[j]
    if misc[_M_SMC]:
        # controller input w = [command, u_cmd, z_measured, u_c]
        w = _vec(F, I, _F_W)
        z = _vec(F, I, _F_Z)
        meas = _vec(I, I, _I_MEAS)
        nz = meas.size
        for i in range(k):
            w[i] = cmd[i]
            w[k + m + nz + i] = uc[i]
        for i in range(m):
            w[k + i] = u_cmd[i]
        for i in range(nz):
            w[k + m + i] = z[meas[i]]
        xc = _vec(F, I, _F_XC)
        _affine(_mat(F, I, _F_ADC), xc, _mat(F, I, _F_BDC), w, xc, _mat(F, I, _F_SCRATCH))
        integ = _vec(F, I, _F_INTEG)
        for i in range(k):
            integ[i] += dt * e[i]
    x = _vec(F, I, _F_X)
    _affine(_mat(F, I, _F_AD), x, _mat(F, I, _F_BD), uact, x, _mat(F, I, _F_SCRATCH))
    # Actuator delay (DelayLine.push): the command pushed n[c] steps ago.
    udel = _vec(F, I, _F_UDEL)
    dstate = _vec(I, I, _I_DSTATE)
    length = dstate[_D_LENGTH]
    if length == 1:
        for c in range(m):
            udel[c] = u_cmd[c]
    else:
        dbuf = _mat(F, I, _F_DBUF)
        dn = _vec(I, I, _I_DN)
        i0 = dstate[_D_INDEX]
        for c in range(m):
            dbuf[i0, c] = u_cmd[c]
            udel[c] = dbuf[(i0 - dn[c]) % length, c]
        dstate[_D_INDEX] = (i0 + 1) % length
    if misc[_M_ACTUATORS]:
        pos = _vec(F, I, _F_POS)
        actuator_heun_step(
            pos, _vec(F, I, _F_RATE), rate_out, udel, _vec(I, I, _I_FIRST), _vec(F, I, _F_WN2),
            _vec(F, I, _F_C1), lo, hi, rmax, _vec(I, I, _I_JAMMED), _vec(F, I, _F_JAM_POS),
            _vec(I, I, _I_HARDOVER), _vec(F, I, _F_HARD_POS), dt,
        )
        for i in range(m):
            uact[i] = pos[i]
    else:
        for i in range(m):
            uact[i] = min(max(udel[i], lo[i]), hi[i])
            rate_out[i] = 0.0
    nxt = step + 1
    if nxt > misc[_M_N_STEPS] or nxt == misc[_M_FAIL_STEP]:
        return _PENDING
    return _observe(nxt, F, I, inputs)


#: Per-step wall times collected by :func:`step_timer` (None: not timing).
_step_times: list[np.ndarray] | None = None


@contextmanager
def step_timer() -> Iterator[list[np.ndarray]]:
    """Collect the wall time of every step of every :func:`simulate` run inside the block.

    For benchmarks: each run appends an array (seconds, one entry per step
    simulated) timing the allocator call plus the compiled step; set-up and
    failure injection are not included.  Timing adds two clock reads per step.

    Examples
    --------
    >>> with step_timer() as times:
    ...     result = get_scenario("ice")(duration=1.0)
    >>> per_step_us = 1e6 * np.median(times[0])
    """
    global _step_times
    outer, _step_times = _step_times, []
    try:
        yield _step_times
    finally:
        _step_times = outer


def _record_columns(k: int, m: int, n_pilots: int) -> dict[str, slice]:
    """Columns of the record matrix, in the order :func:`_advance` writes them."""
    widths = [("t", 1), ("ref", k), ("out", k), ("cmd", k), ("pseudo", k), ("unalloc", k),
              ("eff", m), ("rate", m), ("lo", m), ("hi", m), ("rmax", m), ("extra", 2 * n_pilots)]
    cols, c = {}, 0
    for name, width in widths:
        cols[name] = slice(c, c + width)
        c += width
    return cols


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

    Per step, one compiled call (:func:`_advance`) records the step,
    integrates the plant, controller, delay and actuators, and evaluates the
    next step up to the allocator demand ``v``; the allocator (a plug-in) is
    called from Python in between.

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
    controller_slots = _controller_slots(vehicle, controller, references, dt)
    n_pilots = len(pilots)
    t_grid = np.arange(n_steps + 1) * dt
    pilot_floats, pilot_ints = _pilot_slots(pilots, ny, dt)
    inputs = np.hstack([
        np.asarray(commands, dtype=float)[: n_steps + 1],
        noise_all,
        np.column_stack([p.attitude_command(t_grid) for p in pilots]) if pilots else np.zeros((n_steps + 1, 0)),
    ])

    # Failure step: the first with t >= t_fail - dt/2 (never: n_steps + 1).
    fail_step = n_steps + 1
    if failure is not None:
        due = np.nonzero(t_grid >= failure.time - 0.5 * dt)[0]
        fail_step = int(due[0]) if due.size else n_steps + 1
    # The actuator delay ring holds the longest delay of the run.
    ring = 1
    if failure is not None and failure.delay is not None:
        ring = int(DelayLine(m, dt, failure.delay).n.max()) + 1

    misc = np.zeros(_N_MISC, dtype=np.int64)
    misc[[_M_N_STEPS, _M_RECORD_EVERY, _M_FAIL_STEP]] = n_steps, record_every, fail_step
    misc[_M_SMC] = smc
    misc[_M_OBSERVED] = smc and controller.observer_poles is not None
    misc[_M_SIGN] = smc and controller.eps is None
    misc[_M_ACTUATORS] = actuators
    nx, nc, nk = vehicle.A.shape[0], controller_slots[_F_ADC].shape[0], controller_slots[_F_AK].shape[0]
    packed = _Packed(
        floats={
            _F_X: np.zeros(nx), _F_AD: plant.Ad, _F_BD: plant.Bd, _F_C: plant.C, _F_D: plant.D, _F_UACT: bank.pos,
            **controller_slots,
            _F_INTEG: np.zeros(k), _F_DEMAND: vehicle.demand_map, _F_BOUND: np.broadcast_to(output_bound, (k,)),
            _F_DT: np.array(dt),
            _F_POS: bank.pos, _F_RATE: bank.rate, _F_RATE_OUT: np.zeros(m), _F_WN2: bank.wn2, _F_C1: bank.c1,
            _F_LO: bank.lo, _F_HI: bank.hi, _F_RMAX: bank.rmax, _F_JAM_POS: bank.jam_pos,
            _F_HARD_POS: bank.hard_pos, _F_DBUF: np.zeros((ring, m)),
            **pilot_floats,
            _F_Y: np.zeros(ny), _F_Z: np.zeros(ny), _F_CMD: np.zeros(k), _F_R: np.zeros(k),
            _F_E: np.zeros(k), _F_UC: np.zeros(k), _F_V: np.zeros(k), _F_UDEL: np.zeros(m), _F_O: np.zeros(3 * k),
            _F_SCRATCH: np.zeros((2, max(nx, ny, nc, nk, k))),
        },
        ints={
            _I_FIRST: bank.first, _I_JAMMED: bank.jammed, _I_HARDOVER: bank.hardover,
            _I_DN: delay.n, _I_DSTATE: np.array([0, 1]), **pilot_ints,
            _I_MEAS: meas, _I_CTRL: np.asarray(vehicle.controlled), _I_MISC: misc,
        },
    )
    # The bank's position and rate live in the packed buffer (failures write there).
    bank.pos, bank.rate = packed.view(_F_POS), packed.view(_F_RATE)
    F, I = packed.F, packed.I
    v = packed.view(_F_V)

    cols = _record_columns(k, m, n_pilots)
    rec = np.zeros((n_steps // record_every + 1, cols["extra"].stop))
    u_cmd = np.zeros(m)
    n_done = n_steps + 1

    def fail_now(u_last: np.ndarray) -> LoopAllocator:
        _inject(failure, plant, bank, delay, packed, u_last)
        if actuators:
            packed.view(_F_UACT)[:] = bank.pos  # a jammed surface is at its jam position at once
        if allocator_knows_failure:
            return build_allocator(vehicle, method, method_options or {}, failure=failure, rate_aware=rate_aware)
        return allocator

    if fail_step == 0:
        allocator = fail_now(u_cmd)
    status = _observe(0, F, I, inputs)
    iterator = range(n_steps + 1)
    if progress:
        iterator = tqdm(iterator, total=n_steps + 1, unit="step", mininterval=0.5, desc=scenario)
    timed = _step_times is not None
    times = np.full(n_steps + 1, np.nan) if timed else None
    clock = time.perf_counter
    last_before_failure = fail_step - 1 if failure is not None else -1
    advance, diverged = _advance, _DIVERGED  # locals: the loop body is the per-step Python cost
    for step in iterator:
        if status == diverged:
            n_done = step
            break
        if timed:
            t0 = clock()
        u_cmd, v_achieved = allocator(v, u_cmd, dt)
        status = advance(step, u_cmd, v_achieved, F, I, inputs, rec)
        if timed:
            times[step] = clock() - t0
        if step == last_before_failure:
            allocator = fail_now(u_cmd)
            status = _observe(step + 1, F, I, inputs)
    if timed:
        _step_times.append(times[:n_done])
    n = (n_done + record_every - 1) // record_every  # samples recorded before step n_done
    return _result(rec[:n], cols, scenario, method, vehicle, failure, pilots, diverged=n_done <= n_steps)


def _result(
    rec: np.ndarray, cols: dict[str, slice], scenario: str, method: str, vehicle: Vehicle,
    failure: Failure | None, pilots: Sequence[Pilot], *, diverged: bool,
) -> SimResult:
    """SimResult from the record matrix (contiguous copies of its columns)."""

    def column(name: str) -> np.ndarray:
        return np.ascontiguousarray(rec[:, cols[name]])

    extra = {}
    for j, p in enumerate(pilots):
        extra[f"{p.name}_command"] = rec[:, cols["extra"].start + 2 * j].copy()
        extra[f"{p.name}"] = rec[:, cols["extra"].start + 2 * j + 1].copy()
    return SimResult(
        scenario=scenario,
        method=method,
        failure=None if failure is None else failure.name,
        t=rec[:, 0].copy(),
        channels=vehicle.channels,
        reference=column("ref"),
        output=column("out"),
        command=column("cmd"),
        pseudo=column("pseudo"),
        effectors=column("eff"),
        effector_rates=column("rate"),
        effector_names=vehicle.effector_names,
        # Limits as they were at each sample (failures change them).
        effector_limits=(column("lo"), column("hi")),
        rate_limits=(-column("rmax"), column("rmax")),
        failure_time=None if failure is None else failure.time,
        diverged=diverged,
        unallocated=column("unalloc"),
        extra=extra,
    )


def _controller_slots(
    vehicle: Vehicle, controller: SMCDesign | LoopShapedDesign, references: Sequence[TF], dt: float
) -> dict[int, np.ndarray]:
    """Packed arrays of the controller: the SMC system and gains, or reference models and compensators."""
    k = len(vehicle.controlled)
    if isinstance(controller, SMCDesign):
        ctl, n_in = _controller_system(vehicle, controller, references, dt)
        eps = np.ones(k) if controller.eps is None else controller.eps  # unused with sign (eps None)
        return {
            _F_XC: ctl.x, _F_ADC: ctl.Ad, _F_BDC: ctl.Bd, _F_CC: ctl.C, _F_W: np.zeros(n_in),
            _F_XK: np.zeros(0), _F_AK: np.zeros((0, 0)), _F_BK: np.zeros((0, k)), _F_CK: np.zeros((k, 0)),
            _F_DK: np.zeros((k, k)),
            _F_K0: controller.K0, _F_KM1: controller.Km1, _F_RHO: controller.rho, _F_EPS: eps,
        }
    ref = DiscreteLTI(*_diagonal_system(references, k), dt=dt)
    comp = DiscreteLTI(*_diagonal_system(controller.compensators, k), dt=dt)
    return {
        _F_XC: ref.x, _F_ADC: ref.Ad, _F_BDC: ref.Bd, _F_CC: ref.C, _F_W: np.zeros(0),
        _F_XK: comp.x, _F_AK: comp.Ad, _F_BK: comp.Bd, _F_CK: comp.C, _F_DK: comp.D,
        _F_K0: np.zeros(k), _F_KM1: np.zeros(k), _F_RHO: np.zeros(k), _F_EPS: np.zeros(k),
    }


def _pilot_slots(pilots: Sequence[Pilot], ny: int, dt: float) -> tuple[dict[int, np.ndarray], dict[int, np.ndarray]]:
    """Packed arrays of the pilots (float slots, int slots); each delay is a DelayLine ring of its own."""
    n = len(pilots)
    length = np.array([int(DelayLine(1, dt, p.delay).n[0]) + 1 for p in pilots], dtype=np.int64)
    floats = {
        _F_PROW: np.array([p.row for p in pilots], dtype=float).reshape(n, ny),
        _F_PGAIN: np.array([p.gain for p in pilots], dtype=float),
        _F_PATT: np.zeros(n),
        _F_PBUF: np.zeros((int(length.max(initial=1)), n)),
    }
    ints = {
        _I_PN: length - 1, _I_PLEN: length, _I_PIDX: np.zeros(n),
        _I_PCHAN: np.array([p.channel for p in pilots]), _I_PINT: np.array([p.integrate for p in pilots]),
    }
    return floats, ints


def _diagonal_system(tfs: Sequence[TF], k: int) -> tuple[np.ndarray, ...]:
    """Stack of SISO transfer functions, ``y[i] = G_i(s) u[i]``."""
    return stack_lti(
        [tf_to_ss(n, d) for n, d in tfs],
        [np.eye(k)[[i]] for i in range(k)],
        [np.eye(k)[:, [i]] for i in range(k)],
        k, k,
    )


def _inject(
    failure: Failure, plant: ScheduledPlant, bank: ActuatorBank, delay: DelayLine, packed: _Packed,
    u_last: np.ndarray,
) -> None:
    """Apply a failure to the plant, the actuators and the actuator delay (``u_last``: last command pushed)."""
    eff = np.ones(bank.m)
    for f in failure.actuators:
        if f.kind == "float":
            eff[f.index] = 0.0
        elif f.kind == "effectiveness":
            eff[f.index] = float(f.fraction)
        else:
            bank.apply_failure(f)  # a jam writes pos/rate straight into the packed buffer
    plant.fail(effectiveness=eff)
    packed.view(_F_AD)[:] = plant.Ad
    packed.view(_F_BD)[:] = plant.Bd
    packed.view(_F_D)[:] = plant.D
    for slot, a in ((_F_WN2, bank.wn2), (_F_C1, bank.c1), (_F_LO, bank.lo), (_F_HI, bank.hi),
                    (_F_RMAX, bank.rmax), (_F_JAM_POS, bank.jam_pos), (_F_HARD_POS, bank.hard_pos),
                    (_I_FIRST, bank.first), (_I_JAMMED, bank.jammed), (_I_HARDOVER, bank.hardover)):
        packed.view(slot)[:] = a
    if failure.delay is not None:
        # DelayLine.set_delay: the ring restarts, pre-filled with the last command pushed.
        delay.set_delay(failure.delay)
        length = int(delay.n.max()) + 1
        packed.view(_I_DN)[:] = delay.n
        packed.view(_I_DSTATE)[:] = 0, length
        packed.view(_F_DBUF)[:length] = u_last
