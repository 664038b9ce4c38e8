"""The stage-1 statistic of :mod:`.detection` and the whitening of its windows: the GLR of a
linear Gaussian model (Basseville and Nikiforov, *Detection of Abrupt Changes*, 1993, 4.2)."""

from __future__ import annotations

from typing import Any

import numpy as np

from ..exceptions import OptionError
from ..problem import as_float_array, check_magnitude

def correlation_setting(value: Any) -> np.ndarray:
    """``noise_correlation`` as a 1-D array of finite lags in (-1, 1), or OptionError naming it."""
    arr = as_float_array("noise_correlation", value, OptionError)
    if arr.ndim != 1 or arr.size == 0 or arr.size > 100_000:
        raise OptionError(f"noise_correlation: expected a sequence of 1 to 100000 lags, got shape {arr.shape}")
    check_magnitude("noise_correlation", arr, OptionError)
    if not (np.abs(arr) < 1.0).all():
        i = int(np.argmax(~(np.abs(arr) < 1.0)))
        raise OptionError(f"noise_correlation: lag {i + 1} = {arr[i]:g} is not inside (-1, 1)")
    return arr.copy()


def whitener(rho: np.ndarray, n: int) -> np.ndarray:
    """``W`` (n, n) with ``W Sigma W^T = I``, ``Sigma`` the window's Toeplitz correlation matrix."""
    # here, not at import: scipy.linalg is 0.2 s of the service's start, and few detectors whiten
    from scipy.linalg import LinAlgError, cholesky, solve_triangular, toeplitz

    lags = np.zeros(n)
    lags[0] = 1.0
    use = min(n - 1, rho.size)
    lags[1:1 + use] = rho[:use]
    try:
        factor = cholesky(toeplitz(lags), lower=True)
    except LinAlgError:
        raise OptionError(f"noise_correlation: not positive definite over the {n}-sample window "
                          "(not the autocorrelation of any noise)") from None
    return solve_triangular(factor, np.eye(n), lower=True)


def linear_glr(S: np.ndarray, U: np.ndarray, c: np.ndarray, whiten: np.ndarray | None = None) -> np.ndarray:
    """Twice the log GLR of ``s_t = c (theta_1 + theta_2 u_t) + e`` per column, ``e ~ N(0, c Sigma)``.

    Generalised least squares: ``s``, the constant regressor ``x_1`` and ``u`` are whitened
    first (``W``, ``W Sigma W^T = I``; none: white), ``u``'s part along ``x_1`` removed (``u_c``,
    orthogonal columns), then ``(x_1 . s)^2 / (c x_1 . x_1) + (u_c . s)^2 / (c u_c . u_c)``,
    chi-square with the rank's degrees of freedom under ``theta = 0``.  Unwhitened this is
    ``(sum s)^2 / (n c) + (sum s (u - mean u))^2 / (c sum (u - mean u)^2)``.  A column whose
    ``u`` does not vary contributes only the first term (rank 1: no information on the second
    parameter, none invented).
    """
    n = S.shape[-2]  # leading axes, if any, are windows (window_statistics)
    x1 = np.ones(n)
    if whiten is not None:
        S, U, x1 = whiten @ S, whiten @ U, whiten @ x1
    x11 = float(x1 @ x1)
    Uc = U - x1[:, None] * ((x1 @ U) / x11)[..., None, :]
    cc = np.where(c > 0, c, np.inf)
    s0 = x1 @ S
    s1 = np.einsum("...ij,...ij->...j", S, Uc)
    uu = np.einsum("...ij,...ij->...j", Uc, Uc)
    # does u vary, beyond round-off of the whitening? (relative to u's own size, not u_c's)
    scale = np.maximum(np.abs(U).max(axis=-2, initial=0.0), 1e-300)
    varies = uu > (1e-12 * scale) ** 2 * n
    term2 = np.where(varies, s1 * s1 / (cc * np.where(varies, uu, 1.0)), 0.0)
    return s0 * s0 / (x11 * cc) + term2
