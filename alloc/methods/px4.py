"""PX4's multirotor allocator: pseudo-inverse with sequential desaturation and airmode.

Restated from PX4-Autopilot's ``control_allocator`` module (read, not copied):
``src/modules/control_allocator/ControlAllocation/ControlAllocationSequentialDesaturation.cpp``
(commit 1bbd11683f715ebce43c377e0c8628d783ba5b04; the yaw margin is ``MINIMUM_YAW_MARGIN`` of
its header), the same steps as PX4 has them now at
``src/lib/control_allocation/control_allocation/ControlAllocationSequentialDesaturation.cpp``
(commit ef41cd8aee7a), on top of ``ControlAllocationPseudoInverse.cpp`` (its normalisation:
:mod:`alloc.px4_mix`).  The unit tests that pin it are
``ControlAllocationSequentialDesaturationTest.cpp`` (commit 5cda32d5565b); their numbers are
reproduced in ``tests/alloc/test_px4.py``.

The mix ``M`` (m x k) is the weighted pseudo-inverse of Eq 1.23 (PX4's ``geninv``, the
Moore-Penrose inverse, when ``Wu`` is the identity), with entries below ``zero`` in magnitude
set to zero as PX4 does.  The unconstrained command is ``u = up + M (v - B up)`` (PX4: the
actuator trim plus the mix times the setpoint minus the control trim).  Saturation is then
removed axis by axis, each time by moving along one column of ``M`` (PX4's
``desaturateActuators``: the gain that brings the worst saturations back, applied, then half
of the gain still needed, so that remaining saturation is shared between the two ends):

``airmode="disabled"`` (``MC_AIRMODE`` 0, PX4's default)
    mix without yaw; thrust only reduced; roll, then pitch reduced; then yaw (below).
``airmode="roll_pitch"`` (1)
    mix without yaw; thrust raised or lowered to keep roll and pitch; then yaw (below).
``airmode="roll_pitch_yaw"`` (2)
    full mix; thrust raised or lowered; then yaw reduced.

"Then yaw" (PX4's ``mixYaw``): yaw is added and desaturated against limits whose upper end
is raised by 15 % of the range (PX4's ``MINIMUM_YAW_MARGIN``: some yaw at full thrust), then
thrust is only reduced.  Yaw is given up first, and thrust moves to keep roll and pitch.

Axes are found by name (the problem's ``axes``): ``roll``, ``pitch``, ``yaw`` and the vertical
force ``fz`` (or ``thrust``, the vehicle files' name for it); ``fx``, ``fy`` and any axis of
another name are mixed and never desaturated, like PX4's ``THRUST_X``/``THRUST_Y``.  A problem
without these names is allocated as PX4's plain pseudo-inverse with clipping.  "Only reduce
thrust" is a move that lowers the sum of the commands along the thrust column (PX4's
``increase_only`` on its ``fz`` column, whose entries are negative; the same rule whatever the
thrust axis's sign).

Units.  PX4 allocates normalised setpoints: it divides the mix's columns by scales
(:func:`alloc.px4_mix.mix_scales`), and its thresholds -- ``weak`` (0.2: an effector whose entry
is smaller does not size a desaturation step) and ``zero`` (1e-3: smaller entries are set to
zero) -- apply to that normalised mix.  This method computes the same scales from ``B`` and
applies the thresholds there, so ``B`` may be in physical units (N m, N) or already normalised
(``alloc.importers.px4``, ``normalize="px4"``; its scales are then 1): the commands are the
same.  Desaturating along a scaled column gives the same command (the gain absorbs the scale).

Differences from PX4, on purpose: float64 instead of float32; the scales are recomputed for
the problem as given (PX4 keeps the healthy vehicle's scales after a motor failure); the call's
bounds are the (rate-limited, Eq 1.28) bounds ``[lo, hi]``, so desaturation works within what
the step can reach (PX4 desaturates against the position limits and applies its slew limit
afterwards, as a clip); the command is clipped to those bounds at the end (PX4 clips in the
module after ``allocate``).
"""

