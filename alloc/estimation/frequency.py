"""Frequency-domain least squares with a recursive Fourier transform (seed Eqs 1.5-1.12).

Every sample updates, for each frequency ``omega`` of a stated band, the running transforms
(Eq 1.7, ``X_i = X_(i-1) + x_i exp(-j omega i dt)``, ``x~ = X dt``) of the regressor and of the
output; an estimate solves Eq 1.12, ``theta = Re(X* X)^(-1) Re(X* Y)``, the least-squares
fit with complex data of Eq 1.10, for all output rows at once (``Re(X* X)`` is shared,
as the seed notes).  Two forms:

``response``   ``y = B u + noise``: ``Y = y~``, regressor ``u~`` (the effectiveness matrix
               from measured virtual-control responses).
``derivative`` ``x' = A x + B u`` (Eq 1.5): ``Y_r = j omega x~_r``, regressor ``[x~, u~]``;
               ``theta_r = [A_r, B_r]`` (Eq 1.8).

The seed's own findings (section 1.3.2.2) set the design:

* the band excludes zero frequency (trim and bias do not enter); default 0.1-1.5 Hz, the
  band the seed reports working for aircraft rigid-body modes;
* a nonzero initial state or a bias spills into the low bins, so every signal passes a
  first-order high-pass (the signal minus its low-passed self, the seed's remedy) with its
  corner at a quarter of the band's lowest frequency.  A linear filter applied to both sides
  of a linear relation leaves the relation unchanged, so it biases nothing;
* the transforms have infinite memory, so an estimator that must follow a change restarts
  them: two banks of transforms, each restarted every ``window`` seconds, half a window
  apart; an estimate uses the older bank, so it rests on between ``window / 2`` and
  ``window`` seconds of data, and a change is forgotten at most ``window`` seconds later.

Memory is fixed (two banks of ``f (p + k)`` complex numbers), as the seed says.  An estimate
also forms the noise transform ``Phi``, ``2 f`` rows by the bank's samples (up to ``window /
sample_time``), so the settings are priced before anything is allocated: at most
:data:`MAX_BINS` frequencies (counted from ``band`` and ``spacing`` as a float, not by
building them) and ``f`` times the window's samples at most :data:`MAX_TRANSFORM_CELLS`
(about 64 MiB of ``Phi``); beyond, OptionError naming ``spacing`` or ``window``.

Uncertainty (``response`` form).  The noise's transforms are linear in the noise samples:
the stacked real and imaginary parts are ``dt Phi e`` with ``Phi`` the bank's cosine and
sine rows passed through the (adjoint of the) high-pass, so the estimate's covariance is
exactly ``sigma^2 dt^2 K K^T`` with ``K = Re(X* X)^(-1) X_s^T Phi`` -- correlated bins included
-- for white noise of standard deviation ``sigma`` (given, or estimated from the residuals
with the same matrix).  In the ``derivative`` form the states are noisy on both sides of the
regression and the same formula is only an approximation.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..exceptions import OptionError
from ..domain import short_repr
from ._checks import (
    StateError,
    sample_vector,
    samples_in,
    setting_real,
    setting_vector,
    state_array,
    state_count,
    state_mapping,
)

__all__ = ["FrequencyDomainEstimator", "FrequencyEstimate", "MAX_BINS", "MAX_TRANSFORM_CELLS"]

#: Frequencies in the band at most.
MAX_BINS = 512
#: Frequencies times the window's samples at most: the noise transform ``Phi`` of an estimate
#: is ``2 f`` by the window's samples (64 MiB at this cap; its filtering doubles it).
MAX_TRANSFORM_CELLS = 2 ** 22

#: relative singular-value cut: directions of Re(X* X) below it are unidentified (seed 1.3.2.5)
RANK_RTOL = 1e-9


@dataclass(frozen=True)
class FrequencyEstimate:
    """One solution of Eq 1.12.

    ``theta`` (k, p); ``std`` (k, p), ``inf`` for a parameter the data do not determine
    (it then holds the minimum-norm value); ``rank`` of ``Re(X* X)``; ``samples`` behind it;
    ``condition`` of ``Re(X* X)`` (``inf`` when rank deficient).
    """

    theta: np.ndarray
    std: np.ndarray
    rank: int
    samples: int
    condition: float


class _Bank:
    """One restartable set of running transforms (and its own high-pass state)."""

    __slots__ = ("X", "Y", "count", "lp")

    def __init__(self, f: int, p: int, k: int, n_signals: int) -> None:
        self.X = np.zeros((f, p), dtype=complex)
        self.Y = np.zeros((f, k), dtype=complex)
        self.count = 0
        self.lp = np.zeros(n_signals)

    def restart(self) -> None:
        self.X[:] = 0.0
        self.Y[:] = 0.0
        self.count = 0


class FrequencyDomainEstimator:
    """Seed Eqs 1.5-1.12 with a windowed restart (see the module docstring).

    Parameters
    ----------
    n_outputs : int
        ``k``: outputs (``response``) or states (``derivative``).
    n_inputs : int
        ``m``: effectors.
    sample_time : float
        Seconds between samples.
    band : (float, float)
        Lowest and highest frequency in Hz (both above zero, below Nyquist).
    spacing : float
        Bin spacing in Hz.
    window : float
        Seconds between restarts of each bank (the memory; one period of the
        lowest frequency at least).
    form : "response" or "derivative"
    noise_std : float or array (k,), optional
        White measurement noise of each output; estimated from the residuals when omitted.
    highpass : bool
        Pass every signal through the high-pass described above.
    """

    def __init__(self, n_outputs: int, n_inputs: int, sample_time: float, *, band: tuple[float, float] = (0.1, 1.5),
                 spacing: float = 0.05, window: float = 20.0, form: str = "response", noise_std: Any = None,
                 highpass: bool = True) -> None:
        for name, value in (("n_outputs", n_outputs), ("n_inputs", n_inputs)):
            if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)) or not 1 <= value <= 1024:
                raise OptionError(f"{name}: expected an integer in [1, 1024], got {short_repr(value)}")
        if not isinstance(form, str) or form not in ("response", "derivative"):
            raise OptionError(f"form: expected 'response' or 'derivative', got {short_repr(form)}")
        if not isinstance(highpass, bool):
            raise OptionError(f"highpass: expected true or false, got {type(highpass).__name__}")
        self.k, self.m, self.form, self.highpass = int(n_outputs), int(n_inputs), form, highpass
        self.dt = setting_real("sample_time", sample_time, 0.0, 3600.0, lo_open=True)
        nyquist = 0.5 / self.dt
        if not (isinstance(band, (tuple, list)) and len(band) == 2):
            raise OptionError(f"band: expected (low, high) in Hz, got {short_repr(band)}")
        lo = setting_real("band", band[0], 0.0, nyquist, lo_open=True, hi_open=True)
        hi = setting_real("band", band[1], lo, nyquist, hi_open=True)
        self.spacing = setting_real("spacing", spacing, 0.0, max(hi - lo, 1e-12) if hi > lo else 1.0, lo_open=True)
        self.band = (lo, hi)
        bins = np.floor((hi - lo) / self.spacing + 1e-9) + 1  # counted before any is built: 1e-12 asked 10 TiB
        if not bins <= MAX_BINS:
            raise OptionError(f"spacing: {bins:.3g} bins in the band; at most {MAX_BINS}")
        self.freqs = lo + self.spacing * np.arange(int(bins))
        self.window = setting_real("window", window, 1.0 / lo, 1e6)
        self.window_samples = max(2, samples_in("window", self.window, self.dt, MAX_TRANSFORM_CELLS // self.freqs.size))
        self.noise_known = noise_std is not None
        self.noise_std = setting_vector("noise_std", noise_std, self.k, positive=True) if noise_std is not None \
            else np.full(self.k, np.nan)
        self.p = self.m + (self.k if form == "derivative" else 0)
        self._omega = 2.0 * np.pi * self.freqs
        self._rot = np.exp(-1j * self._omega * self.dt)
        #: high-pass corner (Hz) and its one-step low-pass gain
        self.corner = lo / 4.0
        self._a = 1.0 - np.exp(-2.0 * np.pi * self.corner * self.dt)
        n_signals = self.m + self.k
        f = self.freqs.size
        self._banks = [_Bank(f, self.p, self.k, n_signals), _Bank(f, self.p, self.k, n_signals)]
        self.samples = 0

    # ------------------------------------------------------------------ streaming
    def update(self, u: Any, y: Any) -> None:
        """One sample: effector positions ``u`` (m,) and outputs ``y`` (k,) -- the measured
        response (``response``) or the states (``derivative``).  SampleError naming the
        field for a wrong shape or a non-finite value (the state is then unchanged)."""
        u = sample_vector("u", u, self.m)
        y = sample_vector("y", y, self.k)
        signals = np.concatenate([u, y])
        half = self.window_samples // 2
        for b, bank in enumerate(self._banks):
            # bank 1 starts half a window after bank 0; each restarts every window
            if b == 1 and self.samples < half:
                continue
            if bank.count >= self.window_samples:
                bank.restart()
            if bank.count == 0:
                bank.lp = signals.copy()  # the high-pass starts at rest: no initial-state step
            if self.highpass:
                bank.lp = bank.lp + self._a * (signals - bank.lp)
                s = signals - bank.lp
            else:
                s = signals
            phasor = self._rot ** bank.count  # bank-local time: Eq 1.12 is invariant to each bin's phase
            su, sy = s[:self.m], s[self.m:]
            if self.form == "response":
                bank.X += np.outer(phasor, su)
            else:
                bank.X[:, :self.k] += np.outer(phasor, sy)
                bank.X[:, self.k:] += np.outer(phasor, su)
            bank.Y += np.outer(phasor, sy)
            bank.count += 1
        self.samples += 1

    def _active(self) -> _Bank:
        return max(self._banks, key=lambda bank: bank.count)

    def estimate(self) -> FrequencyEstimate:
        """Eq 1.12 on the older bank, with its uncertainty (module docstring)."""
        bank = self._active()
        p, k = self.p, self.k
        X = bank.X * self.dt  # Eq 1.7: x~ = X dt
        Y = bank.Y * self.dt
        if self.form == "derivative":
            Y = (1j * self._omega)[:, None] * Y
        Xs = np.vstack([X.real, X.imag])  # Eq 1.12 is the real least squares of the stacked parts
        Ys = np.vstack([Y.real, Y.imag])
        U, sv, Vt = np.linalg.svd(Xs, full_matrices=False)
        keep = sv > RANK_RTOL * (sv[0] if sv.size and sv[0] > 0 else 1.0)
        rank = int(keep.sum())
        theta = np.zeros((k, p))
        std = np.full((k, p), np.inf)
        if rank == 0 or bank.count < 2:
            return FrequencyEstimate(theta, std, 0, bank.count, float("inf"))
        V, s_inv = Vt[keep].T, 1.0 / sv[keep]
        pinv = (V * s_inv) @ U[:, keep].T  # (p, 2f)
        theta = (pinv @ Ys).T
        Phi = self._noise_rows(bank.count)  # (2f, N): noise transform per unit noise, over dt
        K = pinv @ Phi * self.dt
        unit_var = np.einsum("ij,ij->i", K, K)
        if self.noise_known:
            sigma2 = self.noise_std ** 2
        else:
            resid = Ys - Xs @ theta.T
            Hat = U[:, keep] @ U[:, keep].T
            N = Phi * self.dt
            dof = float(np.einsum("ij,ij->", N, N) - np.einsum("ij,ij->", Hat @ N, N))
            sigma2 = (resid ** 2).sum(axis=0) / dof if dof > 0 else np.full(k, np.inf)
        std = np.sqrt(np.maximum(sigma2[:, None] * unit_var[None, :], 0.0))
        if rank < p:  # a parameter with any part in the unidentified directions is undetermined
            hidden = Vt[~keep]
            undetermined = (np.abs(hidden).max(axis=0) > 1e-6 if hidden.size else np.zeros(p, dtype=bool))
            if Vt.shape[0] < p:  # fewer stacked rows (2 f) than parameters: R^p beyond Vt's rows is hidden too
                undetermined |= np.einsum("ij,ij->j", Vt[keep], Vt[keep]) < 1.0 - 1e-12
            std[:, undetermined] = np.inf
        cond = float(sv[0] ** 2 / sv[-1] ** 2) if rank == p else float("inf")
        return FrequencyEstimate(theta, std, rank, bank.count, cond)

    def _noise_rows(self, n: int) -> np.ndarray:
        """``Phi`` (2f, n): the stacked real/imaginary transform of white noise samples,
        through the adjoint of the bank's high-pass (so correlations are exact)."""
        t = np.arange(n) * self.dt
        arg = np.outer(self._omega, t)
        rows = np.vstack([np.cos(arg), -np.sin(arg)])
        if not self.highpass:
            return rows
        # high-pass output h = x - lp, lp_0 = x_0, lp_j = (1-a) lp_(j-1) + a x_j (the bank's
        # filter, with lp_0 = x_0 + a (x_0 - x_0)); r F = r - r L with L the low-pass map
        a = self._a
        from scipy.signal import lfilter  # here: scipy.signal is 0.2 s of every service start
        rev = lfilter([1.0], [1.0, -(1.0 - a)], rows[:, ::-1], axis=1)[:, ::-1]  # h_i = sum_{j>=i} r_j (1-a)^(j-i)
        rL = a * rev
        rL[:, 0] = rev[:, 0]  # sample 0: lp_0 = x_0, carried as (1-a)^j x_0
        return rows - rL

    def restart(self) -> None:
        """Restart both banks now (after a detected change)."""
        for bank in self._banks:
            bank.restart()
        self.samples = 0

    # ------------------------------------------------------------------ durable state
    def to_dict(self) -> dict[str, Any]:
        """The state as JSON-ready lists (fixed size)."""
        return {
            "kind": "frequency", "n_outputs": self.k, "n_inputs": self.m, "sample_time": self.dt,
            "band": list(self.band), "spacing": self.spacing, "window": self.window, "form": self.form,
            "noise_std": self.noise_std.tolist() if self.noise_known else None, "highpass": self.highpass,
            "samples": self.samples,
            "banks": [{"X_re": b.X.real.tolist(), "X_im": b.X.imag.tolist(), "Y_re": b.Y.real.tolist(),
                       "Y_im": b.Y.imag.tolist(), "count": b.count, "lp": b.lp.tolist()} for b in self._banks],
        }

    @classmethod
    def from_dict(cls, data: Any) -> FrequencyDomainEstimator:
        """Inverse of :meth:`to_dict`; StateError naming the field for anything that does not fit."""
        d = state_mapping(data, "frequency", ("n_outputs", "n_inputs", "sample_time", "band", "spacing", "window",
                                              "form", "noise_std", "highpass", "samples", "banks"))
        if not (isinstance(d["band"], list) and len(d["band"]) == 2):
            raise StateError(f"band: expected [low, high] in Hz, got {short_repr(d['band'])}")
        try:
            est = cls(d["n_outputs"], d["n_inputs"], d["sample_time"], band=tuple(d["band"]), spacing=d["spacing"],
                      window=d["window"], form=d["form"], noise_std=d["noise_std"], highpass=d["highpass"])
        except (OptionError, TypeError) as exc:  # the settings: named by the constructor's message
            raise StateError(str(exc)) from None
        banks = d["banks"]
        if not isinstance(banks, list) or len(banks) != 2:
            raise StateError("banks: expected two stored banks")
        f = est.freqs.size
        for bank, b in zip(est._banks, banks):
            b = state_mapping({"kind": "bank", **b} if isinstance(b, dict) else b, "bank",
                              ("X_re", "X_im", "Y_re", "Y_im", "count", "lp"))
            bank.X = state_array("X_re", b["X_re"], (f, est.p)) + 1j * state_array("X_im", b["X_im"], (f, est.p))
            bank.Y = state_array("Y_re", b["Y_re"], (f, est.k)) + 1j * state_array("Y_im", b["Y_im"], (f, est.k))
            bank.lp = state_array("lp", b["lp"], (est.m + est.k,))
            if isinstance(b["count"], bool) or not isinstance(b["count"], int) or not 0 <= b["count"] <= est.window_samples:
                raise StateError("count: expected an integer within the window")
            bank.count = b["count"]
        est.samples = state_count("samples", d["samples"])
        return est
