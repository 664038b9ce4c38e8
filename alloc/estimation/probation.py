"""Do no harm, in the detector: each detection on probation, withdrawn when the data favour
"nothing failed" decisively; and how much of the residual a detection explains.

Probation.  After a detection is applied, for ``probation`` seconds (a setting of
:class:`~.detection.FailureDetector`, 2 s by default, 0: none) the detector weighs every sample's
residuals under its belief against their values under the effector's health before the
detection (the first of a chain of refinements: what :meth:`~.detection.FailureDetector.withdraw`
restores), the Gaussian log likelihood ratio of :func:`.harm.evidence_log_ratio` accumulated
sample by sample:

    Lambda_n = kappa sum_t 0.5 (|r_before,t|^2 - |r_belief,t|^2)     (+ the same of q with sensors)

The residuals are whitened as the detector whitens them (by the stated noise; for the robust
detector, the learnt model's innovation over its predictive standard deviation ``s``).  A health
acts on effector ``j`` through its position ``p`` and effectiveness ``f`` (0 floating), so
the stated-whitened residual under the health before is ``r_belief + b_j (f_belief p_belief -
f_before p_before)`` with ``b_j = B_j / sigma``; the robust detector's is its learner's innovation
of that, with the regressor and the predictive std of the position before (and the Gaussian's
``ln s`` term, since the two stds differ); and ``q_before = q_belief + (p_belief - p_before) /
sigma_p``.  ``kappa = 1 / (1 + 2 sum_l rho_l)`` (at most 1; ``rho`` the stated or the
learnt autocorrelation) scales correlated samples to the independent ones they are worth, the
effective sample size of :func:`.harm.effective_samples`: an approximation of the exact
generalised-least-squares ratio that keeps each sample's cost ``O(k)``.

The belief's parameter is not known exactly: a jam's position or an effectiveness fraction is
the isolation's estimate, with its standard deviation.  Judged as exact, an estimate two of its
stds off loses to "nothing failed" on the first sample where the command happens to sit near
the true jam (both then predict about the same response, and the belief's small offset costs
more): a service stream withdrew a real jam one sample after its detection (estimate 3.13, std
0.04) and re-detected it at 3.03.  So the belief is the mixture over its parameter, a normal
prior at the estimate with its std, updated sample by sample as a scalar Kalman filter: each
residual is judged by its predictive law ``N(c m, I + v c c')`` (``c`` the residual's change
per unit of the parameter, ``m`` and ``v`` the posterior offset and variance), a rank-one
update of cost ``O(k)``.  The ratio of that marginal likelihood to the health before's is again
a martingale under the belief (a Bayes factor), so the bound below holds for the mixture.  For
the robust detector ``c`` is divided by the predictive std (the learner's regressor also moves
with the position: neglected, a first-order approximation).  Kinds without a parameter std
(float, limits, rate limits) keep the point belief.

The detection is withdrawn (reason :data:`REASON`, statistic ``-2 Lambda``) as soon as
``Lambda <= -ln 100`` -- Jeffreys' "decisive" Bayes factor for the health before -- while the
health before fits its residuals (their whitened sum of squares, times ``kappa``, within
``chi2.isf(0.01, kappa n)`` for ``n`` numbers: a ratio between two misfits favours neither, as
in :func:`.harm.judge`), and stands when its probation ends without that.  Without the fit, a
reduced limit's estimate with a spurious bound was withdrawn for the healthy model, which fits
worse still: the seeded limits worlds of tests/alloc/estimation/test_detection.py ended with the
limit known in 13 of 24, against 17 or more without probation.  If the belief is the plant (the model and noise as
stated), ``1 / exp(Lambda)`` is a non-negative martingale of mean 1, so by Ville's inequality the
chance that it ever reaches 100 -- a real failure withdrawn, at any of the looks -- is at most
1/100 with no correction for looking every sample (exact for white noise and the stated model;
``kappa`` and the learnt law make it an approximation otherwise).  A surface commanded still gives no evidence
either way (its belief and its health before predict the same response): nothing is withdrawn.
Free parameters: the probation (2 s, :class:`.harm.HarmDesign`'s reasoning: two time constants of
the loop's slowest channel), ln 100 and the fit level 0.01 (:class:`.harm.HarmDesign`'s ``level``).

Improvement.  :func:`explained_fraction` is ``1 - SS_belief / SS_before`` over the samples the
detection was fitted on: the share of the residual sum of squares (whitened, positions included)
under the model before the detection that the detection explains, clipped to [0, 1].  A
hard-over's run to its stop is scored as the jam it becomes, so its fraction is a lower bound.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..effector_health import EffectorHealth
from ..health import FailureEvent, FailureKind, apply_event
from ..problem import MAX_MAGNITUDE, as_real
from ._checks import StateError, state_count
from .robust import PRIOR_SAMPLES

__all__ = ["DECISIVE_LOG", "REASON", "position_under", "start", "step", "explained_fraction",
           "probations_to_dict", "probations_from_dict"]

#: ln 100: Jeffreys' decisive Bayes factor (Theory of Probability, 1961, appendix B)
DECISIVE_LOG = math.log(100.0)
REASON = "evidence favours the health before the detection"
_KEYS = {"time", "end", "llr", "samples", "rate", "ss_before", "values"}
#: the belief's parameter (posterior offset, variance, and what it is: "position", "effectiveness"
#: or "" for none); a state stored before them has a point belief
_PARAMETER_KEYS = {"offset", "variance", "wrt"}
_WRT = {"jam": "position", "hardover": "position", "effectiveness": "effectiveness"}
#: the chi-square level at which the health before must fit its residuals to be favoured
#: (harm.HarmDesign.level: 0.01)
FIT_LEVEL = 0.01


def position_under(h: EffectorHealth | None, u: float, prev: float, dt: float) -> tuple[float, float]:
    """``(position, effectiveness)`` of an effector commanded to ``u`` under its health entry
    ``h`` (``None``: healthy); ``prev`` its previous position (rate limits)."""
    if h is None:
        return u, 1.0
    if h.jam_position is not None:
        p = h.jam_position
    else:
        p = u if h.limits is None else min(max(u, h.limits[0]), h.limits[1])
        if h.rate_limits is not None:
            p = prev + min(max(p - prev, h.rate_limits[0] * dt), h.rate_limits[1] * dt)
    return p, 0.0 if h.floating else h.effectiveness


def start(det: Any, name: str, time: float, detection: Any = None) -> None:
    """Put the detection just applied on ``name`` (at ``time``) on probation (none when 0 s); a
    refinement's probation replaces its chain's, against the same health before the chain.
    ``detection``'s parameter std, where its kind has one, is the belief's prior spread."""
    det._probations.pop(name, None)
    if det.probation > 0:
        j = det.problem.index(name)
        wrt, variance = "", 0.0
        std = None if detection is None else detection.parameter_std
        if std is not None and math.isfinite(std) and std > 0:
            wrt = _WRT.get(str(detection.event.kind), "")
            variance = min(float(std) ** 2, MAX_MAGNITUDE) if wrt else 0.0
        det._probations[name] = {"time": float(time), "end": float(time) + det.probation, "llr": 0.0,
                                 "samples": 0, "rate": float(det._rate_state[j]), "ss_before": 0.0, "values": 0,
                                 "offset": 0.0, "variance": variance, "wrt": wrt}


def _sensitivity(det: Any, rec: dict[str, Any], j: int, p_n: float, f_n: float,
                 s_pred: np.ndarray | None) -> tuple[np.ndarray, float] | None:
    """``(c_r, c_q)``: how the belief's whitened residuals ``r`` and ``q_j`` fall per unit of its
    parameter (``None`` for a point belief)."""
    wrt = rec.get("wrt", "")
    if not wrt or not rec.get("variance", 0.0) > 0:
        return None
    c_r = det._Bn0[:, j] * (f_n if wrt == "position" else p_n)
    if s_pred is not None:
        c_r = c_r / s_pred
    c_q = 1.0 / det.position_std[j] if det.has_position and wrt == "position" else 0.0
    return c_r, float(c_q)


def _kappa(det: Any) -> float:
    """The evidence one correlated sample is worth, in independent samples (at most 1)."""
    if det._learner is not None:
        lr = det._learner
        rho = (PRIOR_SAMPLES * lr.stated_rho + lr.sum_cl) / max(PRIOR_SAMPLES + lr.sum_c0, 1e-300)  # as lr.correlation
    elif det.noise_correlation is not None:
        rho = det.noise_correlation[: det.N - 1]
    else:
        return 1.0
    return 1.0 / max(1.0, 1.0 + 2.0 * float(np.sum(rho)))


def step(det: Any, t: float, u: np.ndarray, known: np.ndarray, r: np.ndarray, q: np.ndarray,
         r0: np.ndarray | None = None, s_pred: np.ndarray | None = None) -> list[tuple[str, float]]:
    """One sample's evidence (taken at ``t`` with commands ``u``, known positions ``known`` and
    residuals ``r``, ``q`` under the belief; for the robust detector, before its learner takes
    the sample, ``r0`` the stated-whitened residual and ``s_pred`` the predictive standard
    deviations that made ``r``) for every detection on probation; returns the ``(effector,
    statistic)`` to withdraw.  Probations that end are closed."""
    out: list[tuple[str, float]] = []
    if not det._probations:
        return out
    kappa = _kappa(det)
    for name in list(det._probations):
        rec = det._probations[name]
        if not t > rec["time"]:  # the detection was decided on this sample: evidence starts after it
            continue
        j = det.problem.index(name)
        before = det._active.get(name, {}).get("before")
        p_b, f_b = position_under(before, float(u[j]), rec["rate"], det.dt)
        p_n, f_n = float(known[j]), float(det._f_known[j])
        with np.errstate(over="ignore", invalid="ignore"):
            # the stated-whitened residual under the health before: the column on the effective
            # positions; the robust detector's innovation of it, as its learner whitens it (the
            # regressor and the predictive std change with the position), with the Gaussian's
            # normalising term, since the two hypotheses' stds differ
            delta = det._Bn0[:, j] * (f_n * p_n - f_b * p_b)
            if s_pred is None:
                r_b = r + delta
                log_s = 0.0
            else:
                known_b = known.copy()
                known_b[j] = p_b
                r_b, s_b = det._learner.residual(r0 + delta, det._learner.regressor(known_b))
                log_s = 2.0 * float(np.sum(np.log(s_b / s_pred)))
            ss_b = float(r_b @ r_b)
            gain = ss_b + log_s
            if det.has_position:
                q_b = q[j] + (p_n - p_b) / det.position_std[j]
                gain += float(q_b * q_b)
                ss_b += float(q_b * q_b)
            offset, variance = rec.get("offset", 0.0), rec.get("variance", 0.0)
            sens = _sensitivity(det, rec, j, p_n, f_n, s_pred)
            if sens is None:
                gain -= float(r @ r) + (float(q[j] * q[j]) if det.has_position else 0.0)
            else:  # the predictive law of the mixture over the parameter (module docstring)
                c_r, c_q = sens
                r_m = r - c_r * offset
                q_m = float(q[j]) - c_q * offset if det.has_position else 0.0
                cc = float(c_r @ c_r) + c_q * c_q
                cr = float(c_r @ r_m) + c_q * q_m
                spread = 1.0 + variance * cc
                gain -= float(r_m @ r_m) + q_m * q_m - variance * cr * cr / spread + math.log(spread)
                offset += variance * cr / spread
                variance /= spread
            llr = rec["llr"] + 0.5 * kappa * gain
            ss_before = rec["ss_before"] + kappa * ss_b
        # held in the stored domain (|x| <= 1e50, as every number of a state): far past ln 100 already
        bounded = float(min(max(llr, -MAX_MAGNITUDE), MAX_MAGNITUDE)) if not math.isnan(llr) else rec["llr"]
        if not (math.isfinite(offset) and math.isfinite(variance)):  # beyond the domain: a point belief
            offset, variance = rec.get("offset", 0.0), 0.0
        rec = {**rec, "llr": bounded, "offset": float(min(max(offset, -MAX_MAGNITUDE), MAX_MAGNITUDE)),
               "variance": float(min(variance, MAX_MAGNITUDE)),
               "samples": rec["samples"] + 1, "rate": p_b,
               "ss_before": float(min(ss_before, MAX_MAGNITUDE)) if not math.isnan(ss_before) else rec["ss_before"],
               "values": rec["values"] + len(r) + int(det.has_position)}
        favoured = rec["llr"] <= -DECISIVE_LOG and _fits(rec["ss_before"], rec["values"] * kappa)
        if favoured:
            out.append((name, min(-2.0 * rec["llr"], MAX_MAGNITUDE)))
        if favoured or t >= rec["end"]:
            del det._probations[name]
        else:
            det._probations[name] = rec
    return out


def _fits(sum_of_squares: float, values: float) -> bool:
    """Whether residuals with this whitened sum of squares over ``values`` numbers are noise
    (chi-square at :data:`FIT_LEVEL`): only a health that explains the data can be favoured."""
    from scipy.stats import chi2  # here: scipy.stats costs a second at import, and only a decision needs it

    return bool(sum_of_squares <= chi2.isf(FIT_LEVEL, max(1.0, values)))


def explained_fraction(det: Any, detection: Any) -> float:
    """``1 - SS_belief / SS_before`` over the ``detection.samples`` it was fitted on (module
    docstring), from the detector's buffers before the detection is applied."""
    n = int(detection.samples)
    U, R, Q, _, K = det._window(det._count)
    U, R, Q, K = U[-n:], R[-n:], Q[-n:], K[-n:]
    ev: FailureEvent = detection.event
    j = det.problem.index(ev.effector)
    name = det.problem.names[j]
    _, health = apply_event(det.problem, det.health, FailureEvent(name, FailureKind.REPAIR))
    _, health = apply_event(det.problem, health, ev)
    h = health.get(name)
    lo, hi = float(det.problem.umin[j]), float(det.problem.umax[j])
    # a rate-limited surface's start is one of the isolation's grid (where commanded, or nine
    # across the range): the one whose run ends where the fit says it did
    starts = [float(U[0, j])] + (list(np.linspace(lo, hi, 9)) if detection.end_position is not None else [])
    best = None
    for first in starts:
        p_new, f_new = _run(h, U[:, j], first, det.dt)
        miss = 0.0 if detection.end_position is None else abs(p_new[-1] - detection.end_position)
        if best is None or miss < best[0]:
            best = (miss, p_new, f_new)
    _, p_new, f_new = best
    with np.errstate(over="ignore", invalid="ignore"):
        d_cur = det._f_known[j] * K[:, j]
        R_new = R - np.outer(f_new * p_new - d_cur, det._Bn[:, j])
        ss_before, ss_new = float(np.sum(R * R)), float(np.sum(R_new * R_new))
        if det.has_position:
            Q_new = Q[:, j] - (p_new - K[:, j]) / det.position_std[j]
            ss_before += float(np.sum(Q * Q))
            ss_new += float(np.sum(Q * Q) - np.sum(Q[:, j] ** 2) + np.sum(Q_new * Q_new))
        fraction = 1.0 - ss_new / ss_before if ss_before > 0 else 0.0
    return float(min(1.0, max(0.0, fraction))) if math.isfinite(fraction) else 0.0