from __future__ import annotations

import numpy as np
import alloc._engine._kernel_cache  # noqa: F401 - kernel caches placed before any kernel is decorated
from numba import njit

from .._engine._kernels import close_out, copy_demand, finish, packed_out, rate_window_into
from .._engine._linalg import RCOND, check_rcond
from ..exceptions import SolverError
from ..method import Method, register
from ..options import choice, real
from ..problem import MAX_MAGNITUDE, Problem
from ..px4_mix import ZERO_ENTRY, mix_scales
from ..result import EXACT_RTOL
from .pseudo_inverse import distribution_matrix

#: PX4's ``MC_AIRMODE`` values, by name (0, 1, 2)
AIRMODES = ("disabled", "roll_pitch", "roll_pitch_yaw")
#: PX4's ``MINIMUM_YAW_MARGIN``: the upper limits are raised by this fraction of the range
#: while yaw is desaturated, so some yaw remains at full thrust
YAW_MARGIN = 0.15
#: rows of the desaturation columns (``C``, ``U``) in the kernels
_ROLL, _PITCH, _YAW, _FZ = 0, 1, 2, 3
#: PX4's six axes, in its order (the roles an axis of the problem can have)
PX4_AXES = ("roll", "pitch", "yaw", "fx", "fy", "fz")
#: the problem's axis names (lower case) that take each role
ROLE_NAMES = {"roll": ("roll",), "pitch": ("pitch",), "yaw": ("yaw",), "fx": ("fx", "thrust_x"),
              "fy": ("fy", "thrust_y"), "fz": ("fz", "thrust", "thrust_z")}
#: the roles PX4 desaturates along (fx and fy are mixed, never desaturated)
DESATURATED = ("roll", "pitch", "yaw", "fz")


def axis_roles(axes: tuple[str, ...]) -> dict[str, int | None]:
    """Index of each of PX4's axes among ``axes`` (None where absent; the first axis with one of
    a role's names wins)."""
    lower = [a.lower() for a in axes]
    out: dict[str, int | None] = {}
    for role, names in ROLE_NAMES.items():
        out[role] = next((i for i, a in enumerate(lower) if a in names), None)
    return out


@njit(cache=True, nogil=True, _nrt=False)
def _gain(vec, usable, u, lo, hi, margin):  # pragma: no cover - compiled
    """PX4's ``computeDesaturationGain``: over the usable effectors outside ``[lo, top]``
    (``top = hi + margin (hi - lo)``), the step along ``vec`` that brings each back to its
    violated bound; the most negative step plus the most positive one (each counted from 0),
    so that opposite saturations balance."""
    k_min = 0.0
    k_max = 0.0
    for i in range(u.shape[0]):
        if usable[i] == 0.0:
            continue
        top = hi[i] + margin * (hi[i] - lo[i])
        if u[i] < lo[i]:
            g = (lo[i] - u[i]) / vec[i]
            k_min = min(k_min, g)
            k_max = max(k_max, g)
        if u[i] > top:
            g = (top - u[i]) / vec[i]
            k_min = min(k_min, g)
            k_max = max(k_max, g)
    return k_min + k_max


@njit(cache=True, nogil=True, _nrt=False)
def _desaturate(C, U, axis, u, lo, hi, margin, down):  # pragma: no cover - compiled
    """PX4's ``desaturateActuators`` along row ``axis`` of ``C`` (``U`` marks the usable
    entries), in place: the gain, then half the gain still needed.  ``down`` != 0: only a step
    whose gain has that sign (PX4's ``increase_only`` on thrust)."""
    vec = C[axis]
    g = _gain(vec, U[axis], u, lo, hi, margin)
    if down != 0.0 and g * down < 0.0:
        return
    for i in range(u.shape[0]):
        u[i] += g * vec[i]
    g = 0.5 * _gain(vec, U[axis], u, lo, hi, margin)
    for i in range(u.shape[0]):
        u[i] += g * vec[i]


