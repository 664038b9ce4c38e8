"""PX4's multirotor allocator: pseudo-inverse with sequential desaturation and airmode.

Restated from PX4-Autopilot's ``control_allocator`` module (read, not copied):
``src/modules/control_allocator/ControlAllocation/ControlAllocationSequentialDesaturation.cpp``
(commit 1bbd11683f715ebce43c377e0c8628d783ba5b04; the yaw margin is ``MINIMUM_YAW_MARGIN`` of
its header) on top of ``ControlAllocationPseudoInverse.cpp`` (commit
089afb0915460c7768ea0e3ee1dad5a93c20ab5e).  The unit tests that pin it are
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

from .._linalg import RCOND, check_rcond
from ..exceptions import SolverError
from ..method import FloatArray, Method, register
from ..options import choice, real
from ..problem import Problem
from ..px4_mix import ZERO_ENTRY, mix_scales
from .pseudo_inverse import distribution_matrix

#: PX4's ``MC_AIRMODE`` values, by name (0, 1, 2)
AIRMODES = ("disabled", "roll_pitch", "roll_pitch_yaw")
#: PX4's ``MINIMUM_YAW_MARGIN``: the upper limits are raised by this fraction of the range
#: while yaw is desaturated, so some yaw remains at full thrust
YAW_MARGIN = 0.15
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


def desaturation_gain(vec: FloatArray, u: FloatArray, lo: FloatArray, hi: FloatArray, usable: np.ndarray) -> float:
    """PX4's ``computeDesaturationGain``: over the usable effectors outside ``[lo, hi]``, the
    step along ``vec`` that brings each back to its violated bound; the most negative step plus
    the most positive one (each at least 0 in magnitude), so opposite saturations balance."""
    below = usable & (u < lo)
    above = usable & (u > hi)
    k = np.concatenate(((lo[below] - u[below]) / vec[below], (hi[above] - u[above]) / vec[above]))
    if k.size == 0:
        return 0.0
    return min(float(k.min()), 0.0) + max(float(k.max()), 0.0)


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
        # desaturation moves along the normalised columns (PX4's); the step's size is the gain's
        self._cols = {role: (None if roles[role] is None else np.ascontiguousarray(Mn[:, roles[role]]))
                      for role in DESATURATED}
        self._usable = {role: (None if c is None else np.abs(c) >= weak) for role, c in self._cols.items()}
        yaw = roles["yaw"]
        # the first mix leaves yaw out except in full airmode (PX4 mixes it separately)
        self._M_first = M.copy()
        if yaw is not None and airmode != "roll_pitch_yaw":
            self._M_first[:, yaw] = 0.0
        self._Myaw = None if yaw is None or airmode == "roll_pitch_yaw" else np.ascontiguousarray(M[:, yaw])
        self._yaw = yaw
        thrust = self._cols["fz"]
        # the sign of a thrust step that lowers the commands' sum (PX4: a positive gain on fz)
        self._thrust_down = 1.0 if thrust is None or thrust.sum() <= 0.0 else -1.0
        self._B = np.array(problem.B)
        self._up = np.array(problem.up)

    def _desaturate(self, u: FloatArray, role: str, lo: FloatArray, hi: FloatArray, reduce_only: bool = False) -> None:
        """PX4's ``desaturateActuators`` along ``role``'s column, in place."""
        vec = self._cols[role]
        if vec is None:
            return
        usable = self._usable[role]
        gain = desaturation_gain(vec, u, lo, hi, usable)
        if reduce_only and gain * self._thrust_down < 0.0:
            return
        u += gain * vec
        u += 0.5 * desaturation_gain(vec, u, lo, hi, usable) * vec

    def _mix_yaw(self, u: FloatArray, d: FloatArray, lo: FloatArray, hi: FloatArray) -> None:
        """PX4's ``mixYaw``: yaw added, desaturated with 15 % more room at the top, thrust only reduced."""
        if self._Myaw is not None:
            u += self._Myaw * d[self._yaw]
        self._desaturate(u, "yaw", lo, hi + YAW_MARGIN * (hi - lo))
        self._desaturate(u, "fz", lo, hi, reduce_only=True)

    def solve(self, v, lo, hi, u_prev):
        d = v - self._B @ self._up
        u = self._up + self._M_first @ d
        mode = self.airmode
        if mode == "disabled":
            self._desaturate(u, "fz", lo, hi, reduce_only=True)
            self._desaturate(u, "roll", lo, hi)
            self._desaturate(u, "pitch", lo, hi)
            self._mix_yaw(u, d, lo, hi)
        elif mode == "roll_pitch":
            self._desaturate(u, "fz", lo, hi)
            self._mix_yaw(u, d, lo, hi)
        else:
            self._desaturate(u, "fz", lo, hi)
            self._desaturate(u, "yaw", lo, hi)
        if not np.isfinite(u).all():  # beyond the float range: the allocator's safe answer
            raise SolverError("px4: non-finite command (demand or mix beyond the float range)")
        return np.minimum(np.maximum(u, lo), hi), 0
