"""Isolation and classification of a stage-1 alarm (stage 2 of :mod:`.detection`).

Isolation and classification (stage 2), on an alarm.  For every movable effector and every
kind, the maximum-likelihood fit of the kind's own signature, each at its best onset within
the buffer (the closed-form kinds on every onset at once by reverse cumulative sums, the
others on the onsets of the stage-1 model, of the best jam and of the whole buffer):
``jam``: ``p - u``; ``hardover``: a jam at a stop, or a run to it at the nominal rate limit
(as the simulator's hard-over); ``float``: no moment, the surface where commanded (as the
simulator's float acts); ``effectiveness``: ``(f - 1) u``, the surface where commanded;
``limits``: ``clip(u, lo, hi) - u``; ``rate_limits``: a rate-limited copy of ``u`` from a
free start.  Scores are the log-likelihood ratios less ``(n_params / 2) ln n`` (the Bayesian
information criterion); the confidence is the posterior with equal priors: the effector's
(summed over its kinds) times the share, within it, of the hypotheses that tell an
allocator the same thing as the best (a jam at 59.9 and a hard-over at 60; a float and a jam
at zero).  A :class:`Detection` is emitted when both reach ``min_confidence``; otherwise the
alarm stays pending while data arrive and is dropped unreported after a buffer's length
(ambiguous: no decision).  Two rules name what no data can tell apart: a surface never seen
moving inside fitted reduced limits, and one that moves less than a jam's position is
known to, are jammed.

The fits assume white residuals (the stage-1 test whitens them when the detector is told
the noise's autocorrelation, :mod:`.detection`): they run only after a stage-1 alarm, so
the stage-1 threshold bounds the false-alarm rate whatever they do.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from ..health import FailureEvent, FailureKind

__all__ = ["Detection", "Withdrawal", "Isolation"]

#: rate-limit candidates, fractions of the nominal rate
_RATE_FRACTIONS = np.geomspace(0.02, 0.9, 40)
#: a hard-over's onset before its first sample, in sample periods (a grid: 0.05 of a period
#: is 0.75 deg of ICE's elevon at 150 deg/s and 0.1 s samples, within its noise)
_ONSET_FRACTIONS = np.arange(20) / 20.0


@dataclass(frozen=True)
class Detection:
    """One isolated failure with its evidence.

    ``event`` the :class:`~alloc.health.FailureEvent` (effector name, kind, estimated
    parameters); ``time`` of the decision and ``onset`` (estimated start), in seconds;
    ``statistic`` and ``threshold`` of the stage-1 test (twice the log likelihood ratio,
    chi-square under no failure); ``confidence`` = ``effector_confidence * kind_confidence``;
    ``parameter`` and ``parameter_std`` the estimated jam position or effectiveness fraction
    (the rate of a rate limit, without a std; ``None`` for the kinds with none or several);
    ``samples`` the fit used; ``end_position`` a rate-limited surface's estimated position;
    ``improvement`` the share of the residual sum of squares over those samples that the
    detection explains, in [0, 1] (:func:`.probation.explained_fraction`; ``None`` in states
    stored before it).
    """

    event: FailureEvent
    time: float
    onset: float
    statistic: float
    threshold: float
    confidence: float
    effector_confidence: float
    kind_confidence: float
    parameter: float | None
    parameter_std: float | None
    samples: int
    end_position: float | None = None
    improvement: float | None = None

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        ev = self.event
        d["event"] = {"effector": ev.effector, "kind": ev.kind.value,
                      **{f: getattr(ev, f) for f in ("position", "fraction", "lo", "hi", "rate_min", "rate_max")
                         if getattr(ev, f) is not None}}
        return d


@dataclass(frozen=True)
class Withdrawal:
    """A detection taken back: the effector's health before it is restored.

    ``effector`` and ``kind`` (the failure kind withdrawn, its :class:`~alloc.health.FailureKind`
    value); ``time`` of the withdrawal and ``detection_time`` of the detection withdrawn, in
    seconds; ``statistic`` the evidence for "nothing failed" against the event (twice the log
    likelihood ratio over the data since the event; ``None`` when another component asked,
    :meth:`~.detection.FailureDetector.withdraw`); ``reason`` in words.
    """

    effector: str
    kind: str
    time: float
    detection_time: float
    statistic: float | None
    reason: str

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


@dataclass
class _Fit:
    kind: FailureKind
    llr: float
    n_params: int
    params: dict[str, float]
    parameter: float | None = None
    parameter_std: float | None = None
    samples: int = 0  # the suffix (samples since the onset) it was fitted on
    end_position: float | None = None  # a rate-limited surface's position at the last sample


class Isolation:
    """Stage 2 of :class:`~.detection.FailureDetector` (its base: it reads the detector's
    problem, buffers, known health and settings, and never changes them)."""

    def _onset(self, U: np.ndarray, R: np.ndarray, Q: np.ndarray, tested: np.ndarray) -> int:
        """Samples since the estimated onset: the suffix maximising the stage-1 model's log
        likelihood ratio less ``(d / 2) ln n`` over every tested effector (the GLR change-time
        estimate), from reverse cumulative sums (every suffix at once)."""
        Bw = self._Bn[:, tested]
        c = np.einsum("ij,ij->j", Bw, Bw)
        parts = [(R @ Bw, c)]
        if self.has_position:
            parts.append((Q[:, tested], np.ones(len(tested))))
        Ut = U[:, tested]
        n = np.arange(1, len(U) + 1, dtype=float)[:, None]
        rsum = lambda x: np.cumsum(x[::-1], axis=0)  # noqa: E731 - row i: the sum over the last i + 1 samples
        su, suu = rsum(Ut), rsum(Ut * Ut)
        uuc = suu - su * su / n
        varies = uuc > 1e-12 * np.maximum(suu, 1e-300)
        stat = np.zeros_like(su)
        for S, cj in parts:
            cc = np.where(cj > 0, cj, np.inf)
            ss, ssu = rsum(S), rsum(S * Ut)
            s1c = ssu - ss * su / n
            stat += ss * ss / (n * cc) + np.where(varies, s1c * s1c / (cc * np.where(varies, uuc, 1.0)), 0.0)
        score = 0.5 * stat.max(axis=1) - 0.5 * self.dof * np.log(n[:, 0])
        return int(np.argmax(score)) + 1

    def _weigh(self) -> tuple[list[tuple[int, _Fit]], np.ndarray, int, np.ndarray, int] | None:
        """Every hypothesis's fit on the buffer, its posterior (equal priors, less the BIC
        penalty) and the best's index, with the buffer's times and length; ``None`` when
        nothing can be fitted."""
        tested = self.tested
        n_all = self._count
        U, R, Q, T, K = self._window(n_all)
        n_onset = self._onset(U, R, Q, tested)
        fits: list[tuple[int, _Fit]] = []
        for j in tested:
            fits += [(int(j), f) for f in self._fits(int(j), U[:, j], R, Q[:, j], K[:, j], n_onset)]
        if not fits:
            return None
        scores = np.array([f.llr - 0.5 * f.n_params * math.log(f.samples) for _, f in fits])
        from scipy.special import logsumexp  # here: scipy.special is 0.3 s of the service's start

        ib = int(np.argmax(scores))  # ties: the first listed (the simpler kind, see _fits)
        return fits, np.exp(scores - logsumexp(scores)), ib, T, n_all

    def evidence(self) -> list[tuple[str, str, float]]:
        """``(effector, kind, posterior)`` of every hypothesis the isolation weighs on the data
        now (summed over its fits, largest first): what a pending alarm waits on.  For
        diagnostics; nothing changes.  The isolation weighs them only after a stage-1 alarm."""
        weighed = self._weigh()
        if weighed is None:
            return []
        mass: dict[tuple[str, str], float] = {}
        for (j, f), pw in zip(weighed[0], weighed[1]):
            key = (self.problem.names[j], f.kind.value)
            mass[key] = mass.get(key, 0.0) + float(pw)
        return sorted(((e, k, p) for (e, k), p in mass.items()), key=lambda x: -x[2])

    def _isolate(self, pending: dict[str, Any], gamma: float) -> Detection | None:
        weighed = self._weigh()
        if weighed is None:
            return None
        fits, post, ib, T, n_all = weighed
        jbest, fit = fits[ib]
        # a sum of posteriors: round-off may carry it past 1 (1.0000000000016744 was printed)
        eff_conf = min(1.0, float(sum(pw for (j, _), pw in zip(fits, post) if j == jbest)))
        # the kind's confidence: the posterior of this effector's hypotheses that tell an
        # allocator the same thing as the best (a jam at 59.9 and a hard-over at 60 do)
        same = sum(pw for (j, f), pw in zip(fits, post) if j == jbest and self._same_consequence(jbest, fit, f))
        kind_conf = min(1.0, float(same / max(eff_conf, 1e-300)))
        if 2.0 * fit.llr < gamma or eff_conf < self.min_confidence or kind_conf < self.min_confidence:
            return None
        current = self._current_fit(jbest)
        if current is not None and (current.kind == fit.kind or self._same_consequence(jbest, current, fit)) \
                and fit.kind not in (FailureKind.LIMITS, FailureKind.RATE_LIMITS):
            return None  # nothing new about this effector
        name = self.problem.names[jbest]
        event = FailureEvent(name, fit.kind, **fit.params)
        return Detection(event=event, time=float(T[-1]), onset=float(T[n_all - fit.samples]),
                         statistic=pending["statistic"], threshold=gamma, confidence=eff_conf * kind_conf,
                         effector_confidence=eff_conf, kind_confidence=kind_conf, parameter=fit.parameter,
                         parameter_std=fit.parameter_std, samples=int(fit.samples), end_position=fit.end_position)

    def _current_fit(self, j: int) -> _Fit | None:
        """What is known of effector ``j``, as a fit (``None``: healthy)."""
        h = self.health.get(self.problem.names[j])
        if h is None:
            return None
        if h.floating:
            return _Fit(FailureKind.FLOAT, 0.0, 0, {})
        if h.jam_position is not None:
            return _Fit(FailureKind.JAM, 0.0, 0, {"position": h.jam_position}, h.jam_position, 0.0)
        if h.effectiveness != 1.0 and h.limits is None and h.rate_limits is None:
            return _Fit(FailureKind.EFFECTIVENESS, 0.0, 0, {"fraction": h.effectiveness}, h.effectiveness, 0.0)
        if h.limits is not None:
            return _Fit(FailureKind.LIMITS, 0.0, 0, {"lo": h.limits[0], "hi": h.limits[1]})
        rl = h.rate_limits or (0.0, 0.0)
        return _Fit(FailureKind.RATE_LIMITS, 0.0, 0, {"rate_min": rl[0], "rate_max": rl[1]})

    def _same_consequence(self, j: int, f: _Fit, g: _Fit) -> bool:
        """Whether two fits of effector ``j`` give an allocator the same problem, within three
        standard deviations: both hold the surface with the same moment (a float's is zero,
        as is that of an effectiveness indistinguishable from zero), or both leave it
        movable with the same effectiveness, limits or rate limits."""
        if f.kind == g.kind and f.kind in (FailureKind.LIMITS, FailureKind.RATE_LIMITS):
            return f.params == g.params
        bw = self._Bn[:, j]
        sd = lambda fit: 0.0 if fit.parameter_std is None else fit.parameter_std  # noqa: E731

        def held(fit: _Fit) -> tuple[float, float] | None:  # (held position's moment scale, its std)
            if fit.kind is FailureKind.FLOAT:
                return 0.0, 0.0
            if fit.kind in (FailureKind.JAM, FailureKind.HARDOVER):
                return float(fit.params["position"]), sd(fit)
            if fit.kind is FailureKind.EFFECTIVENESS and fit.parameter is not None and fit.parameter <= 3 * sd(fit):
                return 0.0, 0.0  # no control power left: as good as floating
            return None

        hf, hg = held(f), held(g)
        if hf is not None and hg is not None:
            if FailureKind.FLOAT in (f.kind, g.kind) or FailureKind.EFFECTIVENESS in (f.kind, g.kind):
                other = hg if hf == (0.0, 0.0) else hf  # the moment of the held one must be zero
                return float(np.linalg.norm(bw) * (abs(other[0]) - 3 * other[1])) <= 3.0
            return abs(hf[0] - hg[0]) <= 3 * math.hypot(hf[1], hg[1]) + 1e-12
        if f.kind is FailureKind.EFFECTIVENESS and g.kind is FailureKind.EFFECTIVENESS:
            return abs(f.parameter - g.parameter) <= 3 * math.hypot(sd(f), sd(g))
        return False

    def _fits(self, j: int, u: np.ndarray, R: np.ndarray, q: np.ndarray, known: np.ndarray,
              n_onset: int) -> list[_Fit]:
        """Maximum-likelihood fit of every kind's signature for effector ``j``.

        The closed-form kinds (float, hard-over, jam, effectiveness) are fitted on every
        suffix (onset) at once from reverse cumulative sums, each at its best onset; limits and
        rate limits on the onsets of the stage-1 model and of the best jam and the whole
        buffer.  Listed simplest first (ties go to the first).
        """
        p = self.problem
        bw = self._Bn[:, j]
        c = float(bw @ bw)
        N = len(u)
        if c <= 0 and not self.has_position:
            return []
        # deviations from the command (position units): the residual is against the current
        # model, so its known part (a held position, a scaled moment) is added back
        f0 = float(self._f_known[j])
        dm0, dp0 = f0 * known - u, known - u  # the current model's own deviations
        a = (R @ bw) / c + dm0 if c > 0 else np.zeros(N)  # moment-based estimate, variance 1 / c
        wq = 1.0 / float(self.position_std[j]) ** 2 if self.has_position else 0.0
        qd = q * float(self.position_std[j]) + dp0 if self.has_position else np.zeros(N)
        # every fit is scored against the current model: its own likelihood ratio over healthy
        # is subtracted, suffix by suffix (zero for a healthy effector)
        base = c * (a * dm0 - 0.5 * dm0 * dm0) + wq * (qd * dp0 - 0.5 * dp0 * dp0)
        wc = c + wq
        a_comb = (c * a + wq * qd) / wc  # combined deviation estimate, variance 1 / wc
        lo0, hi0 = float(p.umin[j]), float(p.umax[j])
        rsum = lambda x: np.cumsum(x[::-1])  # noqa: E731 - entry i: the last i + 1 samples
        n = np.arange(1, N + 1, dtype=float)
        A, AU, U1, U2, AP = rsum(a_comb), rsum(a_comb * u), rsum(u), rsum(u * u), rsum(a * u)
        BASE = rsum(base)
        logn = np.log(n)

        def held_llr(P: np.ndarray) -> np.ndarray:  # the surface at P: sum wc (a d - d^2 / 2), d = P - u
            return wc * (P * A - AU - 0.5 * (n * P * P - 2 * P * U1 + U2)) - BASE

        def best(llr: np.ndarray, k: int) -> int:
            return int(np.argmax(llr - 0.5 * k * logn))

        fits = []
        if c > 0:  # float: no moment (theta = -1 on u), the surface where commanded
            llr = c * (-AP - 0.5 * U2) - BASE
            i = best(llr, 0)
            fits.append(_Fit(FailureKind.FLOAT, float(llr[i]), 0, {}, samples=i + 1))
        llr_lo, llr_hi = held_llr(np.full(N, lo0)), held_llr(np.full(N, hi0))
        i_lo, i_hi = best(llr_lo, 0), best(llr_hi, 0)
        stop, i, llr = (lo0, i_lo, llr_lo) if llr_lo[i_lo] >= llr_hi[i_hi] else (hi0, i_hi, llr_hi)
        fits.append(_Fit(FailureKind.HARDOVER, float(llr[i]), 0, {"position": stop}, stop, 0.0, samples=i + 1))
        P = np.clip((A + U1) / n, lo0, hi0)
        llr = held_llr(P)
        i_jam = best(llr, 1)
        fits.append(_Fit(FailureKind.JAM, float(llr[i_jam]), 1, {"position": float(P[i_jam])}, float(P[i_jam]),
                         1.0 / math.sqrt((i_jam + 1) * wc), samples=i_jam + 1))
        if c > 0:
            ok = U2 > 0
            theta = np.where(ok, AP / np.where(ok, U2, 1.0), 0.0)
            f = np.clip(1.0 + theta, 0.0, 1.0)
            th = f - 1.0
            llr = np.where(ok, c * (th * AP - 0.5 * th * th * U2) - BASE, -np.inf)
            i = best(llr, 1)
            if np.isfinite(llr[i]):  # c U2 may underflow to 0 (u ~ 1e-160): numpy's inf, not ZeroDivisionError
                fits.append(_Fit(FailureKind.EFFECTIVENESS, float(llr[i]), 1, {"fraction": float(f[i])}, float(f[i]),
                                 float(1.0 / np.sqrt(c * U2[i])), samples=i + 1))
        fits += self._runs_to_stop(j, u, a_comb, wc, lo0, hi0, base)
        for length in sorted({n_onset, i_jam + 1, N}):
            fits += self._range_fits(j, u[N - length:], a_comb[N - length:], wc, lo0, hi0,
                                     float(base[N - length:].sum()))
        return fits

    def _runs_to_stop(self, j: int, u: np.ndarray, a_comb: np.ndarray, wc: float, lo0: float, hi0: float,
                      base: np.ndarray) -> list[_Fit]:
        """A hard-over as the simulator's: from where it was commanded at the onset, the surface
        runs to a stop at its nominal rate limit and stays; every onset at once (an ``N x N``
        table of suffix by sample).

        The onset need not fall on a sample: a run that began a fraction ``phi`` of a sample
        period before sample ``s`` has moved ``phi rate dt`` there.  With onsets on samples only,
        ICE's elevon (15 deg a 0.1 s sample) failing 0.02 s before a sample fitted worse than a
        jam at the position it passed through, which was reported on one sample.  ``phi`` is a
        free parameter (counted in the score) unless it is zero."""
        p = self.problem
        N = len(u)
        fits = []
        start = np.arange(N)  # the onset sample of each suffix (suffix length N - start)
        t = np.arange(N)
        after = t[None, :] - start[:, None]  # samples since the onset, negative before it
        inside = after >= 0
        length = (N - start).astype(float)
        moved = np.maximum(after, 0)  # whole sample periods since the onset sample
        for stop, rate in ((hi0, float(p.rate_max[j])), (lo0, float(-p.rate_min[j]))):
            if not (math.isfinite(rate) and rate > 0) or N < 2:
                continue
            u0 = u[start][:, None]
            step = np.sign(stop - u0) * rate * self.dt  # one sample period of the run
            lo_run, hi_run = np.minimum(stop, u0), np.maximum(stop, u0)
            best: tuple[float, float, int, int] | None = None  # (score, llr, onset row, n_params)
            for phi in _ONSET_FRACTIONS:
                pos = np.clip(u0 + step * (moved + phi), lo_run, hi_run)
                d = np.where(inside, pos - u[None, :], 0.0)
                llr = (wc * (a_comb[None, :] * d - 0.5 * d * d)).sum(axis=1) - np.cumsum(base[::-1])[::-1]
                k = int(phi > 0)
                score = llr - 0.5 * k * np.log(length)
                i = int(np.argmax(score))
                if best is None or score[i] > best[0]:
                    best = (float(score[i]), float(llr[i]), i, k)
            assert best is not None
            _, llr_i, i, k = best
            fits.append(_Fit(FailureKind.HARDOVER, llr_i, k, {"position": stop}, stop, 0.0, samples=N - i))
        return fits

    def _range_fits(self, j: int, u: np.ndarray, a_comb: np.ndarray, wc: float, lo0: float,
                    hi0: float, base: float) -> list[_Fit]:
        """Reduced limits and reduced rate limits on one suffix."""
        n = len(u)
        fits = []
        # reduced limits: the two sides separate (a sample beyond one side never touches the other)
        cand = np.unique(np.clip(np.concatenate([u, a_comb + u]), lo0, hi0))
        D_hi = np.minimum(0.0, cand[:, None] - u[None, :])
        D_lo = np.maximum(0.0, cand[:, None] - u[None, :])
        llr_hi = (wc * (a_comb * D_hi - 0.5 * D_hi ** 2)).sum(axis=1)
        llr_lo = (wc * (a_comb * D_lo - 0.5 * D_lo ** 2)).sum(axis=1)
        ih = int(np.argmax(llr_hi))
        use_hi = bool(llr_hi[ih] > 0)
        hi_c = float(cand[ih]) if use_hi else hi0
        llr_lo = np.where(cand < hi_c, llr_lo, -np.inf)  # the pair must stay ordered
        il = int(np.argmax(llr_lo))
        use_lo = bool(llr_lo[il] > 0)
        lo_c = float(cand[il]) if use_lo else lo0
        # a surface never seen moving inside the fitted limits is a jam (nothing tells them apart)
        margin = 3.0 / math.sqrt(n * wc)
        moving_inside = int(((u > lo_c + margin) & (u < hi_c - margin)).sum())
        if lo_c < hi_c and (use_hi or use_lo) and moving_inside >= 3:
            llr = float(max(llr_hi[ih], 0.0) + max(llr_lo[il], 0.0)) - base
            fits.append(_Fit(FailureKind.LIMITS, llr, int(use_hi) + int(use_lo), {"lo": lo_c, "hi": hi_c},
                             samples=n))
        p = self.problem
        rate = float(min(-p.rate_min[j], p.rate_max[j]))
        if math.isfinite(rate) and rate > 0 and n > 1:
            # the surface's position at the suffix's start is unknown when the onset lies before
            # the buffer: a grid of starts (the commanded one, and nine across the range)
            starts = np.concatenate([[u[0]], np.linspace(lo0, hi0, 9)])
            rates = np.repeat(rate * _RATE_FRACTIONS, len(starts))
            delta = np.tile(starts, len(_RATE_FRACTIONS))
            D = np.zeros((len(rates), n))
            D[:, 0] = delta - u[0]
            for t in range(1, n):
                delta = delta + np.clip(u[t] - delta, -rates * self.dt, rates * self.dt)
                D[:, t] = delta - u[t]
            llr_r = (wc * (a_comb * D - 0.5 * D ** 2)).sum(axis=1) - base
            # a surface that moves less over the suffix than a jam's position is known to is a jam
            llr_r[rates * (n - 1) * self.dt < 3.0 / math.sqrt(n * wc)] = -np.inf
            free_start = np.tile(np.arange(len(starts)) > 0, len(_RATE_FRACTIONS))
            ir = int(np.argmax(llr_r - 0.5 * free_start * math.log(n)))
            if np.isfinite(llr_r[ir]):
                fits.append(_Fit(FailureKind.RATE_LIMITS, float(llr_r[ir]), 1 + int(free_start[ir]),
                                 {"rate_min": -float(rates[ir]), "rate_max": float(rates[ir])}, float(rates[ir]),
                                 samples=n, end_position=float(D[ir, -1] + u[-1])))
        return fits