def _run(h: EffectorHealth | None, u: np.ndarray, first: float, dt: float) -> tuple[np.ndarray, float]:
    """Positions under ``h`` for the commands ``u``, a rate-limited one starting at ``first``."""
    out = np.empty(len(u))
    prev, f = first, 1.0
    for i in range(len(u)):
        out[i], f = position_under(h, float(u[i]), first if i == 0 else prev, dt)
        if i == 0 and h is not None and h.rate_limits is not None and h.jam_position is None:
            out[0] = first  # the fit's start is the first sample's position
        prev = out[i]
    return out, f


def probations_to_dict(probations: dict[str, dict[str, Any]]) -> dict[str, dict[str, Any]]:
    return {name: dict(rec) for name, rec in probations.items()}


def probations_from_dict(d: Any, det: Any) -> dict[str, dict[str, Any]]:
    """The probations of a stored state (``probations``), each on a standing detection; StateError
    naming the field."""
    if not isinstance(d, dict):
        raise StateError("probations: expected a mapping of effector name to its probation")
    out = {}
    for name, rec in d.items():
        if name not in det._active:
            raise StateError(f"probations: {name!r} has no standing detection (active)")
        if not isinstance(rec, dict) or set(rec) not in (_KEYS, _KEYS | _PARAMETER_KEYS):
            raise StateError(f"probations: expected mappings with {sorted(_KEYS | _PARAMETER_KEYS)}")
        out[name] = {"time": as_real("probations.time", rec["time"], StateError),
                     "end": as_real("probations.end", rec["end"], StateError),
                     "llr": as_real("probations.llr", rec["llr"], StateError),
                     "samples": state_count("probations.samples", rec["samples"]),
                     "rate": as_real("probations.rate", rec["rate"], StateError),
                     "ss_before": as_real("probations.ss_before", rec["ss_before"], StateError),
                     "values": state_count("probations.values", rec["values"])}
        wrt = rec.get("wrt", "")
        if wrt not in ("", "position", "effectiveness"):
            raise StateError(f"probations.wrt: {wrt!r} is not '', 'position' or 'effectiveness'")
        out[name].update({"offset": as_real("probations.offset", rec.get("offset", 0.0), StateError),
                          "variance": as_real("probations.variance", rec.get("variance", 0.0), StateError),
                          "wrt": wrt})
        if not out[name]["variance"] >= 0:
            raise StateError(f"probations.variance: {out[name]['variance']!r} is negative")
        if not out[name]["ss_before"] >= 0:
            raise StateError(f"probations.ss_before: {out[name]['ss_before']!r} is negative")
        if not out[name]["end"] >= out[name]["time"]:
            raise StateError(f"probations.end: {out[name]['end']!r} before its detection's time")
    return out