@njit(cache=True, nogil=True)
def px4_mix(M1, myaw, yaw, C, U, mode, down, B, up, v, lo, hi, u):  # pragma: no cover - compiled
    """PX4's ``allocate`` into ``u`` for demand ``v`` within ``[lo, hi]`` (not yet clipped).

    ``M1`` is the first mix (m x k; yaw left out unless ``mode`` is 2), ``myaw`` the yaw column
    added later (``yaw`` its axis, -1 for none), ``C``/``U`` the normalised desaturation columns
    (rows roll, pitch, yaw, fz; a zero row for an absent axis) and their usable entries,
    ``mode`` 0/1/2 PX4's ``MC_AIRMODE``, ``down`` the sign of a thrust-lowering gain."""
    k, m = B.shape
    d = np.empty(k)  # v - B up
    for i in range(k):
        s = 0.0
        for j in range(m):
            s += B[i, j] * up[j]
        d[i] = v[i] - s
    for j in range(m):
        s = up[j]
        for i in range(k):
            s += M1[j, i] * d[i]
        u[j] = s
    if mode == 2:  # mixAirmodeRPY: thrust both ways, then yaw given up
        _desaturate(C, U, _FZ, u, lo, hi, 0.0, 0.0)
        _desaturate(C, U, _YAW, u, lo, hi, 0.0, 0.0)
        return
    if mode == 1:  # mixAirmodeRP: thrust both ways
        _desaturate(C, U, _FZ, u, lo, hi, 0.0, 0.0)
    else:  # mixAirmodeDisabled: thrust only reduced, then roll, then pitch
        _desaturate(C, U, _FZ, u, lo, hi, 0.0, down)
        _desaturate(C, U, _ROLL, u, lo, hi, 0.0, 0.0)
        _desaturate(C, U, _PITCH, u, lo, hi, 0.0, 0.0)
    # mixYaw: yaw added, room at the top raised by the margin, then thrust only reduced
    if yaw >= 0:
        for j in range(m):
            u[j] += myaw[j] * d[yaw]
    _desaturate(C, U, _YAW, u, lo, hi, YAW_MARGIN, 0.0)
    _desaturate(C, U, _FZ, u, lo, hi, 0.0, down)


@njit(cache=True, nogil=True)
def fused_px4(M1, myaw, yaw, C, U, mode, down, B, up, umin, umax, rate_min, rate_max, lo, hi, rtol, vmax,
              v, u_prev, dt):  # pragma: no cover - compiled
    """One call of ``px4`` (the allocator's packed fast path, with or without rate limits):
    domain checks, the Eq 1.28 window when ``dt > 0`` (into the scratch ``lo``, ``hi``),
    :func:`px4_mix`, then the clip, ``B u`` and the status of :func:`alloc._engine._kernels.finish`.
    Returns ``(out, code, 0)``: code 3 ``v``, 4 ``u_prev`` outside the valid domain."""
    k, m = B.shape
    out = packed_out(m, k)
    if not copy_demand(v, out, m, vmax):
        return out, 3, 0
    if dt > 0.0:
        for j in range(m):
            if not abs(u_prev[j]) <= vmax:
                return out, 4, 0
        rate_window_into(umin, umax, rate_min, rate_max, u_prev, dt, lo, hi)
        a, b = lo, hi
    else:
        a, b = umin, umax
    px4_mix(M1, myaw, yaw, C, U, mode, down, B, up, v, a, b, out[:m])
    code = finish(B, out[:m], a, b, v, out[m:m + k], rtol)
    close_out(out, m, k)
    return out, code, 0


