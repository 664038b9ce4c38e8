"""Helpers shared by the optimisation-based methods."""

from __future__ import annotations

import numpy as np

from ..exceptions import OptionError
from ..method import FloatArray


#: Stage 2 of the two-stage methods keeps stage 1's moment within this relative band
#: instead of as an exact equality.  When stage 1's optimum is a single point of the box
#: (typical for unattainable demands) an exact equality leaves a degenerate feasible set
#: on which active-set solvers report false infeasibility; a 1e-9 band removes that and
#: changes the moment by far less than the ``exact`` tolerance (1e-6).
KEEP_RTOL = 1e-9


def row_basis(B: FloatArray, rtol: float = 1e-10) -> FloatArray:
    """Orthonormal rows ``Q'`` spanning the row space of ``B`` (``r x k``, ``r = rank B``).

    ``Q' B u = Q' B u1`` is the equality ``B u = B u1`` without the linearly dependent
    rows that a rank-deficient ``B`` would otherwise hand the solver.
    """
    if B.size == 0:
        return np.zeros((0, B.shape[0]))
    U, s, _ = np.linalg.svd(B, full_matrices=False)
    keep = s > rtol * (s[0] if s.size else 0.0)
    return U[:, keep].T


def check_backend(name: object, allowed: list[str], method: str) -> str:
    if not isinstance(name, str) or name not in allowed:
        raise OptionError(f"{method}: backend {name!r} not available; choose one of {allowed}")
    return name


def check_diagonal(W: FloatArray, field: str, method: str) -> FloatArray:
    """The diagonal of ``W``; the L1 methods weigh each axis/effector separately."""
    d = np.diagonal(W).copy()
    if np.count_nonzero(W - np.diag(d)):
        raise OptionError(f"{method}: {field} must be diagonal (Eqs 1.18-1.19 use weight vectors)")
    return d
