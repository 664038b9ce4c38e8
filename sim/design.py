"""Linear sliding-mode design tools: regular form, LQ sliding surface, equivalent control.

These follow seed section 2.1.7 (itself a transcription of Edwards & Spurgeon,
*Sliding Mode Control: Theory and Applications*, 1998, pp. 66 and 74) and
section 2.1.4 (equivalent control).  An LQR design is provided for the
comparison controller of seed section 2.2.

Conventions
-----------
* Plant ``x' = A x + B u`` with ``A`` (n, n), ``B`` (n, m), ``rank(B) = m``.
* Switching function ``sigma = S x`` (seed Eq 2.14, 2.32), ``S`` (m, n).
* Every gain returned here multiplies the state directly: ``u_eq = K_eq x``
  (seed Eq 2.15) and ``u_lqr = -K_lqr x`` (the MATLAB ``lqr`` sign, which is
  how the seed prints ``K_LQR`` in section 2.2).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg

__all__ = [
    "RegularForm",
    "regular_form",
    "lq_sliding_surface",
    "equivalent_control_gain",
    "lqr_gain",
]


def _as_matrix(x: np.ndarray, name: str) -> np.ndarray:
    a = np.asarray(x, dtype=float)
    if a.ndim == 1:
        a = a[:, None]
    if a.ndim != 2:
        raise ValueError(f"{name} must be a 2-D matrix, got shape {a.shape}")
    return a


def _check_plant(A: np.ndarray, B: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    A = _as_matrix(A, "A")
    B = _as_matrix(B, "B")
    n = A.shape[0]
    if A.shape != (n, n):
        raise ValueError(f"A must be square, got shape {A.shape}")
    if B.shape[0] != n:
        raise ValueError(f"B must have {n} rows to match A, got shape {B.shape}")
    if np.linalg.matrix_rank(B) != B.shape[1]:
        raise ValueError(f"B must have full column rank {B.shape[1]}, got rank {np.linalg.matrix_rank(B)}")
    return A, B


@dataclass(frozen=True)
class RegularForm:
    """A plant in regular form (seed Eqs 2.33-2.37).

    Attributes
    ----------
    T_r : ndarray, shape (n, n)
        Orthogonal change of coordinates ``z = T_r x`` (Eq 2.33) with
        ``T_r B = [0; B2]`` (Eq 2.34).
    A : ndarray, shape (n, n)
        ``T_r A T_r^T`` (Eq 2.35).
    B : ndarray, shape (n, m)
        ``T_r B = [0; B2]`` (Eq 2.34).
    m : int
        Number of inputs; ``z_2`` is the last ``m`` coordinates.
    """

    T_r: np.ndarray
    A: np.ndarray
    B: np.ndarray
    m: int

    @property
    def _k(self) -> int:
        return self.A.shape[0] - self.m

    @property
    def A11(self) -> np.ndarray:
        """Upper-left (n-m, n-m) block of Eq 2.35."""
        return self.A[: self._k, : self._k]

    @property
    def A12(self) -> np.ndarray:
        """Upper-right (n-m, m) block of Eq 2.35."""
        return self.A[: self._k, self._k :]

    @property
    def A21(self) -> np.ndarray:
        """Lower-left (m, n-m) block of Eq 2.35 (matched: SMC is insensitive to it)."""
        return self.A[self._k :, : self._k]

    @property
    def A22(self) -> np.ndarray:
        """Lower-right (m, m) block of Eq 2.35 (matched)."""
        return self.A[self._k :, self._k :]

    @property
    def B2(self) -> np.ndarray:
        """Nonsingular (m, m) input block of Eq 2.34."""
        return self.B[self._k :, :]


def regular_form(A: np.ndarray, B: np.ndarray) -> RegularForm:
    """Transform ``(A, B)`` to regular form by a QR decomposition of ``B``.

    Following Edwards & Spurgeon's ``rfm`` m-file (seed section 2.1.7, Eq 2.34),
    ``B = Q R`` with ``Q`` orthogonal; the first ``m`` columns of ``Q`` span
    range(B), so moving the first ``m`` rows of ``Q^T`` to the bottom gives

    .. math:: T_r = \\begin{bmatrix} Q_{:, m:}^T \\\\ Q_{:, :m}^T \\end{bmatrix},
              \\qquad T_r B = \\begin{bmatrix} 0 \\\\ B_2 \\end{bmatrix}.

    NumPy's QR is LAPACK's Householder factorisation, the same as MATLAB's, so
    the signs of ``T_r`` match the matrix printed in seed section 2.2.

    Parameters
    ----------
    A : array_like, shape (n, n)
    B : array_like, shape (n, m)
        Full column rank.

    Returns
    -------
    RegularForm
    """
    A, B = _check_plant(A, B)
    m = B.shape[1]
    Q, _ = np.linalg.qr(B, mode="complete")
    T_r = np.vstack([Q[:, m:].T, Q[:, :m].T])
    B_reg = T_r @ B
    # The top n-m rows are orthogonal to range(B) by construction; clean the round-off.
    B_reg[:-m, :] = 0.0
    return RegularForm(T_r=T_r, A=T_r @ A @ T_r.T, B=B_reg, m=m)


def lq_sliding_surface(A: np.ndarray, B: np.ndarray, Q: np.ndarray) -> np.ndarray:
    """Sliding surface ``S`` minimising the LQ cost of the sliding motion.

    Edwards & Spurgeon's ``lqcf`` method (seed section 2.1.7, the "quadratic
    minimization" design of Eq 2.44, used for ``S`` in section 2.2): minimise

    .. math:: J = \\int_{t_s}^\\infty x^T Q x \\, dt

    along the sliding motion.  In regular-form coordinates
    ``T_r Q T_r^T = [[Q11, Q12], [Q21, Q22]]`` the reduced-order problem
    ``z1' = A11 z1 + A12 z2`` with ``z2`` as the "control" has the cross term
    removed by

    .. math:: \\hat Q = Q_{11} - Q_{12} Q_{22}^{-1} Q_{21}, \\qquad
              \\hat A = A_{11} - A_{12} Q_{22}^{-1} Q_{21},

    and its LQR gain ``K = Q22^{-1} A12^T P`` (``P`` from the Riccati equation
    of ``(Â, A12, Q̂, Q22)``) gives ``M = K + Q22^{-1} Q21`` (Eq 2.41, with
    the sliding motion ``z2 = -M z1``, Eq 2.43).  With ``S2 = I``,

    .. math:: S = [M \\;\\; I_m] \\, T_r .

    Parameters
    ----------
    A : array_like, shape (n, n)
    B : array_like, shape (n, m)
    Q : array_like, shape (n, n)
        Symmetric state weight in the original coordinates; the ``Q22`` block
        of ``T_r Q T_r^T`` must be positive definite.

    Returns
    -------
    ndarray, shape (m, n)
        Switching-function matrix ``S`` in original coordinates (Eq 2.32).
    """
    A, B = _check_plant(A, B)
    Q = _as_matrix(Q, "Q")
    n, m = B.shape
    if Q.shape != (n, n):
        raise ValueError(f"Q must have shape {(n, n)}, got {Q.shape}")
    rf = regular_form(A, B)
    Qt = rf.T_r @ Q @ rf.T_r.T
    k = n - m
    Q11, Q12, Q22 = Qt[:k, :k], Qt[:k, k:], Qt[k:, k:]
    Q22_inv_Q21 = np.linalg.solve(Q22, Q12.T)
    Q_hat = Q11 - Q12 @ Q22_inv_Q21
    A_hat = rf.A11 - rf.A12 @ Q22_inv_Q21
    P = scipy.linalg.solve_continuous_are(A_hat, rf.A12, Q_hat, Q22)
    K = np.linalg.solve(Q22, rf.A12.T @ P)
    M = K + Q22_inv_Q21
    return np.hstack([M, np.eye(m)]) @ rf.T_r


def equivalent_control_gain(A: np.ndarray, B: np.ndarray, S: np.ndarray) -> np.ndarray:
    """Gain ``K_eq`` of the equivalent control ``u_eq = K_eq x`` (seed Eq 2.15).

    .. math:: u_{eq} = -(S B)^{-1} S A \\, x

    Parameters
    ----------
    A : array_like, shape (n, n)
    B : array_like, shape (n, m)
    S : array_like, shape (m, n)
        Switching-function matrix with ``S B`` nonsingular.

    Returns
    -------
    ndarray, shape (m, n)
    """
    A, B = _check_plant(A, B)
    S = np.atleast_2d(np.asarray(S, dtype=float))
    if S.shape != (B.shape[1], A.shape[0]):
        raise ValueError(f"S must have shape {(B.shape[1], A.shape[0])}, got {S.shape}")
    return -np.linalg.solve(S @ B, S @ A)


def lqr_gain(A: np.ndarray, B: np.ndarray, Q: np.ndarray, R: np.ndarray | float) -> np.ndarray:
    """Continuous-time LQR gain ``K`` for ``u = -K x`` (MATLAB ``lqr`` convention).

    .. math:: K = R^{-1} B^T P, \\qquad
              A^T P + P A - P B R^{-1} B^T P + Q = 0

    Parameters
    ----------
    A : array_like, shape (n, n)
    B : array_like, shape (n, m)
    Q : array_like, shape (n, n)
    R : float or array_like, shape (m, m)

    Returns
    -------
    ndarray, shape (m, n)
    """
    A, B = _check_plant(A, B)
    R = np.atleast_2d(np.asarray(R, dtype=float))
    P = scipy.linalg.solve_continuous_are(A, B, np.asarray(Q, dtype=float), R)
    return np.linalg.solve(R, B.T @ P)
