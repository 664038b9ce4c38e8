"""Recursive least squares with exponential forgetting and a parameter-change penalty.

The estimator minimises, at every sample ``n``, the seed's criterion (Eq 1.4), one output
row ``r`` at a time::

    J_r(theta) = sum_{i<=n} lambda^(n-i) (y_r(i) - w(i)^T theta)^2 + alpha ||theta - theta_r(n-1)||^2

where ``w`` is the regressor (effector commands, optionally states and a constant) and
``theta_r(n-1)`` the previous estimate.  The minimiser is, in information form,

    theta_r(n) = (R_n + alpha I)^(-1) (q_r(n) + alpha theta_r(n-1)),
    R_n = lambda R_(n-1) + w w^T,   q_r(n) = lambda q_r(n-1) + y_r(n) w.

Why this form is numerically robust: the matrix solved, ``R_n + alpha I``, has every
eigenvalue in ``[alpha, alpha + max|w|^2 / (1 - lambda)]``, so its condition number is at
most ``1 + max|w|^2 / (alpha (1 - lambda))`` -- the penalty is what keeps it invertible when
the data carry no information (the seed's ``u = 0`` case, section 1.3.2).  In floating point
that holds only while ``alpha`` is above the rounding of ``R_n``'s entries (about ``eps
trace R_n`` per sample of memory): with ``|w| = 1e8`` and ``alpha = 1`` an unexcited direction
of ``R_n + alpha I`` was rounded to zero.  So the penalty solved with is ``alpha_n = max(alpha,
PENALTY_FLOOR trace R_n)`` (the stated fallback; ``alpha`` itself whenever ``trace R_n <= 1e10
alpha``, every ordinary case), and the condition number is at most ``1 + 1e10`` whatever
the data: the estimate is within about ``1e10 eps`` of the exact minimiser (1.1e-5 relative
measured at the bound, tests/alloc/estimation/test_hostile_inputs.py).  The covariance
below uses the same ``alpha_n``, so it stays exact for the estimate computed.

Domain.  Settings and samples are finite with ``|x| <= 1e50`` (:data:`alloc.domain.MAX_MAGNITUDE`),
``penalty`` in ``[1e-50, 1e12]``, the standard deviations at most ``1e24`` (their squares
within it); the state (``theta``, ``R``, ``q``, the covariances, the
residual variance) is kept within the same bound -- a sample that would take any of it
beyond is refused (SampleError naming ``w`` or ``y``, the state unchanged), so every output
is finite and every state stored loads again.  Memory is priced before allocation: the
state's ``8 (9 p^2 + 2 k p)`` bytes at most :data:`MAX_STATE_BYTES`.
There is no covariance matrix to wind up: in a direction the data never excite, ``R_n`` has
no information, the gain there is ``alpha / alpha = 1`` on the previous estimate and the
estimate does not move (the behaviour with uninformative data, stated and tested).

Uncertainty.  The estimation error ``e_n = theta(n) - theta`` of constant true parameters
``theta`` obeys a linear recursion driven by the measurement noise and the prior error::

    eps_n = lambda eps_(n-1) + w_n nu_n,      e_n = G_n (eps_n + alpha e_(n-1)),   G_n = (R_n + alpha I)^(-1)

so the joint covariance of ``(eps_n, e_n)`` is propagated exactly (two ``2p x 2p``
congruences a sample: one per unit of noise variance, one per unit of prior variance).
The reported standard deviations are ``sqrt(sigma_r^2 S_noise + s0_r^2 S_prior)`` on the
diagonal: exact (Gaussian) for constant parameters and the stated noise; after a change of
the parameters the estimate also carries a tracking bias that no covariance describes.
Both matrices stay bounded: the recursion's transition has no eigenvalue above 1, and in
unexcited directions the prior's uncertainty is kept, never grown.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..domain import MAX_MAGNITUDE, MIN_WEIGHT, as_float_array, check_magnitude, short_repr
from ..exceptions import OptionError
from ._checks import (
    SampleError,
    StateError,
    sample_vector,
    setting_real,
    setting_vector,
    state_array,
    state_count,
    state_mapping,
)

__all__ = ["RecursiveLeastSquares", "EffectivenessRLS", "PENALTY_FLOOR", "MAX_STATE_BYTES"]

#: The penalty solved with is at least this fraction of ``trace R_n`` (module docstring): the
#: matrix solved has condition number at most ``1 + 1 / PENALTY_FLOOR``.
PENALTY_FLOOR = 1e-10
#: The state's size, ``8 (9 p^2 + 2 k p)`` bytes (``R``, the two ``2p x 2p`` covariances,
#: ``theta`` and ``q``), priced before it is allocated: 32 MiB, ``p`` up to about 680.  An
#: update's temporaries are a few times the state and its time grows as ``p^3``.
MAX_STATE_BYTES = 32 * 2 ** 20

_STATE_KEYS = ("n_outputs", "n_regressors", "forgetting", "penalty", "theta", "R", "q", "S_noise", "S_prior",
               "noise_std", "prior_std", "noise_known", "samples", "residual_var")


class RecursiveLeastSquares:
    """Seed Eq 1.4 for ``k`` outputs sharing one regressor of length ``p``.

    Parameters
    ----------
    n_outputs, n_regressors : int
        ``k`` outputs (rows estimated), ``p`` regressors (columns).
    forgetting : float
        ``lambda`` in (0, 1]; the memory is about ``1 / (1 - lambda)`` samples.
    penalty : float
        ``alpha > 0`` of Eq 1.4, in regressor units squared.  Directions with less
        accumulated information than ``alpha`` are held near the previous estimate.
    theta0 : array (k, p), optional
        Prior estimate (default zeros), e.g. the nominal effectiveness matrix.
    prior_std : float or array (k,)
        Standard deviation of each prior parameter (per output row).
    noise_std : float or array (k,), optional
        Measurement noise of each output.  Given, the uncertainty is exact for constant
        parameters; omitted, it is estimated from the prediction errors (exponentially
        weighted with the same forgetting; about ``1 + w^T P w`` too large, so conservative).
    """

    def __init__(self, n_outputs: int, n_regressors: int, *, forgetting: float = 0.995, penalty: float = 1.0,
                 theta0: Any = None, prior_std: Any = 1.0, noise_std: Any = None) -> None:
        for name, value in (("n_outputs", n_outputs), ("n_regressors", n_regressors)):
            if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)) or not 1 <= value <= 4096:
                raise OptionError(f"{name}: expected an integer in [1, 4096], got {short_repr(value)}")
        k, p = int(n_outputs), int(n_regressors)
        state_bytes = 8 * (9 * p * p + 2 * k * p)
        if state_bytes > MAX_STATE_BYTES:
            raise OptionError(f"n_regressors: a state of {state_bytes / 2 ** 20:.0f} MiB for {k} outputs and {p} "
                              f"regressors; at most {MAX_STATE_BYTES // 2 ** 20} MiB")
        self.k, self.p = k, p
        self.forgetting = setting_real("forgetting", forgetting, 0.0, 1.0, lo_open=True)
        self.penalty = setting_real("penalty", penalty, MIN_WEIGHT, 1e12)
        self.prior_std = _std_setting("prior_std", prior_std, k)
        self.noise_known = noise_std is not None
        self.noise_std = _std_setting("noise_std", noise_std, k) if noise_std is not None else np.ones(k)
        if theta0 is None:
            self.theta = np.zeros((k, p))
        else:
            theta = as_float_array("theta0", theta0, OptionError)
            if theta.shape != (k, p):
                raise OptionError(f"theta0: expected a finite ({k}, {p}) array, got shape {theta.shape}")
            check_magnitude("theta0", theta, OptionError)
            self.theta = theta
        self._reset_information()
        self.samples = 0
        self.residual_var = self.noise_std ** 2

    def _reset_information(self) -> None:
        p = self.p
        self.R = np.zeros((p, p))
        self.q = self.theta * 0.0  # (k, p): the data's part; the prior enters through alpha
        self.S_noise = np.zeros((2 * p, 2 * p))
        self.S_prior = np.zeros((2 * p, 2 * p))
        self.S_prior[p:, p:] = np.eye(p)

    def reset(self, prior_std: Any = None) -> None:
        """Forget all data: keep the current estimate as the new prior (``prior_std`` per row,
        default the constructor's).  For use after a detected change (seed section 1.3.2.2:
        restart so the estimator can follow it)."""
        if prior_std is not None:
            self.prior_std = _std_setting("prior_std", prior_std, self.k)
        self._reset_information()

    def update(self, w: Any, y: Any) -> None:
        """One sample: regressor ``w`` (p,), measured outputs ``y`` (k,).

        Raises SampleError naming ``w`` or ``y`` for a wrong shape or a non-finite value;
        the state is unchanged then.
        """
        w = sample_vector("w", w, self.p)
        y = sample_vector("y", y, self.k)
        with np.errstate(over="ignore", invalid="ignore"):  # an overflow is refused below, state unchanged
            self._update(w, y)

    def _update(self, w: np.ndarray, y: np.ndarray) -> None:
        lam, p = self.forgetting, self.p
        innovation = y - self.theta @ w
        R = lam * self.R + np.outer(w, w)
        R = 0.5 * (R + R.T)
        _within("w", "the accumulated information R", R)  # never hand LAPACK a NaN
        alpha = self._penalty_for(R)
        M = R + alpha * np.eye(p)
        # eigenvalues of M lie in [alpha, alpha + trace R] with alpha >= 1e-10 trace R: well conditioned
        try:
            G = np.linalg.inv(M)
        except np.linalg.LinAlgError as exc:  # not expected with the floor; a refusal, never LAPACK's error
            raise SampleError(f"w: the information matrix could not be inverted ({exc})") from exc
        G = 0.5 * (G + G.T)
        q = lam * self.q + np.outer(y, w)
        theta = (q + alpha * self.theta) @ G
        # the error recursion's covariance in blocks (eps-eps A, eps-err C, err-err D), noise and
        # prior parts stacked: eps' = lam eps + w nu, err' = G (lam eps + alpha err) + G w nu
        S = np.stack([self.S_noise, self.S_prior])
        A, C, D = S[:, :p, :p], S[:, :p, p:], S[:, p:, p:]
        H = lam * A + alpha * C  # Cov(eps, lam eps + alpha err) / lam
        cov_h = lam * lam * A + lam * alpha * (C + C.transpose(0, 2, 1)) + alpha * alpha * D
        out = np.empty_like(S)
        out[:, :p, :p] = lam * lam * A
        out[:, :p, p:] = lam * H @ G
        out[:, p:, p:] = G @ cov_h @ G
        Gw = G @ w
        out[0, :p, :p] += np.outer(w, w)
        out[0, :p, p:] += np.outer(w, Gw)
        out[0, p:, p:] += np.outer(Gw, Gw)
        out[:, p:, :p] = out[:, :p, p:].transpose(0, 2, 1)
        out[:, p:, p:] = 0.5 * (out[:, p:, p:] + out[:, p:, p:].transpose(0, 2, 1))
        residual_var = (self.residual_var if self.noise_known
                        else lam * self.residual_var + (1.0 - lam) * innovation ** 2)
        _within("y", "the accumulated q", q)
        _within("y", "the estimate theta", theta)
        _within("w", "the error covariance", out)
        _within("y", "the residual variance", residual_var)
        if self.samples >= _MAX_SAMPLES:
            raise SampleError(f"w: {self.samples} samples, the most one estimator counts; reset it")
        self.R, self.q, self.theta = R, q, theta
        self.S_noise, self.S_prior = out[0], out[1]
        self.samples += 1
        if not self.noise_known:
            self.residual_var = residual_var
            self.noise_std = np.sqrt(np.maximum(self.residual_var, 1e-300))

    def _penalty_for(self, R: np.ndarray) -> float:
        """The penalty solved with for information ``R``: ``max(alpha, PENALTY_FLOOR trace R)``."""
        return max(self.penalty, PENALTY_FLOOR * float(np.trace(R)))

    @property
    def covariance(self) -> np.ndarray:
        """(k, p, p): the covariance of each output row's estimate (see the module docstring)."""
        p = self.p
        Sn, Sp = self.S_noise[p:, p:], self.S_prior[p:, p:]
        return self.noise_std[:, None, None] ** 2 * Sn + self.prior_std[:, None, None] ** 2 * Sp

    @property
    def std(self) -> np.ndarray:
        """(k, p): standard deviation of each parameter estimate."""
        p = self.p
        dn, dp = np.diag(self.S_noise)[p:], np.diag(self.S_prior)[p:]
        var = self.noise_std[:, None] ** 2 * dn + self.prior_std[:, None] ** 2 * dp
        return np.sqrt(np.maximum(var, 0.0))

    def information(self) -> np.ndarray:
        """Eigenvalues of the accumulated information ``R_n`` (ascending): a direction whose
        eigenvalue is small against ``penalty`` is unexcited and its estimate is held."""
        return np.linalg.eigvalsh(self.R)

    def condition(self) -> float:
        """Condition number of ``R_n + alpha_n I`` (bounded, see the module docstring)."""
        ev = self.information()
        alpha = self._penalty_for(self.R)
        return float((ev[-1] + alpha) / (max(ev[0], 0.0) + alpha))

    # -------------------------------------------------------------- durable state
    def to_dict(self) -> dict[str, Any]:
        """The whole state as JSON-ready lists (bounded: ``O(p^2 + k p)`` numbers)."""
        return {
            "kind": "rls", "n_outputs": self.k, "n_regressors": self.p, "forgetting": self.forgetting,
            "penalty": self.penalty, "theta": self.theta.tolist(), "R": self.R.tolist(), "q": self.q.tolist(),
            "S_noise": self.S_noise.tolist(), "S_prior": self.S_prior.tolist(),
            "noise_std": self.noise_std.tolist(), "prior_std": self.prior_std.tolist(),
            "noise_known": self.noise_known, "samples": self.samples, "residual_var": self.residual_var.tolist(),
        }

    @classmethod
    def from_dict(cls, data: Any) -> RecursiveLeastSquares:
        """Inverse of :meth:`to_dict`; StateError naming the field for anything that does not fit."""
        d = state_mapping(data, "rls", _STATE_KEYS)
        k, p = d["n_outputs"], d["n_regressors"]
        if isinstance(k, bool) or isinstance(p, bool) or not isinstance(k, int) or not isinstance(p, int):
            raise StateError("n_outputs: the stored sizes must be integers")
        if not 1 <= k <= 4096 or not 1 <= p <= 4096:
            raise StateError(f"n_outputs: stored sizes {short_repr(k)} x {short_repr(p)} outside [1, 4096]")
        if not isinstance(d["noise_known"], bool):
            raise StateError("noise_known: expected true or false")
        try:
            est = cls(k, p, forgetting=d["forgetting"], penalty=d["penalty"], prior_std=d["prior_std"],
                      noise_std=d["noise_std"] if d["noise_known"] else None)
        except OptionError as exc:
            raise StateError(str(exc)) from None
        est.theta = state_array("theta", d["theta"], (k, p))
        est.R = state_array("R", d["R"], (p, p))
        est.q = state_array("q", d["q"], (k, p))
        est.S_noise = state_array("S_noise", d["S_noise"], (2 * p, 2 * p))
        est.S_prior = state_array("S_prior", d["S_prior"], (2 * p, 2 * p))
        est.noise_std = state_array("noise_std", d["noise_std"], (k,))
        est.residual_var = state_array("residual_var", d["residual_var"], (k,))
        if not (est.noise_std > 0).all() or not (est.residual_var >= 0).all():
            raise StateError("noise_std: the stored noise levels must be > 0 and residual_var >= 0")
        est.samples = state_count("samples", d["samples"], _MAX_SAMPLES)
        return est


