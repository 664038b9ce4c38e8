"""PX4's normalisation of a mix (pseudo-inverse) matrix: one definition, two readers.

``ControlAllocationPseudoInverse::updateControlAllocationMatrixScale`` (PX4-Autopilot
``src/lib/control_allocation/control_allocation/ControlAllocationPseudoInverse.cpp``, commit
1316f1cea719, as the PX4 importer cites it) divides the columns of the mix ``M`` (m x 6, PX4's
axis order roll, pitch, yaw, fx, fy, fz) by six scales ``s``, so that the setpoints it allocates
are normalised.  Read by :func:`alloc.importers.px4.px4_scales` (the normalised effectiveness
``diag(s) B`` of an imported vehicle) and by the ``px4`` method (:mod:`alloc.methods.px4`),
whose thresholds are PX4's and apply to the normalised mix.  numpy only: both readers import it.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["FLT_EPSILON", "ZERO_ENTRY", "mix_scales"]

#: float32's machine epsilon: PX4's guards are ``> FLT_EPSILON``
FLT_EPSILON = float(np.finfo(np.float32).eps)
#: entries of the mix below this in magnitude count as zero (PX4: ``1e-3f``)
ZERO_ENTRY = 1e-3


def mix_scales(M6: np.ndarray, *, normalize_rpy: bool) -> np.ndarray:
    """PX4's six axis scales of the mix ``M6`` (m x 6, PX4's axis order; an absent axis a zero
    column), with the FLT_EPSILON guards of ``normalizeControlAllocationMatrix`` folded in (an
    unused scale is 1).

    Roll and pitch share ``max`` over the two columns of ``sqrt(|col|^2 / (n / 2))``, ``n`` the
    entries above :data:`ZERO_ENTRY` in magnitude; yaw is the column's signed maximum (both only
    with ``normalize_rpy``, a multirotor's setting, else 1); each force axis its own scale, the
    mean over the effectors acting on it of ``|M_i,axis|``, z first, an axis no effector acts on
    taking z's (an older PX4, commit 089afb091546, shared one scale, the mean norm of each
    effector's 3-vector: the same for a multirotor, which has only fz).
    """
    m = M6.shape[0]
    s = np.ones(6)
    if normalize_rpy:
        def rp_scale(col: np.ndarray) -> float:
            n = int((np.abs(col) > ZERO_ENTRY).sum())
            return math.sqrt(float(col @ col) / (n / 2.0)) if n > 0 else 1.0

        s_rp = max(rp_scale(M6[:, 0]), rp_scale(M6[:, 1]))
        s_yaw = float(M6[:, 2].max()) if m else 1.0
        if s_rp > FLT_EPSILON:
            s[0] = s[1] = s_rp
        if s_yaw > FLT_EPSILON:
            s[2] = s_yaw
    # each force axis its own scale: the mean |M_i,axis| over the effectors acting on it; an axis no
    # effector acts on takes z's scale (z first, 1 when nothing acts on z either)
    s_z = 1.0
    for axis in (5, 4, 3):
        magnitudes = np.abs(M6[:, axis])
        acting = int((magnitudes > FLT_EPSILON).sum())
        s[axis] = float(magnitudes.sum()) / acting if acting else s_z
        if axis == 5:
            s_z = s[5]
    if not s[3] > FLT_EPSILON:  # PX4 divides the three force columns only when x's scale is usable
        s[3:6] = 1.0
    return s