@register("px4")
class PX4SequentialDesaturation(Method):
    equation = "Eq 1.23 + PX4 sequential desaturation"
    summary = "PX4 multirotor mixer: pseudo-inverse, then thrust/roll/pitch/yaw desaturated in turn (airmode)"
    options = {
        "airmode": choice("disabled", "PX4's MC_AIRMODE: which axes thrust may be raised to keep", AIRMODES),
        "rcond": real(RCOND, "relative singular-value cut-off of the inverse", low=0.0, high=1.0, high_open=True),
        "weak": real(0.2, "normalised |M| entries below this do not size a desaturation step (PX4: 0.2)",
                     low=0.0),
        "zero": real(ZERO_ENTRY, "normalised |M| entries below this are set to 0 (PX4: 1e-3)", low=0.0),
    }

    def __init__(self, problem: Problem, *, airmode: str = "disabled", rcond: float = RCOND, weak: float = 0.2,
                 zero: float = ZERO_ENTRY) -> None:
        super().__init__(problem)
        self.airmode = airmode
        M = distribution_matrix(problem, check_rcond(rcond, self.name))
        roles = axis_roles(problem.axes)
        # PX4's thresholds are on its normalised mix: scale the columns the way PX4 does
        # (alloc.px4_mix), so that B may be in any units (on a normalised B the scales are 1)
        M6 = np.zeros((problem.m, len(PX4_AXES)))
        for j, role in enumerate(PX4_AXES):
            if roles[role] is not None:
                M6[:, j] = M[:, roles[role]]
        s6 = mix_scales(M6, normalize_rpy=True)
        scale = np.ones(problem.k)
        for j, role in enumerate(PX4_AXES):
            if roles[role] is not None:
                scale[roles[role]] = s6[j]
        M[np.abs(M / scale) < zero] = 0.0  # PX4's normalizeControlAllocationMatrix
        self.M = M
        Mn = M / scale
        # desaturation moves along the normalised columns (PX4's); the step's size is the gain's.
        # Rows roll, pitch, yaw, fz; an absent axis is a zero row (its steps are 0).
        C = np.zeros((len(DESATURATED), problem.m))
        for r, role in enumerate(DESATURATED):
            if roles[role] is not None:
                C[r] = Mn[:, roles[role]]
        U = (np.abs(C) >= weak).astype(float) * (C != 0.0)
        yaw = -1 if roles["yaw"] is None else roles["yaw"]
        full = airmode == "roll_pitch_yaw"
        # the first mix leaves yaw out except in full airmode (PX4 mixes it separately)
        M1 = M.copy()
        myaw = np.zeros(problem.m)
        if yaw >= 0 and not full:
            M1[:, yaw] = 0.0
            myaw = M[:, yaw].copy()
        # the sign of a thrust step that lowers the commands' sum (PX4: a positive gain on fz)
        down = 1.0 if C[_FZ].sum() <= 0.0 else -1.0
        p = problem
        # writable contiguous copies: the compiled kernels see one array type (no recompiles)
        self._mix = (M1, myaw, yaw if not full else -1, C, U, AIRMODES.index(airmode), down, np.array(p.B),
                     np.array(p.up))
        self.packed = self.packed_rate = (fused_px4, (*self._mix, np.array(p.umin), np.array(p.umax),
                                                      np.array(p.rate_min), np.array(p.rate_max),
                                                      np.zeros(p.m), np.zeros(p.m), EXACT_RTOL, MAX_MAGNITUDE))

    def solve(self, v, lo, hi, u_prev):
        u = np.empty(self.problem.m)
        lo, hi = np.array(lo, dtype=float), np.array(hi, dtype=float)
        px4_mix(*self._mix, np.array(v, dtype=float), lo, hi, u)
        if not np.isfinite(u).all():  # beyond the float range: the allocator's safe answer
            raise SolverError("px4: non-finite command (demand or mix beyond the float range)")
        return np.minimum(np.maximum(u, lo), hi), 0