#: Samples one estimator counts (exact in a float); the counter is informational.
_MAX_SAMPLES = 2 ** 53


def _std_setting(name: str, value: Any, k: int) -> np.ndarray:
    """A standard deviation per output, in ``(0, 1e24]``: its square, a variance the state
    keeps, stays within the valid domain."""
    std = setting_vector(name, value, k, positive=True)
    if not std.max() <= _MAX_STD:
        raise OptionError(f"{name}: {std.max():g} above {_MAX_STD:g} (its square, a variance, must stay within "
                          f"{MAX_MAGNITUDE:g})")
    return std


#: the largest standard deviation: its square within the valid domain
_MAX_STD = 1e24


def _within(field: str, what: str, arr: np.ndarray) -> None:
    """SampleError naming ``field`` unless ``arr`` stays finite and within the valid domain."""
    if not np.abs(arr).max(initial=0.0) <= MAX_MAGNITUDE:
        raise SampleError(f"{field}: this sample would take {what} beyond the valid domain "
                          f"(finite, |x| <= {MAX_MAGNITUDE:g}); refused, the state is unchanged")


class EffectivenessRLS:
    """The effectiveness matrix ``B`` (k x m) estimated from applied commands and responses.

    Model: ``y = B u + A x + c + noise`` where ``y`` is the measured virtual-control response
    (moments, or state derivatives), ``u`` the applied effector positions, ``x`` optional
    extra regressors (states, for a regression on state derivatives, seed Eq 1.1) and ``c``
    an optional constant (trim and bias).  Every row is estimated by Eq 1.4
    (:class:`RecursiveLeastSquares`); the regressor ``w = [u, x, 1]``.

    Parameters
    ----------
    B0 : array (k, m)
        Prior (nominal) effectiveness.
    n_states : int
        Length of ``x`` (0: none).
    bias : bool
        Estimate the constant ``c``.
    forgetting, penalty, prior_std, noise_std
        As for :class:`RecursiveLeastSquares`; ``prior_std`` is per output row.
    """

    def __init__(self, B0: Any, *, n_states: int = 0, bias: bool = False, forgetting: float = 0.995,
                 penalty: float = 1.0, prior_std: Any = 1.0, noise_std: Any = None) -> None:
        B0 = as_float_array("B0", B0, OptionError)
        if B0.ndim != 2 or 0 in B0.shape:
            raise OptionError(f"B0: expected a finite 2-D (k, m) array, got shape {B0.shape}")
        check_magnitude("B0", B0, OptionError)
        if isinstance(n_states, (bool, np.bool_)) or not isinstance(n_states, (int, np.integer)) \
                or not 0 <= n_states <= 1024:
            raise OptionError(f"n_states: expected an integer in [0, 1024], got {short_repr(n_states)}")
        if not isinstance(bias, bool):
            raise OptionError(f"bias: expected true or false, got {type(bias).__name__}")
        self.k, self.m = B0.shape
        self.n_states, self.bias = int(n_states), bias
        p = self.m + self.n_states + int(bias)
        theta0 = np.zeros((self.k, p))
        theta0[:, :self.m] = B0
        self.rls = RecursiveLeastSquares(self.k, p, forgetting=forgetting, penalty=penalty, theta0=theta0,
                                         prior_std=prior_std, noise_std=noise_std)

    def regressor(self, u: Any, x: Any = None) -> np.ndarray:
        """``w = [u, x, 1]`` from a sample (SampleError naming ``u`` or ``x``)."""
        u = sample_vector("u", u, self.m)
        parts = [u]
        if self.n_states:
            if x is None:
                raise SampleError(f"x: {self.n_states} states expected, got none")
            parts.append(sample_vector("x", x, self.n_states))
        elif x is not None:
            raise SampleError("x: this estimator takes no states (n_states = 0)")
        if self.bias:
            parts.append(np.ones(1))
        return np.concatenate(parts)

    def update(self, u: Any, y: Any, x: Any = None) -> None:
        """One sample: applied positions ``u`` (m,), response ``y`` (k,), states ``x`` if any."""
        self.rls.update(self.regressor(u, x), y)

    def reset(self, prior_std: Any = None) -> None:
        """See :meth:`RecursiveLeastSquares.reset`."""
        self.rls.reset(prior_std)

    @property
    def B(self) -> np.ndarray:
        """Current estimate of ``B`` (k, m)."""
        return self.rls.theta[:, :self.m].copy()

    @property
    def B_std(self) -> np.ndarray:
        """Standard deviation of each entry of :attr:`B` (k, m)."""
        return self.rls.std[:, :self.m]

    def column(self, j: int) -> tuple[np.ndarray, np.ndarray]:
        """Effector ``j``'s column of ``B`` and its standard deviations."""
        return self.B[:, j], self.B_std[:, j]

    def to_dict(self) -> dict[str, Any]:
        return {"kind": "effectiveness_rls", "m": self.m, "n_states": self.n_states, "bias": self.bias,
                "rls": self.rls.to_dict()}

    @classmethod
    def from_dict(cls, data: Any) -> EffectivenessRLS:
        d = state_mapping(data, "effectiveness_rls", ("m", "n_states", "bias", "rls"))
        rls = RecursiveLeastSquares.from_dict(d["rls"])
        m, n_states, bias = d["m"], d["n_states"], d["bias"]
        if not (type(m) is int and type(n_states) is int and isinstance(bias, bool)) \
                or m + n_states + int(bias) != rls.p or m < 1 or not 0 <= n_states <= 1024:
            raise StateError("m: the stored sizes do not match the regressor length")
        est = cls.__new__(cls)
        est.k, est.m, est.n_states, est.bias, est.rls = rls.k, m, n_states, bias, rls
        return est
