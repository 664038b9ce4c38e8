"""Closed-loop engine shared by the MIMO scenarios (ICE, F-18/HARV).

Multi-rate: plant, actuators and delay integrate every step ``dt`` (the
seed's 0.5 ms); the flight-control computer -- pilot sampling, reference
models, observers, SMC, hedges and the allocator -- runs once per frame
``T = LoopSpec.frame_period`` (a multiple of ``dt``), its outputs held in
between.  ``T = dt`` is the seed's single-rate loop, bit for bit.

Signal flow per frame (seed Figs 3-26, 3-32, 4-85)::

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
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from enum import IntEnum, auto
from typing import Any

import numpy as np
from numba import njit
from tqdm import tqdm

from alloc.result import EXACT_RTOL
from sim.allocation import LoopAllocator, build_allocator
from sim.blocks import (
    DEFAULT_DT,
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

__all__ = ["Vehicle", "Failure", "SMCDesign", "LoopShapedDesign", "Pilot", "LoopSpec", "simulate",
           "boundary_layer_at", "BOUNDARY_LAYER_RULES", "anti_windup_on", "ANTI_WINDUP_RULES",
           "FloatSlot", "IntSlot", "Misc"]

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
    #: effector names as the library names them (``alloc.vehicles``); default the actuator names
    names: tuple[str, ...] | None = None

    @property
    def channels(self) -> list[str]:
        return [self.output_names[i] for i in self.controlled]

    @property
    def effector_names(self) -> list[str]:
        return list(self.names) if self.names is not None else [a.name for a in self.actuators]

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
    """Compensatory pilot on one channel (the seed's pilot models, Figs 4-6, 4-41, 4-86, are images).

    McRuer's precision model of the human operator::

        command[channel] = gain (lead s + 1) / ((lag s + 1)(neuromuscular s + 1)) e^{-delay s} error
        error = att_cmd - att,  att = row @ y_measured  (integrated if ``integrate``)

    With ``lead = lag = neuromuscular = 0`` this is the project's original
    stand-in, ``gain (att_cmd - att)`` delayed (gain 2, 0.2 s by default).
    :mod:`sim.pilot` sets the parameters by the crossover-model rule.  The
    pilot is sampled by the flight-control computer once per frame.
    """

    channel: int
    row: np.ndarray
    attitude_command: Callable[[np.ndarray], np.ndarray]
    name: str
    gain: float = 2.0
    delay: float = 0.2
    integrate: bool = False
    lead: float = 0.0
    lag: float = 0.0
    neuromuscular: float = 0.0
    #: label of the rule that set the parameters ("standin", "crossover", ...)
    model: str = "standin"

    @property
    def filtered(self) -> bool:
        """True when the pilot has lead, lag or neuromuscular dynamics (not a pure gain)."""
        return bool(self.lead or self.lag or self.neuromuscular)

    def transfer_function(self) -> TF:
        """``(lead s + 1) / ((lag s + 1)(neuromuscular s + 1))`` (gain and delay excluded)."""
        return [self.lead, 1.0] if self.lead else [1.0], np.polymul([self.lag, 1.0], [self.neuromuscular, 1.0])

    def describe(self) -> dict[str, Any]:
        """Parameters as JSON-ready numbers."""
        return {"name": self.name, "model": self.model, "gain": float(self.gain), "delay": float(self.delay),
                "lead": float(self.lead), "lag": float(self.lag), "neuromuscular": float(self.neuromuscular)}


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

class FloatSlot(IntEnum):
    """Float arrays of the compiled step (slots of ``F``), in buffer order."""

    # plant: state, ZOH matrices, output matrices, effector positions it sees
    X = 0
    AD = auto()
    BD = auto()
    C = auto()
    D = auto()
    UACT = auto()
    # controller: SMC system (reference models, observers, hedge) or, loop-shaped,
    # the reference models (XC..CC) and the compensators (XK..DK)
    XC = auto()
    ADC = auto()
    BDC = auto()
    CC = auto()
    XK = auto()
    AK = auto()
    BK = auto()
    CK = auto()
    DK = auto()
    INTEG = auto()
    K0 = auto()
    KM1 = auto()
    RHO = auto()
    EPS = auto()
    DEMAND = auto()
    BOUND = auto()
    #: integration step (plant, actuators) and flight-control frame period
    DT = auto()
    TFRAME = auto()
    # actuator bank (ActuatorBank arrays) and the actuator delay ring buffer
    POS = auto()
    RATE = auto()
    RATE_OUT = auto()
    WN2 = auto()
    C1 = auto()
    LO = auto()
    HI = auto()
    RMAX = auto()
    JAM_POS = auto()
    HARD_POS = auto()
    DBUF = auto()
    # pilots: output rows, gains, attitudes, delay ring buffers (one column each)
    PROW = auto()
    PGAIN = auto()
    PATT = auto()
    PBUF = auto()
    # pilot lead-lag / neuromuscular filters (block diagonal, input and output: one per pilot)
    PXF = auto()
    PAF = auto()
    PBF = auto()
    PCF = auto()
    PDF = auto()
    PERR = auto()
    # signals of the current step
    Y = auto()
    Z = auto()
    CMD = auto()
    R = auto()
    E = auto()
    UC = auto()
    V = auto()
    W = auto()
    UDEL = auto()
    # controller outputs [r, y_hat, y_f]; two scratch rows for matrix-vector products
    O = auto()  # noqa: E741
    SCRATCH = auto()


_N_FLOAT_SLOTS = len(FloatSlot)


class IntSlot(IntEnum):
    """Integer arrays of the compiled step (slots of ``I``), numbered after the float slots."""

    FIRST = _N_FLOAT_SLOTS
    JAMMED = auto()
    HARDOVER = auto()
    DN = auto()
    DSTATE = auto()
    PN = auto()
    PLEN = auto()
    PIDX = auto()
    PCHAN = auto()
    PINT = auto()
    MEAS = auto()
    CTRL = auto()
    MISC = auto()


_N_SLOTS = _N_FLOAT_SLOTS + len(IntSlot)


#: Entries of the ``IntSlot.MISC`` array (run constants and switches): steps in the run,
#: record every n-th step, failure step, SMC (else loop-shaped), observers in use, sign law
#: (no boundary layer), actuator dynamics on, integration steps per flight-control frame,
#: pilots with lead-lag / neuromuscular dynamics, conditional integration (:func:`anti_windup_on`).
Misc = IntEnum("Misc", ["N_STEPS", "RECORD_EVERY", "FAIL_STEP", "SMC", "OBSERVED", "SIGN", "ACTUATORS", "FRAME",
                        "PFILTER", "ANTI_WINDUP"], start=0, module=__name__)


_N_MISC = len(Misc)

# IntSlot.DSTATE entries: ring index, ring length (DelayLine semantics)
_D_INDEX, _D_LENGTH = 0, 1

# a demand met to this relative tolerance is met (alloc.result.EXACT_RTOL, the library's exact status)
_EXACT_RTOL = EXACT_RTOL

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
    misc = _vec(I, I, IntSlot.MISC)
    x = _vec(F, I, FloatSlot.X)
    y = _vec(F, I, FloatSlot.Y)
    z = _vec(F, I, FloatSlot.Z)
    ctrl = _vec(I, I, IntSlot.CTRL)
    bound = _vec(F, I, FloatSlot.BOUND)
    cmd = _vec(F, I, FloatSlot.CMD)
    k = ctrl.size
    ny = y.size
    scratch = _mat(F, I, FloatSlot.SCRATCH)
    _affine(_mat(F, I, FloatSlot.C), x, _mat(F, I, FloatSlot.D), _vec(F, I, FloatSlot.UACT), y, scratch)
    for i in range(ny):
        z[i] = y[i] + inputs[step, k + i]
    for i in range(k):
        yi = y[ctrl[i]]
        if not np.isfinite(yi) or abs(yi) > bound[i]:
            return _DIVERGED
    for xi in x:
        if not np.isfinite(xi):
            return _DIVERGED
    if step % misc[Misc.FRAME] != 0:
        return _OK  # between frames the flight-control computer's outputs are held
    dt = F[I[3 * FloatSlot.TFRAME]]  # pilot sampling and controller integration: one frame
    for i in range(k):
        cmd[i] = inputs[step, i]
    # Pilots: crossover model on the measured outputs, through their delay lines.
    prow = _mat(F, I, FloatSlot.PROW)
    patt = _vec(F, I, FloatSlot.PATT)
    pbuf = _mat(F, I, FloatSlot.PBUF)
    pgain = _vec(F, I, FloatSlot.PGAIN)
    pn, plen, pidx = _vec(I, I, IntSlot.PN), _vec(I, I, IntSlot.PLEN), _vec(I, I, IntSlot.PIDX)
    pchan, pint = _vec(I, I, IntSlot.PCHAN), _vec(I, I, IntSlot.PINT)
    perr = _vec(F, I, FloatSlot.PERR)[: patt.size]
    patt_out = _vec(F, I, FloatSlot.PERR)[patt.size :]
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
        perr[j] = err
    if misc[Misc.PFILTER]:
        # lead-lag and neuromuscular lag (McRuer precision model) on the delayed error
        pxf = _vec(F, I, FloatSlot.PXF)
        _affine(_mat(F, I, FloatSlot.PCF), pxf, _mat(F, I, FloatSlot.PDF), perr, patt_out, scratch)
        _affine(_mat(F, I, FloatSlot.PAF), pxf, _mat(F, I, FloatSlot.PBF), perr, pxf, scratch)
        for j in range(patt.size):
            cmd[pchan[j]] = pgain[j] * patt_out[j]
    r = _vec(F, I, FloatSlot.R)
    e = _vec(F, I, FloatSlot.E)
    uc = _vec(F, I, FloatSlot.UC)
    xc = _vec(F, I, FloatSlot.XC)
    if misc[Misc.SMC]:
        # sigma = K0 e + K_-1 int(e), u_c = rho sat(sigma / eps) (seed Eq 4.2, 4.8)
        o = _vec(F, I, FloatSlot.O)
        _matvec(_mat(F, I, FloatSlot.CC), xc, o)
        integ = _vec(F, I, FloatSlot.INTEG)
        K0, Km1 = _vec(F, I, FloatSlot.K0), _vec(F, I, FloatSlot.KM1)
        rho, eps = _vec(F, I, FloatSlot.RHO), _vec(F, I, FloatSlot.EPS)
        for i in range(k):
            y_fb = o[k + i] if misc[Misc.OBSERVED] else z[ctrl[i]]
            r[i] = o[i]
            e[i] = o[i] - (y_fb + o[2 * k + i])
            sigma = K0[i] * e[i] + Km1[i] * integ[i]
            if misc[Misc.SIGN]:
                uc[i] = rho[i] * np.sign(sigma)
            else:
                uc[i] = rho[i] * min(max(sigma / eps[i], -1.0), 1.0)
    else:
        _matvec(_mat(F, I, FloatSlot.CC), xc, r)
        for i in range(k):
            e[i] = r[i] - z[ctrl[i]]
        xk = _vec(F, I, FloatSlot.XK)
        _affine(_mat(F, I, FloatSlot.CK), xk, _mat(F, I, FloatSlot.DK), e, uc, scratch)
        _affine(_mat(F, I, FloatSlot.AK), xk, _mat(F, I, FloatSlot.BK), e, xk, scratch)
        _affine(_mat(F, I, FloatSlot.ADC), xc, _mat(F, I, FloatSlot.BDC), cmd, xc, scratch)
    _matvec(_mat(F, I, FloatSlot.DEMAND), uc, _vec(F, I, FloatSlot.V))
    # A reference that leaves the same validity bound is a pilot-loop runaway (the pilot
    # keeps asking for more while the plant output stays bounded): loss of control too.
    for i in range(k):
        if not np.isfinite(r[i]) or abs(r[i]) > bound[i]:
            return _DIVERGED
    return _OK


@njit(cache=True)
def _short_of_demand(v: np.ndarray, v_achieved: np.ndarray) -> bool:
    """True when the allocator fell short: ``max|v - B u| > rtol max(1, max|v|)`` (``alloc``'s exact test)."""
    err, vmax = 0.0, 1.0
    for i in range(v.size):
        err = max(err, abs(v_achieved[i] - v[i]))
        vmax = max(vmax, abs(v[i]))
    return not err <= _EXACT_RTOL * vmax


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
    misc = _vec(I, I, IntSlot.MISC)
    dt = F[I[3 * FloatSlot.DT]]
    ctrl = _vec(I, I, IntSlot.CTRL)
    k = ctrl.size
    y = _vec(F, I, FloatSlot.Y)
    uact = _vec(F, I, FloatSlot.UACT)
    cmd, r, e, uc = _vec(F, I, FloatSlot.CMD), _vec(F, I, FloatSlot.R), _vec(F, I, FloatSlot.E), _vec(F, I, FloatSlot.UC)
    rate_out = _vec(F, I, FloatSlot.RATE_OUT)
    lo, hi, rmax = _vec(F, I, FloatSlot.LO), _vec(F, I, FloatSlot.HI), _vec(F, I, FloatSlot.RMAX)
    patt = _vec(F, I, FloatSlot.PATT)
    m = uact.size
    if step % misc[Misc.RECORD_EVERY] == 0:
        # column order of _record_columns
        row = rec[step // misc[Misc.RECORD_EVERY]]
        row[0] = step * dt
        c = 1
        v = _vec(F, I, FloatSlot.V)
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
    if misc[Misc.SMC] and step % misc[Misc.FRAME] == 0:
        # controller input w = [command, u_cmd, z_measured, u_c], sampled once per frame
        tframe = F[I[3 * FloatSlot.TFRAME]]
        w = _vec(F, I, FloatSlot.W)
        z = _vec(F, I, FloatSlot.Z)
        meas = _vec(I, I, IntSlot.MEAS)
        nz = meas.size
        for i in range(k):
            w[i] = cmd[i]
            w[k + m + nz + i] = uc[i]
        for i in range(m):
            w[k + i] = u_cmd[i]
        for i in range(nz):
            w[k + m + i] = z[meas[i]]
        xc = _vec(F, I, FloatSlot.XC)
        _affine(_mat(F, I, FloatSlot.ADC), xc, _mat(F, I, FloatSlot.BDC), w, xc, _mat(F, I, FloatSlot.SCRATCH))
        integ = _vec(F, I, FloatSlot.INTEG)
        if not (misc[Misc.ANTI_WINDUP] and _short_of_demand(_vec(F, I, FloatSlot.V), v_achieved)):
            for i in range(k):
                integ[i] += tframe * e[i]
    x = _vec(F, I, FloatSlot.X)
    _affine(_mat(F, I, FloatSlot.AD), x, _mat(F, I, FloatSlot.BD), uact, x, _mat(F, I, FloatSlot.SCRATCH))
    # Actuator delay (DelayLine.push): the command pushed n[c] steps ago.
    udel = _vec(F, I, FloatSlot.UDEL)
    dstate = _vec(I, I, IntSlot.DSTATE)
    length = dstate[_D_LENGTH]
    if length == 1:
        for c in range(m):
            udel[c] = u_cmd[c]
    else:
        dbuf = _mat(F, I, FloatSlot.DBUF)
        dn = _vec(I, I, IntSlot.DN)
        i0 = dstate[_D_INDEX]
        for c in range(m):
            dbuf[i0, c] = u_cmd[c]
            udel[c] = dbuf[(i0 - dn[c]) % length, c]
        dstate[_D_INDEX] = (i0 + 1) % length
    if misc[Misc.ACTUATORS]:
        pos = _vec(F, I, FloatSlot.POS)
        actuator_heun_step(
            pos, _vec(F, I, FloatSlot.RATE), rate_out, udel, _vec(I, I, IntSlot.FIRST), _vec(F, I, FloatSlot.WN2),
            _vec(F, I, FloatSlot.C1), lo, hi, rmax, _vec(I, I, IntSlot.JAMMED), _vec(F, I, FloatSlot.JAM_POS),
            _vec(I, I, IntSlot.HARDOVER), _vec(F, I, FloatSlot.HARD_POS), dt,
        )
        for i in range(m):
            uact[i] = pos[i]
    else:
        for i in range(m):
            uact[i] = min(max(udel[i], lo[i]), hi[i])
            rate_out[i] = 0.0
    nxt = step + 1
    if nxt > misc[Misc.N_STEPS] or nxt == misc[Misc.FAIL_STEP]:
        return _PENDING
    return _observe(nxt, F, I, inputs)


def _record_columns(k: int, m: int, n_pilots: int) -> dict[str, slice]:
    """Columns of the record matrix, in the order :func:`_advance` writes them."""
    widths = [("t", 1), ("ref", k), ("out", k), ("cmd", k), ("pseudo", k), ("unalloc", k),
              ("eff", m), ("rate", m), ("lo", m), ("hi", m), ("rmax", m), ("extra", 2 * n_pilots)]
    cols, c = {}, 0
    for name, width in widths:
        cols[name] = slice(c, c + width)
        c += width
    return cols


@dataclass(frozen=True)
class LoopSpec:
    """Everything one closed-loop run needs (the argument of :func:`simulate`).

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


def simulate(
    spec: LoopSpec | None = None,
    *,
    progress: bool = False,
    step_times: list[np.ndarray] | None = None,
    **fields: Any,
) -> SimResult:
    """Run one closed loop.

    Multi-rate (seed 0.5 ms plant, frame ``T`` flight-control computer): at
    each frame the compiled :func:`_observe` samples the pilot and the noisy
    outputs, advances the SMC and produces the demand ``v``; the allocator (a
    plug-in, called from Python) turns it into ``u_cmd`` with ``u_prev`` and
    ``dt = T`` (seed Eq 1.28); one compiled :func:`_advance` per integration
    step records, integrates the controller (at frames), plant, delay and
    actuators with ``u_cmd`` held.  With ``T = dt`` this is the seed's single-
    rate loop, bit for bit.

    Parameters
    ----------
    spec : LoopSpec
        The run; alternatively its fields as keywords (``simulate(**fields)``).
    progress : bool
        Show a progress bar.
    step_times : list or None
        When given, one array is appended: the wall time (s) of every
        integration step (allocator call, when due, plus the compiled step);
        set-up and failure injection are not included.
    """
    if spec is None:
        spec = LoopSpec(**fields)
    elif fields:
        raise TypeError(f"simulate: give a LoopSpec or keywords, not both (got {sorted(fields)})")
    if spec.u_prev_source not in U_PREV_SOURCES:
        raise ValueError(f"u_prev_source: {spec.u_prev_source!r}; expected one of {U_PREV_SOURCES}")
    if spec.anti_windup not in ANTI_WINDUP_RULES:
        raise ValueError(f"anti_windup: {spec.anti_windup!r}; expected one of {ANTI_WINDUP_RULES}")
    if spec.boundary_layer not in BOUNDARY_LAYER_RULES:
        raise ValueError(f"boundary_layer: {spec.boundary_layer!r}; expected one of {BOUNDARY_LAYER_RULES}")
    frame = spec.frame_steps()
    scenario, vehicle, references, controller = spec.scenario, spec.vehicle, spec.references, spec.controller
    commands, pilots, failure, method = spec.commands, spec.pilots, spec.failure, spec.method
    method_options, allocator_knows_failure, rate_aware = spec.method_options, spec.allocator_knows_failure, spec.rate_aware
    actuators, noise, duration, dt, seed = spec.actuators, spec.noise, spec.duration, spec.dt, spec.seed
    output_bound, record_every = spec.output_bound, spec.record_every
    tframe = frame * dt
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
    alloc_options = dict(rate_aware=rate_aware, preferred=spec.preferred, frame_period=tframe,
                         rate_horizon=spec.rate_horizon, rate_window=spec.rate_window)
    allocator: LoopAllocator = build_allocator(vehicle, method, method_options or {}, **alloc_options)
    position_feedback = spec.u_prev_source == "position"

    smc = isinstance(controller, SMCDesign)
    controller_slots = _controller_slots(vehicle, controller, references, tframe, spec.boundary_layer)
    n_pilots = len(pilots)
    t_grid = np.arange(n_steps + 1) * dt
    pilot_floats, pilot_ints = _pilot_slots(pilots, ny, tframe)
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
    misc[[Misc.N_STEPS, Misc.RECORD_EVERY, Misc.FAIL_STEP]] = n_steps, record_every, fail_step
    misc[Misc.SMC] = smc
    misc[Misc.OBSERVED] = smc and controller.observer_poles is not None
    misc[Misc.SIGN] = smc and controller.eps is None
    misc[Misc.ACTUATORS] = actuators
    misc[Misc.FRAME] = frame
    misc[Misc.PFILTER] = any(p.filtered for p in pilots)
    misc[Misc.ANTI_WINDUP] = smc and anti_windup_on(spec.anti_windup, tframe)
    nx, nc, nk = vehicle.A.shape[0], controller_slots[FloatSlot.ADC].shape[0], controller_slots[FloatSlot.AK].shape[0]
    packed = _Packed(
        floats={
            FloatSlot.X: np.zeros(nx), FloatSlot.AD: plant.Ad, FloatSlot.BD: plant.Bd, FloatSlot.C: plant.C, FloatSlot.D: plant.D, FloatSlot.UACT: bank.pos,
            **controller_slots,
            FloatSlot.INTEG: np.zeros(k), FloatSlot.DEMAND: vehicle.demand_map, FloatSlot.BOUND: np.broadcast_to(output_bound, (k,)),
            FloatSlot.DT: np.array(dt), FloatSlot.TFRAME: np.array(tframe),
            FloatSlot.POS: bank.pos, FloatSlot.RATE: bank.rate, FloatSlot.RATE_OUT: np.zeros(m), FloatSlot.WN2: bank.wn2, FloatSlot.C1: bank.c1,
            FloatSlot.LO: bank.lo, FloatSlot.HI: bank.hi, FloatSlot.RMAX: bank.rmax, FloatSlot.JAM_POS: bank.jam_pos,
            FloatSlot.HARD_POS: bank.hard_pos, FloatSlot.DBUF: np.zeros((ring, m)),
            **pilot_floats,
            FloatSlot.Y: np.zeros(ny), FloatSlot.Z: np.zeros(ny), FloatSlot.CMD: np.zeros(k), FloatSlot.R: np.zeros(k),
            FloatSlot.E: np.zeros(k), FloatSlot.UC: np.zeros(k), FloatSlot.V: np.zeros(k), FloatSlot.UDEL: np.zeros(m), FloatSlot.O: np.zeros(3 * k),
            FloatSlot.SCRATCH: np.zeros((2, max(nx, ny, nc, nk, k, *pilot_floats[FloatSlot.PAF].shape, n_pilots))),
        },
        ints={
            IntSlot.FIRST: bank.first, IntSlot.JAMMED: bank.jammed, IntSlot.HARDOVER: bank.hardover,
            IntSlot.DN: delay.n, IntSlot.DSTATE: np.array([0, 1]), **pilot_ints,
            IntSlot.MEAS: meas, IntSlot.CTRL: np.asarray(vehicle.controlled), IntSlot.MISC: misc,
        },
    )
    # The bank's position and rate live in the packed buffer (failures write there).
    bank.pos, bank.rate = packed.view(FloatSlot.POS), packed.view(FloatSlot.RATE)
    F, I = packed.F, packed.I
    v = packed.view(FloatSlot.V)

    cols = _record_columns(k, m, n_pilots)
    rec = np.zeros((n_steps // record_every + 1, cols["extra"].stop))
    u_cmd = np.zeros(m)
    v_achieved = np.zeros(k)
    positions = packed.view(FloatSlot.UACT)
    # allocator status of every frame (STATUS_NAMES codes; -1: not reached)
    call_status = np.full(n_steps // frame + 1, -1, dtype=np.int8)
    n_done = n_steps + 1

    def fail_now(u_last: np.ndarray) -> LoopAllocator:
        _inject(failure, plant, bank, delay, packed, u_last)
        if actuators:
            packed.view(FloatSlot.UACT)[:] = bank.pos  # a jammed surface is at its jam position at once
        if allocator_knows_failure:
            return build_allocator(vehicle, method, method_options or {}, failure=failure, **alloc_options)
        return allocator

    if fail_step == 0:
        allocator = fail_now(u_cmd)
    status = _observe(0, F, I, inputs)
    iterator = range(n_steps + 1)
    if progress:
        iterator = tqdm(iterator, total=n_steps + 1, unit="step", mininterval=0.5, desc=scenario)
    timed = step_times is not None
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
        if step % frame == 0:
            u_prev = positions.copy() if position_feedback else u_cmd
            u_cmd, v_achieved, call_status[step // frame] = allocator(v, u_prev, tframe)
        status = advance(step, u_cmd, v_achieved, F, I, inputs, rec)
        if timed:
            times[step] = clock() - t0
        if step == last_before_failure:
            allocator = fail_now(u_cmd)
            status = _observe(step + 1, F, I, inputs)
    if timed:
        step_times.append(times[:n_done])
    n = (n_done + record_every - 1) // record_every  # samples recorded before step n_done
    n_calls = (n_done + frame - 1) // frame
    result = _result(rec[:n], cols, scenario, method, vehicle, failure, pilots, diverged=n_done <= n_steps)
    result.allocator_t = np.arange(n_calls) * tframe
    result.allocator_status = call_status[:n_calls].copy()
    result.settings = {
        "frame_period": tframe, "dt": dt, "rate_aware": bool(rate_aware), "u_prev_source": spec.u_prev_source,
        "rate_horizon": spec.rate_horizon, "rate_window": spec.rate_window, "anti_windup": spec.anti_windup,
        "boundary_layer": spec.boundary_layer,
        "preferred": spec.preferred, "allocator_knows_failure": bool(allocator_knows_failure), "noise": bool(noise), "seed": int(seed),
        "pilots": [p.describe() for p in pilots],
    }
    return result


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
    vehicle: Vehicle, controller: SMCDesign | LoopShapedDesign, references: Sequence[TF], dt: float,
    boundary_layer: str = "frame",
) -> dict[int, np.ndarray]:
    """Packed arrays of the controller: the SMC system and gains, or reference models and compensators.

    ``dt`` is the frame period; ``boundary_layer`` the rule of :func:`boundary_layer_at`.
    """
    k = len(vehicle.controlled)
    if isinstance(controller, SMCDesign):
        ctl, n_in = _controller_system(vehicle, controller, references, dt)
        # unused with sign (eps None)
        eps = np.ones(k) if controller.eps is None else boundary_layer_at(controller.eps, dt, boundary_layer)
        return {
            FloatSlot.XC: ctl.x, FloatSlot.ADC: ctl.Ad, FloatSlot.BDC: ctl.Bd, FloatSlot.CC: ctl.C, FloatSlot.W: np.zeros(n_in),
            FloatSlot.XK: np.zeros(0), FloatSlot.AK: np.zeros((0, 0)), FloatSlot.BK: np.zeros((0, k)), FloatSlot.CK: np.zeros((k, 0)),
            FloatSlot.DK: np.zeros((k, k)),
            FloatSlot.K0: controller.K0, FloatSlot.KM1: controller.Km1, FloatSlot.RHO: controller.rho, FloatSlot.EPS: eps,
        }
    ref = DiscreteLTI(*_diagonal_system(references, k), dt=dt)
    comp = DiscreteLTI(*_diagonal_system(controller.compensators, k), dt=dt)
    return {
        FloatSlot.XC: ref.x, FloatSlot.ADC: ref.Ad, FloatSlot.BDC: ref.Bd, FloatSlot.CC: ref.C, FloatSlot.W: np.zeros(0),
        FloatSlot.XK: comp.x, FloatSlot.AK: comp.Ad, FloatSlot.BK: comp.Bd, FloatSlot.CK: comp.C, FloatSlot.DK: comp.D,
        FloatSlot.K0: np.zeros(k), FloatSlot.KM1: np.zeros(k), FloatSlot.RHO: np.zeros(k), FloatSlot.EPS: np.zeros(k),
    }


def _pilot_slots(pilots: Sequence[Pilot], ny: int, dt: float) -> tuple[dict[int, np.ndarray], dict[int, np.ndarray]]:
    """Packed arrays of the pilots (float slots, int slots) at the frame period ``dt``.

    Each delay is a DelayLine ring of its own; lead-lag / neuromuscular
    filters are stacked block-diagonally and discretised once (ZOH).
    """
    n = len(pilots)
    length = np.array([int(DelayLine(1, dt, p.delay).n[0]) + 1 for p in pilots], dtype=np.int64)
    if any(p.filtered for p in pilots):
        filt = DiscreteLTI(*_diagonal_system([p.transfer_function() for p in pilots], n), dt=dt)
        pf = (filt.x, filt.Ad, filt.Bd, filt.C, filt.D)
    else:
        pf = (np.zeros(0), np.zeros((0, 0)), np.zeros((0, n)), np.zeros((n, 0)), np.zeros((n, n)))
    floats = {
        FloatSlot.PROW: np.array([p.row for p in pilots], dtype=float).reshape(n, ny),
        FloatSlot.PGAIN: np.array([p.gain for p in pilots], dtype=float),
        FloatSlot.PATT: np.zeros(n),
        FloatSlot.PBUF: np.zeros((int(length.max(initial=1)), n)),
        FloatSlot.PXF: pf[0], FloatSlot.PAF: pf[1], FloatSlot.PBF: pf[2], FloatSlot.PCF: pf[3],
        FloatSlot.PDF: pf[4], FloatSlot.PERR: np.zeros(2 * n),
    }
    ints = {
        IntSlot.PN: length - 1, IntSlot.PLEN: length, IntSlot.PIDX: np.zeros(n),
        IntSlot.PCHAN: np.array([p.channel for p in pilots]), IntSlot.PINT: np.array([p.integrate for p in pilots]),
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
    packed.view(FloatSlot.AD)[:] = plant.Ad
    packed.view(FloatSlot.BD)[:] = plant.Bd
    packed.view(FloatSlot.D)[:] = plant.D
    for slot, a in ((FloatSlot.WN2, bank.wn2), (FloatSlot.C1, bank.c1), (FloatSlot.LO, bank.lo), (FloatSlot.HI, bank.hi),
                    (FloatSlot.RMAX, bank.rmax), (FloatSlot.JAM_POS, bank.jam_pos), (FloatSlot.HARD_POS, bank.hard_pos),
                    (IntSlot.FIRST, bank.first), (IntSlot.JAMMED, bank.jammed), (IntSlot.HARDOVER, bank.hardover)):
        packed.view(slot)[:] = a
    if failure.delay is not None:
        # DelayLine.set_delay: the ring restarts, pre-filled with the last command pushed.
        delay.set_delay(failure.delay)
        length = int(delay.n.max()) + 1
        packed.view(IntSlot.DN)[:] = delay.n
        packed.view(IntSlot.DSTATE)[:] = 0, length
        packed.view(FloatSlot.DBUF)[:length] = u_last
