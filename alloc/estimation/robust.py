"""What the nominal residual actually is on this vehicle: a learnt model for the detector.

The stage-1 test of :mod:`.detection` is exact when the plant is the model and the noise is
the stated white or correlated Gaussian.  No aircraft is: its effectiveness differs from the
model by some tens of percent, its actuators are faster or slower than their data sheet,
gusts move it, and its sensors have heavier tails than a Gaussian (the seed, section 1.3.1:
"any differences between the actual system and the nominal system model can result in a
false detection of a failure").  :class:`NominalLearner` gives the detector the residual's
real law, learnt in flight, starting from a stated bound:

Model error (a Bayesian estimate with a stated prior, stabilised forgetting)
    Per response axis ``i`` the measured response is ``y_i = (b_i + delta_i) . p + g_i . p' +
    e_i`` with ``p`` the known positions, ``p'`` their rate (a lag error of the actuators:
    ``u_true ~ u - tau_error u'``) and ``delta_i``, ``g_i`` unknown.  Their prior is the stated
    uncertainty, used as one standard deviation (a bound taken as 1 sigma, so conservative):
    ``delta_ij ~ N(0, (F b_ij)^2)``, ``g_ij ~ N(0, (F lag_j b_ij)^2)``.  The posterior is kept
    in information form and forgotten toward the prior with memory ``model_memory``
    (``J <- lam J + (1 - lam) J0 + phi phi^T / s^2``; Kulhavy and Zarrop, "On a general
    concept of forgetting", Int. J. Control 58, 1993): unexcited directions return to the
    stated uncertainty instead of winding up, and slow drift is absorbed into the nominal
    model -- it is the aircraft, not a failure.  This is the seed's RLS estimator (Eq 1.4,
    :mod:`.rls`) run on the residual of the nominal model, with a prior.
    The residual of a sample is its innovation against the model learnt before it, whitened by
    the predictive standard deviation ``sqrt(s_i^2 + phi^T J_i^-1 phi)``: while the model is
    not yet learnt, a residual the stated model error could explain is not evidence.
Scale (robust, learnt)
    ``s_i`` is ``max(1, learnt)`` times the stated noise: an exponentially weighted mean of
    ``|r|`` clipped at ``4 s`` (memory ``scale_memory``, with :data:`PRIOR_SAMPLES` at the
    stated level so it is learnt within a second or two, not a memory), times ``sqrt(pi / 2)`` (a Gaussian's
    mean absolute value).  Never below the stated level: heavier tails are handled below, not
    by believing the sensors worse than stated.
Heavy tails (Huber)
    The stage-1 statistic sees each residual component clipped at ``huber`` scale units
    (Huber's M-estimation: Huber, "Robust estimation of a location parameter", Ann. Math.
    Stat. 35, 1964): one sample can move it by at most ``huber^2`` per axis, so a Student-t
    outlier is one bounded sample and a failure -- which persists -- still accumulates.  The
    isolation's fits see the unclipped residuals (a hard-over's position is in their size).
Correlation (learnt)
    The autocorrelation of the clipped standardised residuals at lags ``1..lags``, averaged
    over axes, exponentially weighted with ``scale_memory``, blended with the stated one while
    data are few, and shrunk toward white until its Toeplitz matrix is positive definite:
    turbulence makes the residual a slow coloured process, whose trend across a window the
    uncorrelated test would read as a failure.

The learner stops learning while an alarm is pending (a failure being isolated must not be
absorbed) and keeps learning after a detection (the detection changes the known positions,
not the aircraft's model error).  Every number is bounded; the cost is priced before the
arrays exist (:func:`learner_cost`).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from ..exceptions import OptionError
from ..problem import MAX_MAGNITUDE, as_float_array
from ._checks import StateError, setting_real, state_array, state_count

__all__ = ["RobustSettings", "NominalLearner", "learner_cost", "MAX_LEARNER_FLOPS"]

#: The learnt model's work per sample, ``k p^3`` flops (``p`` parameters per axis): 2^27, about
#: 0.1 s of one core in the worst case; the seed's ICE (k 6, p 32) is 2e5.
MAX_LEARNER_FLOPS = 2 ** 27
#: The stated noise law's weight in the learnt scale and correlation, in samples (5: half a
#: second at the in-loop detector's 10 Hz; the learnt law dominates after a second or two,
#: the stated one keeps the first few samples' estimates from being a sample or two's noise)
PRIOR_SAMPLES = 5.0
#: a Gaussian's ``E|x| = sqrt(2 / pi) sigma``
_MAD_TO_STD = math.sqrt(math.pi / 2.0)


@dataclass(frozen=True)
class RobustSettings:
    """The learnt nominal model's free parameters (each disclosed wherever a verdict uses it).

    Attributes
    ----------
    model_uncertainty : float
        ``F``: the stated relative uncertainty of each effectiveness entry and actuator lag
        (0.2: a model within 20 %, the uncertainty class the published verdicts are measured in).
    model_memory : float
        Seconds of the learnt model's memory (60 s: a loss of effectiveness must be reported
        within 2 s, in which a 60 s memory absorbs about 3 % of it).
    scale_memory : float
        Seconds of the learnt scale's and correlation's memory (30 s: turbulence's slowest
        component, MIL-F-8785C's ``L_u / V``, is 5-10 s at the seed's flight conditions).
    huber : float
        Clip of each standardised residual component in the stage-1 statistic (2.5: Huber's
        efficiency under Gaussian noise is 0.99 there).
    lags : int
        Lags of the learnt autocorrelation (samples).
    """

    model_uncertainty: float = 0.2
    model_memory: float = 60.0
    scale_memory: float = 30.0
    huber: float = 2.5
    lags: int = 16

    def record(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_value(cls, value: Any) -> RobustSettings:
        """``True`` (the defaults), a mapping of fields, or a RobustSettings; OptionError naming ``robust``."""
        if isinstance(value, RobustSettings):
            out = value
        elif value is True:
            out = cls()
        elif isinstance(value, dict):
            unknown = set(value) - set(cls.__dataclass_fields__)
            if unknown:
                raise OptionError(f"robust: unknown settings {sorted(unknown)}; known: {sorted(cls.__dataclass_fields__)}")
            out = cls(**value)
        else:
            raise OptionError(f"robust: expected true, a mapping of settings or None, got {type(value).__name__}")
        setting_real("robust/model_uncertainty", out.model_uncertainty, 0.0, 10.0)
        setting_real("robust/model_memory", out.model_memory, 0.0, 1e6, lo_open=True)
        setting_real("robust/scale_memory", out.scale_memory, 0.0, 1e6, lo_open=True)
        setting_real("robust/huber", out.huber, 0.5, 100.0)
        if isinstance(out.lags, bool) or not isinstance(out.lags, (int, np.integer)) or not 1 <= out.lags <= 256:
            raise OptionError(f"robust/lags: expected an integer in [1, 256], got {out.lags!r}")
        return out


def learner_cost(k: int, m: int, lagged: bool) -> tuple[int, int]:
    """``(flops per sample, bytes)`` of a learner with ``k`` axes and ``m`` effectors."""
    p = 2 * m if lagged else m
    return k * p ** 3, 8 * (3 * k * p * p + 64 * k)


class NominalLearner:
    """The learnt residual model of one detector (see the module docstring).

    ``B`` (k, m) the nominal effectiveness as the detector whitens it (rows divided by the
    stated noise), ``span`` (m,) each effector's travel, ``lag`` (m,) the actuators' lags in
    seconds or None (no rate regressors), ``rho`` the stated autocorrelation (lags 1..) or None
    (white), ``dt`` the sample time.

    Units: the parameters are kept relative -- regressors divided by the travel, each axis's
    parameters by its largest ``|b_ij| span_j`` -- so the prior's standard deviations lie in
    ``[1e-12, F]`` and the arithmetic stays in range over the detector's whole domain
    (``|B / noise| <= 1e50``, travels up to 1e50).
    """

    def __init__(self, settings: RobustSettings, B: np.ndarray, span: np.ndarray, lag: np.ndarray | None,
                 rho: np.ndarray | None, dt: float) -> None:
        self.settings = settings
        k, m = B.shape
        self.k, self.m, self.dt = k, m, dt
        self.lagged = lag is not None
        p = 2 * m if self.lagged else m
        flops, _ = learner_cost(k, m, self.lagged)
        if flops > MAX_LEARNER_FLOPS:
            raise OptionError(f"robust: a learnt model of {k} axes x {p} parameters costs {flops:.3g} flops a sample; "
                              f"at most {MAX_LEARNER_FLOPS:.3g} (fewer effectors, or no effector_lag)")
        self.p = p
        F = settings.model_uncertainty
        span = np.where(np.asarray(span, dtype=float) > 0, span, 1.0)
        self.span = np.concatenate([span, span]) if self.lagged else span  # (p,)
        with np.errstate(over="ignore", under="ignore"):
            moved = np.abs(B) * span[None, :]
            row = moved.max(axis=1, initial=0.0)
        self.row = np.where((row > 0) & np.isfinite(row), row, 1.0)  # (k,)
        rel = np.minimum(moved / self.row[:, None], 1.0)
        scale = rel * F
        if self.lagged:
            scale = np.hstack([scale, rel * F * np.minimum(lag, 3600.0)[None, :]])
        # entries the model says are zero stay (nearly) zero: a scaled column has no new entries
        self.prior_var = np.maximum(scale, 1e-12) ** 2  # (k, p)
        self.J = np.zeros((k, p, p))
        self.J[:, np.arange(p), np.arange(p)] = 1.0 / self.prior_var
        self.h = np.zeros((k, p))
        self.theta = np.zeros((k, p))
        self.cov = np.zeros((k, p, p))
        self.cov[:, np.arange(p), np.arange(p)] = self.prior_var
        self.lam_model = math.exp(-dt / settings.model_memory)
        self.lam_scale = math.exp(-dt / settings.scale_memory)
        self.stated_rho = np.zeros(settings.lags) if rho is None else _pad(rho, settings.lags)
        # discounted sums (weight a^age) of |r| per axis, of clipped r^2 and of lagged products
        # (over axes), and of the weights; the estimates add PRIOR_SAMPLES at the stated law
        self.sum_abs = np.zeros(k)
        self.sum_c0 = 0.0
        self.sum_cl = np.zeros(settings.lags)
        self.weight = 0.0
        self.history = np.zeros((settings.lags, k))  # last clipped residuals, newest first
        self.u_prev: np.ndarray | None = None
        self.samples = 0

    # ------------------------------------------------------------------ per sample
    def regressor(self, known: np.ndarray) -> np.ndarray:
        """The sample's regressors in travel units (positions, and rates when lagged)."""
        if not self.lagged:
            return known / self.span
        rate = np.zeros(self.m) if self.u_prev is None else (known - self.u_prev) / self.dt
        return np.concatenate([known, rate]) / self.span

    def scale(self) -> np.ndarray:
        """The noise scale, in units of the stated level (at least 1)."""
        n0 = PRIOR_SAMPLES
        abs_mean = (n0 / _MAD_TO_STD + self.sum_abs) / (n0 + self.weight)
        return np.maximum(1.0, abs_mean * _MAD_TO_STD)

    def residual(self, r0: np.ndarray, phi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(r, s)``: the innovation of the stated-whitened nominal residual ``r0`` in units of the
        predictive standard deviation, and that standard deviation (in stated units)."""
        pred = self.row * (self.theta @ phi)
        var = self.scale() ** 2 + self.row ** 2 * np.einsum("p,kpq,q->k", phi, self.cov, phi)
        # beyond the domain (a parameter variance times a regressor of 1e50) the spread is the
        # domain's edge, so |r| s stays a number (inf * 0 was a NaN in the learnt scale)
        cap = MAX_MAGNITUDE * MAX_MAGNITUDE
        s = np.sqrt(np.where(np.isfinite(var), np.minimum(var, cap), cap))
        return (r0 - pred) / s, s

    def learn(self, r0: np.ndarray, phi: np.ndarray, r: np.ndarray, s: np.ndarray, known: np.ndarray, *,
              model: bool) -> None:
        """Take one sample (``r``, ``s`` from :meth:`residual`): the scale and correlation always,
        the model unless ``model`` is False (an alarm pending)."""
        h = self.settings.huber
        a = self.lam_scale
        clipped_abs = np.minimum(np.abs(r) * s, 4.0 * self.scale())
        rc = np.clip(r, -h, h)
        self.sum_abs = np.minimum(a * self.sum_abs + clipped_abs, 1e-3 * MAX_MAGNITUDE)  # stays storable
        self.sum_c0 = a * self.sum_c0 + float(rc @ rc) / self.k
        self.sum_cl = a * self.sum_cl + (self.history @ rc) / self.k
        self.weight = a * self.weight + 1.0
        self.history = np.roll(self.history, 1, axis=0)
        self.history[0] = rc
        if model:
            lam = self.lam_model
            w = self.row / self.scale() ** 2  # r0_i = row_i theta_i . phi + noise of variance s_i^2
            J = self.J * lam
            J[:, np.arange(self.p), np.arange(self.p)] += (1.0 - lam) / self.prior_var
            J += np.outer(phi, phi)[None, :, :] * (w * self.row)[:, None, None]
            # Huber's M-estimate: a sample teaches at most ``huber`` predictive standard deviations
            # (a failure's first samples, before its alarm, would otherwise move the model by
            # their whole size -- a hard-over is hundreds of them)
            r0_taught = r0 - (r - rc) * s
            hv = lam * self.h + phi[None, :] * (w * r0_taught)[:, None]
            # a sample that would take the stored state beyond the domain teaches nothing (whitened
            # columns near 1e40 make one sample's information 1e80): the model stays where it was
            if np.abs(J).max(initial=0.0) <= MAX_MAGNITUDE and np.abs(hv).max(initial=0.0) <= MAX_MAGNITUDE:
                self.J, self.h = J, hv
                self._solve()
        self.u_prev = known.copy()
        self.samples += 1

    def _solve(self) -> None:
        from scipy.linalg import LinAlgError, cho_factor, cho_solve

        eye = np.eye(self.p)
        for i in range(self.k):
            try:
                c = cho_factor(self.J[i], lower=True)
            except LinAlgError:  # round-off only: J >= J0 (1 - lam) > 0; keep the last estimate
                continue
            self.theta[i] = cho_solve(c, self.h[i])
            self.cov[i] = cho_solve(c, eye)

    # ------------------------------------------------------------------ the test's view
    def effectiveness(self, B: np.ndarray) -> np.ndarray:
        """The learnt effectiveness ``B + delta`` (stated-whitened rows) of the known positions."""
        return B + self.row[:, None] * self.theta[:, : self.m] / self.span[None, : self.m]

    def correlation(self, n: int) -> np.ndarray | None:
        """The autocorrelation (lags ``1..n-1``) to whiten an ``n``-sample window with."""
        n0 = PRIOR_SAMPLES
        rho = (n0 * self.stated_rho + self.sum_cl) / max(n0 + self.sum_c0, 1e-300)
        rho = _pad(rho, n - 1)
        from scipy.linalg import LinAlgError, cholesky, toeplitz

        for _ in range(40):  # shrink toward white until it is a correlation over n samples
            if not np.abs(rho).max(initial=0.0) > 1e-12:
                return None
            try:
                cholesky(toeplitz(np.concatenate([[1.0], rho])), lower=True)
                return rho
            except LinAlgError:
                rho = 0.8 * rho
        return None

    # ------------------------------------------------------------------ durable state
    def to_dict(self) -> dict[str, Any]:
        return {"settings": self.settings.record(), "J": self.J.tolist(), "h": self.h.tolist(),
                "sum_abs": self.sum_abs.tolist(), "sum_c0": self.sum_c0, "sum_cl": self.sum_cl.tolist(),
                "weight": self.weight,
                "history": self.history.tolist(), "u_prev": None if self.u_prev is None else self.u_prev.tolist(),
                "samples": self.samples}

    def load(self, d: Any) -> None:
        """Restore :meth:`to_dict`'s state into this learner (same settings and shapes); StateError."""
        if not isinstance(d, dict):
            raise StateError("robust: expected a mapping")
        k, p, L = self.k, self.p, self.settings.lags
        self.J = state_array("robust/J", d.get("J"), (k, p, p))
        if not np.allclose(self.J, np.swapaxes(self.J, 1, 2), rtol=0.0, atol=0.0):
            raise StateError("robust/J: not symmetric")
        self.h = state_array("robust/h", d.get("h"), (k, p))
        self.sum_abs = state_array("robust/sum_abs", d.get("sum_abs"), (k,))
        self.sum_cl = state_array("robust/sum_cl", d.get("sum_cl"), (L,))
        self.history = state_array("robust/history", d.get("history"), (L, k))
        self.sum_c0 = float(state_array("robust/sum_c0", d.get("sum_c0"), ()))
        self.weight = float(state_array("robust/weight", d.get("weight"), ()))
        most = 1.0 / (1.0 - self.lam_scale)  # the discounted count's limit
        if not (self.sum_c0 >= 0 and 0 <= self.weight <= most * (1 + 1e-9) and (self.sum_abs >= 0).all()):
            raise StateError(f"robust: sum_c0 and sum_abs must be non-negative, weight in [0, {most:g}]")
        self.u_prev = None if d.get("u_prev") is None else state_array("robust/u_prev", d["u_prev"], (self.m,))
        self.samples = state_count("robust/samples", d.get("samples", 0))
        self._solve()


def _pad(rho: Any, n: int) -> np.ndarray:
    arr = np.asarray(as_float_array("noise_correlation", rho, OptionError), dtype=float).ravel()
    out = np.zeros(n)
    use = min(n, arr.size)
    out[:use] = arr[:use]
    return out
