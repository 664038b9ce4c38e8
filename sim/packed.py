"""The packed state of the closed loop and its two compiled step functions.

Every array the compiled step touches lives in one float64 buffer ``F`` or one int64
buffer ``I``: numba unboxes each call argument (about 0.2 us per array), so the step takes
two buffers instead of some fifty arrays.  Slot ``s`` is described by
``I[3 s : 3 s + 3] = (offset, rows, cols)``; float slots index ``F``, int slots (numbered
after them) index ``I``.

:func:`observe` computes everything up to the allocator demand ``v`` (outputs, divergence
check, pilots, controller); :func:`advance` records a step, integrates the controller, plant,
delay and actuators, then observes the next step.  The compiled step repeats the numpy
formulation operation for operation (``np.dot`` is the BLAS call numpy's ``@`` makes), so
results are identical to the last bit.  :mod:`sim.engine` fills the buffers and runs the loop.
"""

from __future__ import annotations

from enum import IntEnum, auto

import numpy as np
import alloc._engine._kernel_cache  # noqa: F401 - kernel caches placed before any kernel is decorated
from numba import njit

from alloc.result import EXACT_RTOL
from sim.blocks import actuator_heun_step

__all__ = ["FloatSlot", "IntSlot", "Misc", "N_MISC", "OK", "DIVERGED", "PENDING", "Packed", "observe", "advance",
           "record_columns"]


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
    O = auto()
    SCRATCH = auto()
    #: per output: the quantisation step of the measured value (0: none; sim.world ``quantised``)
    QSTEP = auto()


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
#: pilots with lead-lag / neuromuscular dynamics, conditional integration (:func:`anti_windup_on`),
#: measured outputs quantised (``FloatSlot.QSTEP``), and the first ``inputs`` column of the
#: per-step gust increment of the plant state (0: no turbulence; :mod:`sim.world`).
Misc = IntEnum("Misc", ["N_STEPS", "RECORD_EVERY", "FAIL_STEP", "SMC", "OBSERVED", "SIGN", "ACTUATORS", "FRAME",
                        "PFILTER", "ANTI_WINDUP", "QUANT", "GUST"], start=0, module=__name__)


N_MISC = len(Misc)

# IntSlot.DSTATE entries: ring index, ring length (DelayLine semantics)
_D_INDEX, _D_LENGTH = 0, 1

# a demand met to this relative tolerance is met (alloc.result.EXACT_RTOL, the library's exact status)
_EXACT_RTOL = EXACT_RTOL

# step status
OK, DIVERGED, PENDING = 0, 1, 2


class Packed:
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
def observe(step: int, F: np.ndarray, I: np.ndarray, inputs: np.ndarray) -> int:
    """Everything up to the allocator demand at ``step``: outputs, divergence, pilots, SMC, ``v``.

    Matrix products go through ``np.dot`` (the BLAS call numpy's ``@`` makes)
    in the order of the reference formulation, so results match it exactly.
    Returns ``DIVERGED`` (see :func:`sim.result.divergence_check`) or ``OK``.
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
    if misc[Misc.QUANT]:
        # a quantised sensor: the flight computer reads the nearest multiple of the step
        qstep = _vec(F, I, FloatSlot.QSTEP)
        for i in range(ny):
            if qstep[i] > 0.0:
                z[i] = qstep[i] * np.floor(z[i] / qstep[i] + 0.5)
    for i in range(k):
        yi = y[ctrl[i]]
        if not np.isfinite(yi) or abs(yi) > bound[i]:
            return DIVERGED
    for xi in x:
        if not np.isfinite(xi):
            return DIVERGED
    if step % misc[Misc.FRAME] != 0:
        return OK  # between frames the flight-control computer's outputs are held
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
            return DIVERGED
    return OK


@njit(cache=True)
def _short_of_demand(v: np.ndarray, v_achieved: np.ndarray) -> bool:
    """True when the allocator fell short: ``max|v - B u| > rtol max(1, max|v|)`` (``alloc``'s exact test)."""
    err, vmax = 0.0, 1.0
    for i in range(v.size):
        err = max(err, abs(v_achieved[i] - v[i]))
        vmax = max(vmax, abs(v[i]))
    return not err <= _EXACT_RTOL * vmax


@njit(cache=True)
def advance(
    step: int, u_cmd: np.ndarray, v_achieved: np.ndarray, F: np.ndarray, I: np.ndarray,
    inputs: np.ndarray, rec: np.ndarray,
) -> int:
    """Record ``step``, integrate to ``step + 1`` with ``u_cmd`` and observe it (unless a failure is due).

    ``v_achieved = B u_cmd`` as the allocator sees it; ``v - v_achieved`` is
    recorded as unallocated.

    Returns the status of :func:`observe`, or ``PENDING`` when the next
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
        # column order of record_columns
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
    if misc[Misc.GUST]:
        # turbulence: the exact ZOH increment of the gust term, precomputed per step (sim.world)
        off = misc[Misc.GUST]
        for i in range(x.size):
            x[i] += inputs[step, off + i]
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
        return PENDING
    return observe(nxt, F, I, inputs)


def record_columns(k: int, m: int, n_pilots: int) -> dict[str, slice]:
    """Columns of the record matrix, in the order :func:`advance` writes them."""
    widths = [("t", 1), ("ref", k), ("out", k), ("cmd", k), ("pseudo", k), ("unalloc", k),
              ("eff", m), ("rate", m), ("lo", m), ("hi", m), ("rmax", m), ("extra", 2 * n_pilots)]
    cols, c = {}, 0
    for name, width in widths:
        cols[name] = slice(c, c + width)
        c += width
    return cols
