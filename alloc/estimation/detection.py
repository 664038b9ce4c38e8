"""Failure detection and isolation by hypothesis tests on residuals (seed section 1.3.1).

Residuals.  Each sample brings the positions a healthy effector would have (``u``: the
command, or an actuator model's output), the measured virtual-control response ``y`` (k)
and, where a position sensor exists, the measured positions.  With the failures already
known applied (a jammed effector held, an effectiveness scaled), the residuals are

    r = (y - B_eff u_known) / sigma          (k, whitened moment residual)
    q_j = (position_j - u_known_j) / sigma_p (per effector with a sensor)

Every failure kind of :mod:`alloc.health` acts on one effector ``j`` as a deviation of its
effective position ``d_t`` from ``u_t``: ``r_t = b~_j d_t + noise`` (``b~_j = b_j / sigma``),
and ``q_t = d_t / sigma_p`` for the kinds that move the surface (all but effectiveness).

Detection (stage 1).  Over the last ``window`` samples, for each healthy effector, the
generalised likelihood ratio of "``d_t = theta_1 + theta_2 u_t``" (which contains every
kind's first-order signature: a jam ``p - u``, a loss of effectiveness ``(f - 1) u``) against
"no failure".  Under no failure, with Gaussian noise of the stated level and
autocorrelation, twice the log ratio is exactly chi-square with ``d = rank`` degrees of
freedom (``d <= 2``, ``<= 4`` with a position sensor).  The noise of a measured response is
rarely white: a rate differenced from a filtered sensor signal is correlated over a few
samples, and a statistic that assumed it white would have heavier tails than chi-square
(the slope term picks up the noise's own trend across the window).  Given the noise's
autocorrelation (``noise_correlation``, lags in samples, the same for every response axis)
the test is the generalised least-squares one: the window's residuals and regressors are
whitened by the inverse Cholesky factor of its Toeplitz correlation matrix first, so the
statistic is chi-square again.  The threshold is

    gamma = chi2.isf(alpha, d_max),   alpha = F * hop_seconds / 3600 / m_tested

(the GLR test of a linear Gaussian model: Basseville and Nikiforov, *Detection of Abrupt
Changes*, 1993, section 4.2; Wilks' theorem, exact here) for a design false-alarm rate ``F``
per hour: one test per effector every ``hop`` samples,
Bonferroni over effectors and tests, so the rate of alarms is at most ``F``; equal to it
(up to the union's overlap, small at small ``alpha``) when ``hop = window`` (independent
tests).  Overlapping windows (``hop < window``, the default ``window / 4``) are correlated and
alarm less than ``F``.  No excitation, no decision: when ``u_j`` is constant the model has
rank 1 and a surface jammed exactly where it is commanded produces no residual -- there is
nothing to detect and nothing is reported.

Isolation and classification (stage 2, :mod:`.isolation`) runs on an alarm: the
maximum-likelihood fit of every kind's signature on every movable effector, a
:class:`Detection` emitted when the posterior of the best reaches ``min_confidence``.


After a detection the event replaces what was known of that effector, the prediction
accounts for it and the buffers restart.  Every movable effector stays under test against
its current model (the fits are scored against it), so a limit first reported as a jam --
while the command stayed beyond it -- is reported again as limits once the surface is seen
inside, and an imperfect estimate is refined rather than blamed on a neighbour.

Memory is bounded: ring buffers of ``2 window`` samples (``2 long_window`` with a second,
long window) and a list of at most
``MAX_KEPT`` detections.  :meth:`FailureDetector.to_dict` gives the whole state.

Domain and cost.  Settings and samples are finite with ``|x| <= 1e50``; the whitened columns
``B / noise_std`` must stay within that bound too (a subnormal ``noise_std`` is refused).  The
buffers, the whitening matrices and the isolation's ``L x L`` tables (``L`` the buffer length)
are priced from the settings before anything is allocated, at most :data:`MAX_DETECTOR_BYTES`
(the estimate, :func:`detector_bytes`, is in bytes of the largest working set), and the
isolation's time on an alarm, ``m L^2`` cells, at most :data:`MAX_ISOLATION_CELLS`.  A sample whose
whitened residual leaves the domain, or whose test would record a non-finite statistic, is
refused (SampleError naming ``y``) and the state is unchanged; counters stay below ``2^53``.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

import numpy as np

from ..exceptions import OptionError, ProblemError
from ..health import EffectorHealth, FailureEvent, FailureKind, apply_event, health_from_dict, health_to_dict
from ..problem import MAX_MAGNITUDE, Problem, as_float_array, as_real, check_magnitude, short_repr
from ._checks import (
    MAX_COUNT,
    SampleError,
    StateError,
    sample_vector,
    samples_in,
    setting_real,
    setting_vector,
    state_array,
    state_count,
    state_mapping,
)
from ._glr import correlation_setting as _correlation_setting
from ._glr import linear_glr as _linear_glr
from ._glr import whitener as _whitener
from ._records import active_from_dict as _active_from_dict
from ._records import detection_from_dict as _detection_from_dict
from ._records import withdrawal_from_dict as _withdrawal_from_dict
from . import probation as _probation
from .isolation import Detection, Isolation, Withdrawal
from .robust import NominalLearner, RobustSettings

__all__ = ["FailureDetector", "Detection", "Withdrawal", "MAX_KEPT", "MAX_DETECTOR_BYTES", "MAX_ISOLATION_CELLS", "detector_bytes"]

#: detections (and withdrawals) kept in the state (older ones are dropped; the caller has received them)
MAX_KEPT = 64
#: The largest working set a detector's settings may imply (:func:`detector_bytes`): 256 MiB.
#: The isolation's ``L x L`` tables dominate (peak 6-10 ``L^2`` numbers measured with tracemalloc,
#: L 200-800): the buffer ``L`` is at most about 1,600 samples -- the time cap below binds first
#: from two effectors on.
MAX_DETECTOR_BYTES = 256 * 2 ** 20
#: The isolation's work on an alarm, ``m L^2`` table cells at most (``2^22``): 7-10e-7 s a cell
#: measured (2026-12-05, m 5-40, L 100-400), so about 3 s per isolation; five effectors allow a
#: buffer of 900 samples, 512 effectors one of 90 (the default designs: 32).
MAX_ISOLATION_CELLS = 2 ** 22
#: Samples of a window before it is priced (keeps ``round(window / sample_time)`` an exact integer)
_MAX_WINDOW_SAMPLES = 100_000


def detector_bytes(k: int, m: int, n: int, n_long: int, whiten: bool) -> int:
    """Bytes of the largest working set of a detector (``k`` axes, ``m`` effectors, windows of
    ``n`` and ``n_long`` samples): the ring buffers (``L = 2 max(n, n_long)`` samples of
    ``3 m + k + 1`` numbers), the whitening matrices and their factorisation (``4 n^2`` numbers
    each), and the isolation's tables on an alarm (about ``12 L^2`` numbers, measured: the
    run-to-stop table of suffix by sample and its temporaries, the reduced-limits table of
    ``2 L`` candidates by ``L`` samples)."""
    L = 2 * max(n, n_long)
    numbers = L * (3 * m + k + 1) + 12 * L * L
    if whiten:
        numbers += 4 * (n * n + n_long * n_long)
    return 8 * numbers


class FailureDetector(Isolation):
    """Streaming per-effector failure detection and isolation (see the module docstring).

    Parameters
    ----------
    problem : Problem
        The nominal vehicle: ``B``, limits, rate limits, names.
    noise_std : float or array (k,)
        Standard deviation of the measurement noise of each response axis.
    sample_time : float
        Seconds between samples.
    false_alarm_rate : float
        Design false alarms per hour (an upper bound, see the module docstring).
    window : float
        Seconds of data in each stage-1 test.
    long_window : float, optional
        Seconds of a second stage-1 test at every test time, for changes too small to show
        in ``window`` (a loss of a quarter of an effector's effectiveness: its evidence grows
        with the samples, the threshold only with their logarithm).  The false-alarm budget
        is shared (``alpha / 2`` each, Bonferroni), the buffers hold ``2 long_window``.
        ``None`` (default): one window.
    hop : int, optional
        Samples between tests (default a quarter window; the window's length gives
        independent tests).
    position_noise_std : float or array (m,), optional
        Position sensor noise; ``None``: no position sensors.
    min_confidence : float
        Posterior needed to report (effector and kind).
    noise_correlation : sequence of float, optional
        Autocorrelation of each response axis's noise at lags 1, 2, ... samples (lags beyond
        the sequence are zero; only those shorter than the window are used); ``None``: white.
        OptionError when not a correlation (outside (-1, 1), or the window's correlation
        matrix not positive definite).
    robust : True, mapping or RobustSettings, optional
        Judge residuals against a nominal model learnt in flight from a stated model
        uncertainty, with a learnt scale and correlation and Huber-clipped residuals
        (:mod:`.robust`); ``None`` (default): the stated model and noise are exact.
    probation : float
        Seconds each applied detection is judged on its own evidence, withdrawn when the data
        favour the health before it decisively (:mod:`.probation`); 0: never (default 2 s).
    effector_lag : float or array (m,), optional
        Seconds of each actuator's lag, for a robust detector to learn lag errors (rate
        regressors); ``None``: positions only.
    """

    def __init__(self, problem: Problem, noise_std: Any, sample_time: float, *, false_alarm_rate: float = 0.1,
                 window: float = 0.25, hop: int | None = None, position_noise_std: Any = None,
                 min_confidence: float = 0.95, noise_correlation: Any = None,
                 long_window: float | None = None, robust: Any = None, effector_lag: Any = None,
                 probation: float = 2.0) -> None:
        if not isinstance(problem, Problem):
            raise OptionError(f"problem: expected an alloc.Problem, got {type(problem).__name__}")
        self.problem = problem
        k, m = problem.k, problem.m
        self.noise_std = setting_vector("noise_std", noise_std, k, positive=True)
        with np.errstate(over="ignore"):
            Bn = np.array(problem.B, dtype=float) / self.noise_std[:, None]  # the columns' directions
        if not np.abs(Bn).max(initial=0.0) <= MAX_MAGNITUDE:
            i = int(np.argmax(~(np.abs(Bn).max(axis=1) <= MAX_MAGNITUDE)))
            raise OptionError(f"noise_std: noise_std[{i}] = {self.noise_std[i]:g} makes the whitened B / noise_std "
                              f"exceed {MAX_MAGNITUDE:g} (too small for this B)")
        self.dt = setting_real("sample_time", sample_time, 0.0, 3600.0, lo_open=True)
        self.false_alarm_rate = setting_real("false_alarm_rate", false_alarm_rate, 0.0, 3.6e9, lo_open=True)
        self.window_seconds = setting_real("window", window, 0.0, 3600.0, lo_open=True)
        self.N = max(4, samples_in("window", self.window_seconds, self.dt, _MAX_WINDOW_SAMPLES))
        if hop is None:
            self.hop = max(1, self.N // 4)
        else:
            if isinstance(hop, (bool, np.bool_)) or not isinstance(hop, (int, np.integer)) or not 1 <= hop <= self.N:
                raise OptionError(f"hop: expected an integer in [1, {self.N}] (samples), got {short_repr(hop)}")
            self.hop = int(hop)
        self.has_position = position_noise_std is not None
        self.position_std = (setting_vector("position_noise_std", position_noise_std, m, positive=True)
                             if self.has_position else np.full(m, np.inf))
        self.min_confidence = setting_real("min_confidence", min_confidence, 0.0, 1.0, lo_open=True, hi_open=True)
        self.long_window_seconds = (None if long_window is None
                                    else setting_real("long_window", long_window, 0.0, 3600.0, lo_open=True))
        self.N_long = (0 if long_window is None
                       else samples_in("long_window", self.long_window_seconds, self.dt, _MAX_WINDOW_SAMPLES))
        if long_window is not None and not self.N < self.N_long <= _MAX_WINDOW_SAMPLES:
            raise OptionError(f"long_window: {self.N_long} samples; expected more than the window's {self.N} "
                              f"and at most {_MAX_WINDOW_SAMPLES}")
        self.L = 2 * max(self.N, self.N_long)
        cost = detector_bytes(k, m, self.N, self.N_long, noise_correlation is not None)
        if cost > MAX_DETECTOR_BYTES:  # priced before the buffers, whiteners or tables exist
            field = "long_window" if self.N_long else "window"
            raise OptionError(f"{field}: a buffer of {self.L} samples needs about {cost / 2 ** 20:.0f} MiB "
                              f"(isolation tables {self.L} x {self.L}); at most {MAX_DETECTOR_BYTES // 2 ** 20} MiB")
        cells = m * self.L * self.L
        if cells > MAX_ISOLATION_CELLS:
            field = "long_window" if self.N_long else "window"
            raise OptionError(f"{field}: an isolation over {m} effectors and a buffer of {self.L} samples is {cells:.3g} "
                              f"table cells (seconds per alarm); at most {MAX_ISOLATION_CELLS:.3g}")
        self.noise_correlation = (None if noise_correlation is None
                                  else _correlation_setting(noise_correlation))
        self._whiten = None if self.noise_correlation is None else _whitener(self.noise_correlation, self.N)
        self._whiten_long = (None if self.noise_correlation is None or not self.N_long
                             else _whitener(self.noise_correlation, self.N_long))
        self._Bn = self._Bn0 = Bn
        self.robust = None if robust is None or robust is False else RobustSettings.from_value(robust)
        if effector_lag is not None and self.robust is None:
            raise OptionError("effector_lag: only a robust detector uses it (robust = None)")
        self.effector_lag = (None if effector_lag is None
                             else setting_vector("effector_lag", np.broadcast_to(effector_lag, (m,)) if np.ndim(effector_lag) == 0 else effector_lag, m))
        if self.effector_lag is not None and not ((self.effector_lag >= 0) & (self.effector_lag <= 3600)).all():
            raise OptionError("effector_lag: expected seconds in [0, 3600] for every effector")
        self._learner = (None if self.robust is None else
                         NominalLearner(self.robust, Bn, problem.umax - problem.umin, self.effector_lag,
                                        self.noise_correlation, self.dt))
        self.probation = setting_real("probation", probation, 0.0, 3600.0)
        self._probations: dict[str, dict[str, Any]] = {}  # effector -> its evidence so far (.probation)
        self._design()
        self.health: dict[str, EffectorHealth] = {}
        self.detections: list[Detection] = []
        #: detections taken back (:meth:`withdraw`), oldest first, at most MAX_KEPT
        self.withdrawals: list[Withdrawal] = []
        self._unpopped: list[Withdrawal] = []  # withdrawals not yet handed out by pop_withdrawals
        # per effector under a detection: its health before the first detection of the chain
        # (what "nothing failed" restores), and the latest detection's time and kind
        self._active: dict[str, dict[str, Any]] = {}
        self.alarm_count = 0  # stage-1 alarms (isolated or not)
        self.unisolated_count = 0  # alarms dropped without a decision
        self.samples = 0
        self.last_time = -math.inf
        self._pending: dict[str, Any] | None = None
        self._restart()
        self._rate_state = np.array(problem.up, dtype=float)  # predicted positions of rate-limited effectors

    # ------------------------------------------------------------------ design
    @property
    def tested(self) -> np.ndarray:
        """Indices of the effectors tested: every movable one, a failed one against its
        current model (so a failure reported wrongly, or changing, is reported again)."""
        return self._tested

    @property
    def dof(self) -> int:
        """Degrees of freedom of the stage-1 statistic at full rank."""
        return 4 if self.has_position else 2

    def threshold(self) -> float:
        """The stage-1 threshold ``gamma = chi2.isf(alpha, d)`` (module docstring)."""
        return self._gamma

    def _design(self) -> None:
        self._tested = np.flatnonzero(self.problem.umax > self.problem.umin)
        m_tested = max(1, len(self._tested))
        alpha = self.false_alarm_rate * self.hop * self.dt / 3600.0 / m_tested / (2 if self.N_long else 1)
        from scipy.stats import chi2  # here: importing scipy.stats costs 1.2-1.5 s, every service start paid it
        self._gamma = float(chi2.isf(min(alpha, 0.5), self.dof))
        if not math.isfinite(self._gamma):  # alpha underflowed: a test that could never alarm
            raise OptionError(f"false_alarm_rate: {self.false_alarm_rate:g} per hour is a per-test probability of "
                              f"{alpha:g}, too small for any threshold")

    # ------------------------------------------------------------------ model
    def _effective(self) -> tuple[np.ndarray, np.ndarray]:
        """``B_eff`` and the health-derived jam positions (NaN where not held)."""
        B = np.array(self.problem.B, dtype=float)
        held = np.full(self.problem.m, np.nan)
        for name, h in self.health.items():
            j = self.problem.index(name)
            if h.floating:
                B[:, j] = 0.0
            else:
                B[:, j] *= h.effectiveness
                if h.jam_position is not None:
                    held[j] = h.jam_position
        return B, held

    def _known_positions(self, u: np.ndarray) -> np.ndarray:
        """Where the effectors are, given the failures known: held, clipped, rate-limited."""
        out = u.copy()
        for name, h in self.health.items():
            j = self.problem.index(name)
            if h.jam_position is not None:
                out[j] = h.jam_position
            elif h.limits is not None:
                out[j] = min(max(out[j], h.limits[0]), h.limits[1])
            if h.rate_limits is not None and h.jam_position is None:
                prev = self._rate_state[j]
                out[j] = prev + min(max(out[j] - prev, h.rate_limits[0] * self.dt), h.rate_limits[1] * self.dt)
                self._rate_state[j] = out[j]
        return out

    def _restart(self) -> None:
        k, m, L = self.problem.k, self.problem.m, self.L
        self._U = np.zeros((L, m))
        self._K = np.zeros((L, m))
        self._R = np.zeros((L, k))
        self._Rc = np.zeros((L, k))  # what stage 1 sees: R, Huber-clipped when robust
        self._Q = np.zeros((L, m))
        self._T = np.zeros(L)
        self._head = 0
        self._count = 0
        self._since_test = 0
        self._pending = None
        self._B_eff, _ = self._effective()
        self._f_known = np.ones(m)  # the known effectiveness of each effector (0: floating)
        for name, h in self.health.items():
            self._f_known[self.problem.index(name)] = 0.0 if h.floating else h.effectiveness

    # ------------------------------------------------------------------ streaming
    def update(self, u: Any, y: Any, position: Any = None, time: float | None = None) -> list[Detection]:
        """One sample; returns the detections it completes (usually none).

        ``u`` (m,) the healthy positions (command or actuator model), ``y`` (k,) the measured
        response, ``position`` (m,) the measured positions (required with position sensors,
        refused without), ``time`` in seconds (default ``samples * sample_time``;
        strictly increasing).  SampleError naming the field otherwise (nothing changes).
        """
        m = self.problem.m
        u = sample_vector("u", u, m)
        y = sample_vector("y", y, self.problem.k)
        if position is not None:
            if not self.has_position:
                raise SampleError("position: this detector has no position sensors (position_noise_std = None)")
            pos = sample_vector("position", position, m)
        elif self.has_position:
            # a missing reading is not evidence of no deviation: every sample carries them all
            raise SampleError("position: this detector has position sensors; every sample needs their readings")
        else:
            pos = None
        t = self.samples * self.dt if time is None else as_real("time", time, SampleError)
        if not t > self.last_time:
            raise SampleError(f"time: {t:g} is not after the previous sample's {self.last_time:g}")
        if self.samples >= MAX_COUNT:
            raise SampleError(f"time: {self.samples} samples, the most one detector counts; start a new one")
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):  # refused below, never raised
            rate_state = self._rate_state.copy()
            known = self._known_positions(u)
            r = (y - self._B_eff @ known) / self.noise_std
            r0 = r
            if self._learner is not None:
                phi = self._learner.regressor(known)
                r, s_pred = self._learner.residual(r0, phi)
            q = np.zeros(m) if pos is None else (pos - known) / self.position_std
            if not (np.abs(r).max(initial=0.0) <= MAX_MAGNITUDE and np.abs(q).max(initial=0.0) <= MAX_MAGNITUDE):
                self._rate_state = rate_state
                field = "y" if not np.abs(r).max(initial=0.0) <= MAX_MAGNITUDE else "position"
                raise SampleError(f"{field}: the whitened residual leaves the valid domain (|x| <= {MAX_MAGNITUDE:g}) "
                                  "at this noise level; refused, the state is unchanged")
            i = self._head
            saved = (self._U[i].copy(), self._K[i].copy(), self._R[i].copy(), self._Rc[i].copy(), self._Q[i].copy(), self._T[i],
                     self._head, self._count, self._since_test, self.samples, self.last_time, rate_state,
                     None if self._pending is None else dict(self._pending), self.alarm_count,
                     self.unisolated_count)
            self._U[i], self._K[i], self._R[i], self._Q[i], self._T[i] = u, known, r, q, t
            if self._learner is not None:
                # stage 1 judges the innovation in predictive units, Huber-clipped; the
                # isolation fits amplitudes, so it sees it in the noise scale its columns use
                self._Rc[i] = np.clip(r, -self.robust.huber, self.robust.huber)
                self._R[i] = r * s_pred / self._learner.scale()
            else:
                self._Rc[i] = r
            self._head = (i + 1) % self.L
            self._count = min(self._count + 1, self.L)
            self._since_test += 1
            self.samples += 1
            self.last_time = t
            out: list[Detection] = []
            if self._count >= self.N and self._since_test >= self.hop:
                self._since_test = 0
                try:
                    out = self._test(t)
                except _NonFinite as exc:
                    (self._U[i], self._K[i], self._R[i], self._Rc[i], self._Q[i], self._T[i], self._head, self._count,
                     self._since_test, self.samples, self.last_time, self._rate_state, self._pending, self.alarm_count,
                     self.unisolated_count) = saved
                    raise SampleError(f"y: the test would record a non-finite {exc} at this sample's scale; refused, "
                                      "the state is unchanged") from None
            robust = self._learner is not None
            # after the test (nothing to restore), before the learner moves on (its residuals)
            for name, statistic in _probation.step(self, t, u, known, r, q, r0 if robust else None,
                                                   s_pred if robust else None):
                self.withdraw(name, t, _probation.REASON, statistic)
            if robust:  # an alarm being isolated, or just decided, is not the nominal model
                self._learner.learn(r0, phi, r, s_pred, known, model=self._pending is None and not out)
            return out

    def _window(self, n: int, clipped: bool = False) -> tuple[np.ndarray, ...]:
        idx = (self._head - n + np.arange(n)) % self.L
        return self._U[idx], (self._Rc if clipped else self._R)[idx], self._Q[idx], self._T[idx], self._K[idx]

    def _stage1(self, n: int) -> tuple[np.ndarray, np.ndarray]:
        """Stage-1 statistics of the tested effectors over the last ``n`` samples (``N`` or ``N_long``)."""
        tested = self.tested
        U, R, Q, _, _ = self._window(n, clipped=True)
        Bw = self._Bn[:, tested]
        c = np.einsum("ij,ij->j", Bw, Bw)
        S = R @ Bw  # (n, t): b~_j . r~
        if self._learner is None:
            whiten = self._whiten if n == self.N else self._whiten_long
        else:
            rho = self._learner.correlation(n)
            whiten = None if rho is None else _whitener(rho, n)
        stat = _linear_glr(S, U[:, tested], c, whiten)
        if self.has_position:  # position sensors: their own (white) noise
            stat = stat + _linear_glr(Q[:, tested], U[:, tested], np.ones(len(tested)))
        return tested, stat

    def window_statistics(self, u: Any, y: Any, long: bool = False) -> np.ndarray:
        """Stage-1 statistics of every window of ``window`` (``long``: ``long_window``) consecutive
        samples, offline.

        ``u`` (n, m) and ``y`` (n, k) as :meth:`update` takes them, for a detector without
        position sensors, against its current model (the failures it knows applied as it
        would apply them to the first sample; rate limits not tracked across samples).
        Returns ``(n - N + 1, len(tested))``: row ``i`` the statistics after sample
        ``i + N - 1``, those :meth:`update` compares with :meth:`threshold`.  Nothing changes.
        """
        if self.has_position or self.robust is not None:
            raise OptionError("window_statistics: not for a detector with position sensors or a robust one "
                              "(its model and scale change with every sample)")
        if long and not self.N_long:
            raise OptionError("window_statistics: long=True for a detector without a long_window")
        m, k, N = self.problem.m, self.problem.k, self.N_long if long else self.N
        U = as_float_array("u", u, SampleError)
        Y = as_float_array("y", y, SampleError)
        if U.ndim != 2 or U.shape[1] != m or Y.shape != (U.shape[0], k) or U.shape[0] < N:
            raise SampleError(f"u: expected (n, {m}) with y (n, {k}) and n >= {N}, got {U.shape} and {Y.shape}")
        check_magnitude("u", U, SampleError)
        check_magnitude("y", Y, SampleError)
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            stat = self._window_statistics(U, Y, N, long)
        if not np.isfinite(stat).all():
            raise SampleError("y: a window's statistic is not finite at this scale (whitened residuals too large)")
        return stat

    def _window_statistics(self, U: np.ndarray, Y: np.ndarray, N: int, long: bool) -> np.ndarray:
        tested = self.tested
        B_eff, held = self._effective()
        known = np.where(np.isnan(held), U, held)
        R = (Y - known @ B_eff.T) / self.noise_std
        Bw = self._Bn[:, tested]
        S = np.lib.stride_tricks.sliding_window_view(R @ Bw, N, axis=0).swapaxes(1, 2)  # (windows, N, t)
        Uw = np.lib.stride_tricks.sliding_window_view(known[:, tested], N, axis=0).swapaxes(1, 2)
        return _linear_glr(S, Uw, np.einsum("ij,ij->j", Bw, Bw), self._whiten_long if long else self._whiten)

    def _test(self, t: float) -> list[Detection]:
        if len(self.tested) == 0:
            return []
        gamma = self.threshold()
        if self._learner is not None:  # the learnt columns in the learnt scale's units (stage 1, isolation)
            self._Bn = self._learner.effectiveness(self._Bn0) / self._learner.scale()[:, None]
        if self._pending is None:
            tested, stat = self._stage1(self.N)
            if self.N_long and self._count >= self.N_long and not (stat > gamma).any():
                stat = np.maximum(stat, self._stage1(self.N_long)[1])
            if not np.isfinite(stat).all():
                raise _NonFinite("stage-1 statistic")
            if not (stat > gamma).any():
                return []
            self.alarm_count += 1
            self._pending = {"time": t, "statistic": float(stat.max()), "hops": 0}
        pending = self._pending
        try:
            detection = self._isolate(pending, gamma)
        except ProblemError as exc:  # a fitted parameter outside the domain (FailureEvent checks them)
            raise _NonFinite(f"failure parameter ({exc})") from None
        if detection is not None:
            numbers = (detection.time, detection.onset, detection.confidence, detection.parameter,
                       detection.parameter_std, detection.end_position, *detection.event.params.values())
            if not all(x is None or math.isfinite(x) for x in numbers):
                raise _NonFinite("detection")
            detection = replace(detection, improvement=_probation.explained_fraction(self, detection))
            self._emit(detection)
            return [detection]
        pending["hops"] += 1
        if pending["hops"] > self.L // self.hop:
            self.unisolated_count += 1
            self._pending = None
        return []

    def _emit(self, detection: Detection) -> None:
        ev = detection.event
        # a new finding replaces what was known of that effector (a jam would otherwise
        # take precedence over reduced limits, see alloc.health)
        name = self.problem.names[self.problem.index(ev.effector)]
        before = self._active.get(name, {}).get("before", self.health.get(name))
        self._active[name] = {"before": before, "time": float(detection.time), "kind": ev.kind.value}
        _, health = apply_event(self.problem, self.health, FailureEvent(ev.effector, FailureKind.REPAIR))
        _, self.health = apply_event(self.problem, health, ev)
        j = self.problem.index(detection.event.effector)
        self._rate_state[j] = (float(self._U[(self._head - 1) % self.L, j]) if detection.end_position is None
                               else detection.end_position)
        self.detections.append(detection)
        del self.detections[:-MAX_KEPT]
        _probation.start(self, name, detection.time, detection)
        self._restart()

    # ------------------------------------------------------------------ withdrawal
    def withdraw(self, effector: str, time: float, reason: str, statistic: float | None = None) -> Withdrawal:
        """Take back the detection standing on ``effector``: its health before the detection (the
        first of a chain of refinements) is restored and a :class:`Withdrawal` recorded.

        For a component that judges a detection by its consequences (a tracking monitor that
        sees the allocation do worse with it than without); the detector withdraws on its own
        evidence too.  ``time`` in seconds (finite), ``reason`` in words.  The buffers restart:
        their residuals were computed against the event's model.  SampleError naming the field
        when ``effector`` is unknown or has no detection standing.
        """
        if not isinstance(effector, str):
            raise SampleError(f"effector: expected an effector name, got {short_repr(effector)}")
        if effector not in self.problem.names:
            raise SampleError(f"effector: {effector!r} is not one of {list(self.problem.names)}")
        if effector not in self._active:
            raise SampleError(f"effector: no detection of {effector!r} stands to withdraw")
        t = as_real("time", time, SampleError)
        if not isinstance(reason, str):
            raise SampleError(f"reason: expected a string, got {short_repr(reason)}")
        if statistic is not None:
            statistic = as_real("statistic", statistic, SampleError)
        active = self._active.pop(effector)
        self._probations.pop(effector, None)
        withdrawal = Withdrawal(effector=effector, kind=active["kind"], time=t, detection_time=active["time"],
                                statistic=statistic, reason=reason[:200])
        health = dict(self.health)
        if active["before"] is None:
            health.pop(effector, None)
        else:
            health[effector] = active["before"]
        self.health = health
        self.withdrawals.append(withdrawal)
        del self.withdrawals[:-MAX_KEPT]
        self._unpopped.append(withdrawal)
        del self._unpopped[:-MAX_KEPT]
        self._restart()
        return withdrawal

    def pop_withdrawals(self) -> list[Withdrawal]:
        """The withdrawals since the last call (oldest first; at most MAX_KEPT), then forgets them
        (:attr:`withdrawals` keeps them): :meth:`update` returns only detections, so a caller
        that applies what the detector believes asks for these after each update."""
        out, self._unpopped = self._unpopped, []
        return out

    # ------------------------------------------------------------------ durable state
    def to_dict(self) -> dict[str, Any]:
        """The whole state as JSON-ready values (bounded: ``O(window (k + m))`` numbers)."""
        order = (self._head - self._count + np.arange(self._count)) % self.L
        return {
            "kind": "detector", "noise_std": self.noise_std.tolist(), "sample_time": self.dt,
            "false_alarm_rate": self.false_alarm_rate, "window": self.window_seconds, "hop": self.hop,
            "long_window": self.long_window_seconds,
            "position_noise_std": self.position_std.tolist() if self.has_position else None,
            "min_confidence": self.min_confidence,
            "noise_correlation": None if self.noise_correlation is None else self.noise_correlation.tolist(),
            "robust": None if self._learner is None else self._learner.to_dict(),
            "effector_lag": None if self.effector_lag is None else self.effector_lag.tolist(),
            "probation": self.probation, "probations": _probation.probations_to_dict(self._probations),
            "health": health_to_dict(self.health),
            "samples": self.samples, "last_time": None if math.isinf(self.last_time) else self.last_time,
            "alarm_count": self.alarm_count, "unisolated_count": self.unisolated_count,
            "since_test": self._since_test, "pending": self._pending, "rate_state": self._rate_state.tolist(),
            "buffer": {"U": self._U[order].tolist(), "K": self._K[order].tolist(), "R": self._R[order].tolist(),
                       "Rc": self._Rc[order].tolist(), "Q": self._Q[order].tolist(),
                       "T": self._T[order].tolist()},
            "detections": [d.to_dict() for d in self.detections],
            "withdrawals": [w.to_dict() for w in self.withdrawals],
            "unpopped": len(self._unpopped),
            "active": {name: {"before": None if a["before"] is None else a["before"].to_dict(), "time": a["time"],
                              "kind": a["kind"]} for name, a in self._active.items()},
        }

    @classmethod
    def from_dict(cls, problem: Problem, data: Any) -> FailureDetector:
        """Inverse of :meth:`to_dict` for the same ``problem``; StateError naming the field."""
        d = state_mapping(data, "detector", ("noise_std", "sample_time", "false_alarm_rate", "window", "hop",
                                             "position_noise_std", "min_confidence", "health", "samples",
                                             "last_time", "alarm_count", "unisolated_count", "since_test",
                                             "pending", "rate_state", "buffer", "detections"))
        try:
            det = cls(problem, d["noise_std"], d["sample_time"], false_alarm_rate=d["false_alarm_rate"],
                      window=d["window"], hop=d["hop"], position_noise_std=d["position_noise_std"],
                      min_confidence=d["min_confidence"],
                      noise_correlation=d.get("noise_correlation"),  # absent from states stored before it
                      long_window=d.get("long_window"),
                      robust=None if d.get("robust") is None else _robust_settings(d["robust"]),
                      effector_lag=d.get("effector_lag"), probation=d.get("probation", 2.0))
        except (OptionError, TypeError, ValueError) as exc:  # the settings: named by the constructor's message
            raise StateError(str(exc)) from None
        try:
            det.health = health_from_dict(d["health"])
            for name in det.health:
                problem.index(name)
        except (TypeError, ValueError) as exc:
            raise StateError(f"health: {exc}") from None
        for name in ("samples", "alarm_count", "unisolated_count", "since_test"):
            state_count(name, d[name])
        det.samples, det.alarm_count, det.unisolated_count = d["samples"], d["alarm_count"], d["unisolated_count"]
        # a NaN last time would refuse every later sample; a time is a real number or null (none yet)
        det.last_time = -math.inf if d["last_time"] is None else as_real("last_time", d["last_time"], StateError)
        det._restart()
        det._since_test = d["since_test"]
        buf = d["buffer"]
        if not isinstance(buf, dict):
            raise StateError("buffer: expected a mapping")
        T = as_float_array("T", buf.get("T", []), StateError)
        if T.ndim != 1 or T.size > det.L:
            raise StateError(f"T: expected at most {det.L} stored sample times, got shape {T.shape}")
        n = T.size
        check_magnitude("T", T, StateError)
        if n and not (np.diff(T) > 0).all() or n and not T[-1] <= det.last_time:
            raise StateError("T: the stored sample times must increase and end at or before last_time")
        k, m = problem.k, problem.m
        det._U[:n] = state_array("U", buf.get("U", []) if n else np.zeros((0, m)), (n, m))
        det._K[:n] = state_array("K", buf.get("K", []) if n else np.zeros((0, m)), (n, m))
        det._R[:n] = state_array("R", buf.get("R", []) if n else np.zeros((0, k)), (n, k))
        det._Rc[:n] = state_array("Rc", buf["Rc"], (n, k)) if n and "Rc" in buf else det._R[:n]
        if det._learner is not None:
            det._learner.load(d["robust"])
        det._Q[:n] = state_array("Q", buf.get("Q", []) if n else np.zeros((0, m)), (n, m))
        det._T[:n] = T
        det._head, det._count = n % det.L, n
        det._rate_state = state_array("rate_state", d["rate_state"], (m,))
        pending = d["pending"]
        if pending is not None:
            if not (isinstance(pending, dict) and set(pending) == {"time", "statistic", "hops"}):
                raise StateError("pending: expected null or a mapping with time, statistic, hops")
            pending = {"time": as_real("pending", pending["time"], StateError),
                       "statistic": as_real("pending", pending["statistic"], StateError),
                       "hops": state_count("pending", pending["hops"])}
        det._pending = pending
        if not isinstance(d["detections"], list):
            raise StateError("detections: expected a list")
        det.detections = [_detection_from_dict(x) for x in d["detections"][-MAX_KEPT:]]
        # absent from states stored before withdrawals existed
        withdrawals = d.get("withdrawals", [])
        if not isinstance(withdrawals, list):
            raise StateError("withdrawals: expected a list")
        det.withdrawals = [_withdrawal_from_dict(x) for x in withdrawals[-MAX_KEPT:]]
        unpopped = state_count("unpopped", d.get("unpopped", 0))
        det._unpopped = det.withdrawals[len(det.withdrawals) - min(unpopped, len(det.withdrawals)):]
        det._active = _active_from_dict(d.get("active", {}), det)
        det._probations = _probation.probations_from_dict(d.get("probations", {}), det)  # absent before probation
        return det


class _NonFinite(Exception):
    """A test on the current sample would record a non-finite number (internal: the update
    restores its state and refuses the sample)."""


def _robust_settings(d: Any) -> RobustSettings:
    if not isinstance(d, dict) or not isinstance(d.get("settings"), dict):
        raise StateError("robust: expected null or a mapping with its settings")
    return RobustSettings.from_value(d["settings"])
