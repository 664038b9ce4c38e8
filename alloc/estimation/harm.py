"""Do no harm: judge an applied detection by what follows it.

A detection changes the allocation problem; if it is false it can make the loop worse, and a
false belief of a stuck surface can even confirm itself (the allocator pins a healthy surface at
the believed position).  Two numbers judge it once it has been applied for a probation period:

Tracking (:func:`tracking_test`)
    The loop's tracking error ``e = r - z`` (reference less the *measured* controlled outputs,
    what a flight computer has) sampled every ``Ts``, in a window before the detection's onset
    (the loop as it flew without the detection: what the hypothesis "nothing failed" predicts
    it keeps doing) and over the probation after it was applied.  Per channel, the mean-square
    ratio ``F_i = mean(e_after_i^2) / mean(e_before_i^2)`` is tested against the F distribution
    with the windows' effective sample sizes as degrees of freedom (mean squares about zero:
    a bias is harm too, so no mean is removed and no degree lost).  Tracking errors are
    autocorrelated, so each window's ``n`` samples count as ``n_eff = n / (1 + 2 sum_l rho_l)``
    (Bartlett's formula for the variance of a mean square of a correlated Gaussian series,
    lags ``1..max_lag`` of the before window's autocorrelation, each channel its own, clipped to
    ``[1, n]``).  The loop tracks worse when some channel's ``F_i`` exceeds
    ``F.isf(level / k, n_eff_after, n_eff_before)`` (Bonferroni over the ``k`` channels).
    The unattained demand ``|v - B u|`` the allocator reports is not used: it is computed with
    the allocator's own belief, so a false belief reports its own moment as attained.

Evidence (:func:`evidence_log_ratio`)
    Over the same probation, the log likelihood ratio of the response residuals under the
    belief with the detection against the belief without it (the effector's entry as before),
    the residuals whitened by the noise's autocorrelation: ``ln L_belief - ln L_before =
    (|W r_before|^2 - |W r_belief|^2) / 2``.  It is *decisive* when it reaches ``ln 100``
    (Jeffreys' scale: a Bayes factor above 100 is "decisive"; H. Jeffreys, *Theory of
    Probability*, 3rd ed. 1961, appendix B) **and** the belief fits the data: its whitened
    residuals' sum of squares within ``chi2.isf(level, n k)`` (``n`` samples, ``k`` axes).
    A ratio between two models that both fail to fit (a plant-level failure outside every
    effector hypothesis) says which is less wrong, not that either is right.  A detection the
    data favour decisively is kept whatever the tracking: a real jam makes tracking worse too,
    and the belief is then the best the allocator can act on.

Looks.  The rule looks at every sample of the probation from ``min_after`` samples on
(a grossly harmful belief is withdrawn early), at ``level / (k looks)``: Bonferroni over the
channels and the looks, so a harmless detection is withdrawn with probability at most
``level`` in all.

A detection is withdrawn when the tracking is significantly worse and the evidence for it is
not decisive (:func:`judge`).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from ..exceptions import OptionError

__all__ = ["HarmDesign", "DEFAULT_HARM", "TrackingTest", "Verdict", "tracking_test", "evidence_log_ratio",
           "effective_samples", "judge", "looks", "belief_fits", "whitener"]


@dataclass(frozen=True)
class HarmDesign:
    """The do-no-harm rule's free parameters, chosen before any verdict was looked at.

    Attributes
    ----------
    probation : float
        Seconds after a detection is applied over which it is judged (2 s: the loop's slowest
        controlled channel settles in about 1 s on ICE and HARV, so two of its time constants,
        and 20 detector samples; short enough that a false belief is withdrawn before it
        costs the flight).
    before : float
        Seconds of the reference window before the detection's onset (5 s: 50 samples at
        0.1 s, the longest period of the seed's Table 4-2 command sines is about 6 s).
    level : float
        Probability of calling a harmless detection harmful, all channels together
        (0.01, Bonferroni over channels).
    max_lag : int
        Lags (samples) of the autocorrelation in the effective sample size (10: 1 s at 0.1 s).
    decisive : float
        Bayes factor of the residuals above which the evidence for a detection is decisive
        (100, Jeffreys).
    min_before : int
        Fewest samples of the before window for a tracking test (10); with fewer the detection
        is kept (no reference to judge it against).
    min_after : int
        Samples after the application before the first look (5: 0.5 s, the after window's
        mean square is then an average of a few independent values at the effective sizes seen).
    quarantine : float
        Seconds after a withdrawal by the monitor during which new detections are withdrawn at
        once, never applied (2 s, the probation: the time the loop needs to show its tracking
        again without them).
    fit_gate : bool
        Whether a detection is applied only when the belief with it fits the residuals since its
        onset (whitened sum of squares within ``chi2.isf(level, n k)``, as for the evidence):
        a belief that leaves the response unexplained is not acted on (True).
    active : bool
        False: none of it (no hold, gate, probation or quarantine): each detection is applied as
        it comes, the loop of before the rule (for tests of the delivery path itself).
    """

    probation: float = 2.0
    before: float = 5.0
    level: float = 0.01
    max_lag: int = 10
    decisive: float = 100.0
    min_before: int = 10
    min_after: int = 5
    quarantine: float = 2.0
    fit_gate: bool = True
    active: bool = True

    def __post_init__(self) -> None:
        for name in ("probation", "before"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise OptionError(f"{name}: expected a positive number of seconds, got {value!r}")
        if not 0.0 < self.level < 1.0:
            raise OptionError(f"level: expected a probability in (0, 1), got {self.level!r}")
        if not self.decisive > 1.0:
            raise OptionError(f"decisive: expected a Bayes factor above 1, got {self.decisive!r}")
        if not (isinstance(self.max_lag, int) and self.max_lag >= 0):
            raise OptionError(f"max_lag: expected a non-negative integer, got {self.max_lag!r}")
        if not (isinstance(self.min_before, int) and self.min_before >= 2):
            raise OptionError(f"min_before: expected an integer >= 2, got {self.min_before!r}")

    def record(self) -> dict[str, Any]:
        return asdict(self)


DEFAULT_HARM = HarmDesign()


def effective_samples(e: np.ndarray, max_lag: int, rho_from: np.ndarray | None = None) -> np.ndarray:
    """Per column of ``e`` (n, k): ``n / (1 + 2 sum_{l=1..L} rho_l)`` clipped to ``[1, n]``.

    ``rho`` is the autocorrelation (about zero, biased estimator) of ``rho_from`` (default ``e``)
    at lags ``1..L``, ``L = min(max_lag, len(rho_from) - 1)``.
    """
    src = e if rho_from is None else rho_from
    n, k = e.shape
    c0 = np.einsum("ij,ij->j", src, src)
    lags = min(max_lag, src.shape[0] - 1)
    total = np.zeros(k)
    for lag in range(1, lags + 1):
        total += np.einsum("ij,ij->j", src[lag:], src[:-lag]) / np.where(c0 > 0, c0, 1.0)
    factor = np.maximum(1.0 + 2.0 * total, 1.0 / n)
    return np.clip(n / factor, 1.0, n)


@dataclass(frozen=True)
class TrackingTest:
    """The tracking comparison of one detection (:func:`tracking_test`)."""

    ratio: tuple[float, ...]  # F_i per channel
    dof_after: tuple[float, ...]
    dof_before: tuple[float, ...]
    threshold: tuple[float, ...]
    p_value: tuple[float, ...]
    worse: bool

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def tracking_test(before: np.ndarray, after: np.ndarray, design: HarmDesign = DEFAULT_HARM,
                  looks: int = 1) -> TrackingTest:
    """Whether the tracking ``after`` (n2, k) is significantly worse than ``before`` (n1, k)
    (the module docstring: mean-square ratios, effective dof, F test, Bonferroni)."""
    from scipy.stats import f as f_dist

    before = np.asarray(before, dtype=float)
    after = np.asarray(after, dtype=float)
    if before.ndim != 2 or after.ndim != 2 or before.shape[1] != after.shape[1] or min(len(before), len(after)) < 2:
        raise OptionError(f"before/after: expected (n, k) windows of >= 2 samples and the same k, got "
                          f"{before.shape} and {after.shape}")
    k = before.shape[1]
    n1 = effective_samples(before, design.max_lag)
    n2 = effective_samples(after, design.max_lag, rho_from=before)  # under H0 the same process
    ms1 = np.mean(before ** 2, axis=0)
    ms2 = np.mean(after ** 2, axis=0)
    ratio = np.where(ms1 > 0, ms2 / np.where(ms1 > 0, ms1, 1.0), np.where(ms2 > 0, np.inf, 1.0))
    threshold = f_dist.isf(design.level / k / looks, n2, n1)
    p = f_dist.sf(np.minimum(ratio, 1e300), n2, n1)
    return TrackingTest(tuple(map(float, ratio)), tuple(map(float, n2)), tuple(map(float, n1)),
                        tuple(map(float, threshold)), tuple(map(float, p)), bool((ratio > threshold).any()))


def evidence_log_ratio(r_belief: np.ndarray, r_before: np.ndarray, whiten: np.ndarray | None = None) -> float:
    """``ln L_belief - ln L_before`` of residuals (n, k), each already divided by its noise std.

    ``whiten`` (n, n): ``W`` with ``W Sigma W^T = I`` for the window's noise correlation
    (None: white); applied along time, the same for every axis.
    """
    a = np.asarray(r_belief, dtype=float)
    b = np.asarray(r_before, dtype=float)
    if whiten is not None:
        a, b = whiten @ a, whiten @ b
    return float(0.5 * (np.sum(b * b) - np.sum(a * a)))


def whitener(rho: Any, n: int) -> np.ndarray | None:
    """``W`` (n, n) for the Toeplitz correlation of lags ``rho`` (1, 2, ...); None when ``rho`` is None."""
    if rho is None:
        return None
    from scipy.linalg import cholesky, solve_triangular, toeplitz

    lags = np.zeros(n)
    lags[0] = 1.0
    r = np.asarray(rho, dtype=float)
    use = min(n - 1, r.size)
    lags[1:1 + use] = r[:use]
    return solve_triangular(cholesky(toeplitz(lags), lower=True), np.eye(n), lower=True)


@dataclass(frozen=True)
class Verdict:
    """What the rule decides of one applied detection."""

    withdraw: bool
    reason: str
    tracking: TrackingTest | None
    log_evidence: float | None
    decisive: bool

    def statistics(self) -> dict[str, Any]:
        return {"tracking": None if self.tracking is None else self.tracking.to_dict(),
                "log_evidence": self.log_evidence, "decisive": self.decisive}


def looks(design: HarmDesign, sample_time: float) -> int:
    """How many times a probation is looked at (every sample from ``min_after`` to its end)."""
    return max(1, int(round(design.probation / sample_time)) - design.min_after + 1)


def belief_fits(sum_of_squares: float, n_values: int, design: HarmDesign = DEFAULT_HARM) -> bool:
    """Whether whitened residuals with this sum of squares over ``n_values`` numbers are noise."""
    from scipy.stats import chi2

    return bool(sum_of_squares <= chi2.isf(design.level, max(1, n_values)))


def judge(before: np.ndarray, after: np.ndarray, log_evidence: float | None,
          design: HarmDesign = DEFAULT_HARM, *, fits: bool = True, n_looks: int = 1) -> Verdict:
    """Withdraw when the tracking is significantly worse and the evidence is not decisive
    (``fits``: whether the belief's residuals are noise, :func:`belief_fits`)."""
    decisive = log_evidence is not None and log_evidence >= math.log(design.decisive) and fits
    if len(before) < design.min_before:
        return Verdict(False, f"kept: {len(before)} samples before the onset, fewer than {design.min_before}",
                       None, log_evidence, decisive)
    test = tracking_test(before, after, design, n_looks)
    if not test.worse:
        return Verdict(False, "kept: the tracking since is not significantly worse than before", test,
                       log_evidence, decisive)
    if decisive:
        return Verdict(False, "kept: the tracking is worse but the residuals favour the detection decisively",
                       test, log_evidence, decisive)
    worst = int(np.argmax(np.asarray(test.ratio) / np.asarray(test.threshold)))
    return Verdict(True, f"tracking worse since applied (channel {worst}: mean-square ratio "
                   f"{test.ratio[worst]:.3g} > F threshold {test.threshold[worst]:.3g}) and the residual evidence "
                   f"not decisive (log Bayes factor {log_evidence if log_evidence is not None else float('nan'):.3g}"
                   f"{'' if fits else ', the belief does not fit the residuals'}; decisive: >= ln "
                   f"{design.decisive:g} and a fit)", test, log_evidence, decisive)
