"""Do no harm in the loop (``--health detected``): hold stuck beliefs, judge each detection.

The engine's detection handling in one place (:func:`sim.engine.simulate` calls it):

* the allocator's belief is the detector's (:attr:`FailureDetector.health`), delivered after the
  processing delay, and the command to an effector believed stuck (jammed, hard-over,
  floating) is held at its last command before the belief (:func:`sim.allocation.hold_commands`);
* every applied detection is on probation for :attr:`HarmDesign.probation` seconds; at its end
  :func:`alloc.estimation.harm.judge` compares the loop's tracking since with a window before
  the detection's onset, and the response residuals under the belief with and without it.  A
  detection that made the tracking significantly worse, with evidence that is not decisive, is
  withdrawn: the detector is told (:meth:`FailureDetector.withdraw`, which restores the
  effector's health before it), and the allocator gets the detector's belief after the same
  processing delay as a detection;
* the detector's own withdrawals (:meth:`FailureDetector.pop_withdrawals`, each sample) are
  applied the same way.

Each withdrawal is recorded for the run's JSON (``withdrawals``): effector, kind, time (of the
withdrawal), detection_time, applied_time (when the allocator got it back), reason, by
(``monitor`` or ``detector``) and the statistics.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from alloc.effector_health import EffectorHealth
from alloc.estimation.harm import DEFAULT_HARM, HarmDesign, belief_fits, evidence_log_ratio, judge, looks, whitener
from sim.allocation import stuck_effectors
from sim.detection import InLoopDetector
from sim.model import PlantModel

__all__ = ["InLoopHarm", "DESIGN"]

#: the rule flown by :func:`sim.engine.simulate` (the library's default design)
DESIGN = DEFAULT_HARM


@dataclass
class _Probation:
    effector: str
    kind: str
    detection_time: float
    onset: float
    applied_time: float | None = None  # set when the allocator gets it
    before: EffectorHealth | None = None  # the effector's health the withdrawal would restore
    record: dict[str, Any] = field(default_factory=dict)


class InLoopHarm:
    """Beliefs, holds and probations of one detected run (see the module docstring).

    Parameters
    ----------
    vehicle : PlantModel
    detector : InLoopDetector
    design : HarmDesign
    """

    def __init__(self, vehicle: PlantModel, detector: InLoopDetector, design: HarmDesign | None = None) -> None:
        design = DESIGN if design is None else design
        self.vehicle = vehicle
        self.detector = detector
        self.design = design
        self.belief: dict[str, EffectorHealth] = {}
        self.held: dict[int, float] = {}
        self.withdrawals: list[dict[str, Any]] = []
        self._probations: list[_Probation] = []
        self._quiet_until = -np.inf  # end of the quarantine after the monitor's last withdrawal
        self._popped_own: set[tuple[str, float]] = set()
        self._cleared: set[str] = set()  # effectors whose standing belief passed its probation
        #: whether a probation passed since the last :meth:`apply` (its hold is to be released)
        self.released = False
        self._standing: dict[str, EffectorHealth | None] = {}  # effector -> its health before its detections
        n = int(round((design.before + design.probation) / detector.sample_time)) + 64
        self._cap = n
        self._t: list[float] = []
        self._e: list[np.ndarray] = []
        self._y: list[np.ndarray] = []
        self._u: list[np.ndarray] = []
        self._B = np.asarray(detector.detector.problem.B, dtype=float)
        self._std = np.asarray(detector.detector.noise_std, dtype=float)
        self._rho = detector.detector.noise_correlation

    # ------------------------------------------------------------------ samples
    def observe(self, t: float, tracking_error: np.ndarray, y: np.ndarray, u: np.ndarray) -> None:
        """Record one detector sample: the tracking error ``r - z`` and the detector's ``y`` and ``u``."""
        self._t.append(t)
        self._e.append(np.array(tracking_error, dtype=float))
        self._y.append(np.array(y, dtype=float))
        self._u.append(np.array(u, dtype=float))
        if len(self._t) > self._cap:
            del self._t[0], self._e[0], self._y[0], self._u[0]

    # ------------------------------------------------------------------ detections
    def detected(self, record: dict[str, Any]) -> bool:
        """A detection decided now (its JSON record); its probation starts when it is applied.

        Within the quarantine after a withdrawal by the monitor (:attr:`HarmDesign.quarantine`
        seconds) it is withdrawn on the detector at once and never applied (returns False): the
        loop has just shown that the detector's hypotheses made it worse, and a detection that
        follows is most often the same misfit seen again (the detector restarts on a
        withdrawal); a real failure is found again once the quarantine is over.
        """
        name = record["effector"]
        reason = None
        if not self.design.active:
            return True
        if record["time"] < self._quiet_until - 1e-9:
            reason = (f"quarantine: decided {record['time']:.3g} s, within {self.design.quarantine:g} s of the "
                      "monitor's last withdrawal; never applied")
        elif self.design.fit_gate:
            ss, n = self._fit_since(record.get("onset", record["time"]), record["time"])
            if n and not belief_fits(ss, n, self.design):
                reason = (f"does not fit: the belief with it leaves whitened residuals of sum of squares {ss:.4g} "
                          f"over {n} values since its onset (noise: at most chi2.isf({self.design.level:g}, {n})); "
                          "never applied")
        if reason is not None:
            by = "quarantine" if reason.startswith("quarantine") else "fit"
            w = self._withdraw(name, record["time"], reason)
            if w is None:  # the detector took it back on its own evidence in the same sample
                record["probation"] = {"verdict": "withdrawn", "reason": "withdrawn by the detector first",
                                       "time": record["time"], "statistics": None}
                return False
            record["probation"] = {"verdict": "withdrawn", "reason": reason, "time": record["time"], "statistics": None}
            self.withdrawals.append({"effector": name, "kind": w.kind, "time": w.time, "detection_time": w.detection_time,
                                     "detected_applied_time": None, "applied_time": None, "by": by,
                                     "reason": reason, "statistics": None})
            self._popped_own.add((name, w.time))
            return False
        if name not in self._standing:
            self._standing[name] = self.detector.health_before(name)
        onset = record.get("onset", record["time"])
        # the tracking it is judged against is the loop's before the first detection still on
        # probation: a detection that follows a harmful one is not judged against the harm
        anchor = min([onset, *(p.onset for p in self._probations)])
        self._cleared.discard(name)
        # a refinement on the same effector supersedes the earlier one's probation
        self._probations = [p for p in self._probations if p.effector != name]
        self._probations.append(_Probation(name, record["kind"], record["time"], anchor,
                                           before=self._standing[name], record=record))
        return True

    def apply(self, belief: dict[str, EffectorHealth], u_last: np.ndarray, time: float) -> None:
        """The allocator gets ``belief`` now: new stuck effectors are held at ``u_last`` (the last
        command sent), those no longer believed stuck are released; waiting probations start."""
        names = self.vehicle.effector_names
        stuck = {j for j in stuck_effectors(self.vehicle, belief)
                 if names[j] not in self._cleared and self.design.active}
        self.held = {j: (self.held[j] if j in self.held else float(u_last[j])) for j in sorted(stuck)}
        self.belief = dict(belief)
        self.released = False
        for p in self._probations:
            if p.applied_time is None and belief.get(p.effector) is not None:
                p.applied_time = time

    def _withdraw(self, effector: str, t: float, reason: str):
        """The detector's withdrawal of ``effector``'s standing detection, or None when none stands
        any more (the detector withdrew or replaced it on its own evidence first)."""
        from alloc.estimation import SampleError

        try:
            return self.detector.detector.withdraw(effector, t, reason)
        except SampleError as exc:
            if "stands to withdraw" not in str(exc):
                raise
            return None

    def verdicts(self, t: float) -> list[dict[str, Any]]:
        """Judge the probations that end by ``t``; withdraw on the detector those the rule rejects.

        Returns the withdrawals made (records), and the detector's own (popped), in order.
        """
        out: list[dict[str, Any]] = []
        keep: list[_Probation] = []
        if not self.design.active:
            self._probations = []
        for p in self._probations:
            if p.applied_time is None or t < p.applied_time + (self.design.min_after - 0.5) * self.detector.sample_time:
                keep.append(p)
                continue
            verdict = self._judge(p, t)
            ended = t >= p.applied_time + self.design.probation - 1e-9
            if not verdict.withdraw and not ended:
                keep.append(p)
                continue
            p.record["probation"] = {"verdict": "withdrawn" if verdict.withdraw else "kept", "reason": verdict.reason,
                                     "time": t, "statistics": verdict.statistics()}
            if not verdict.withdraw:
                self._cleared.add(p.effector)
                self.released = True
            if verdict.withdraw:
                if self._withdraw(p.effector, t, verdict.reason) is not None:
                    self._popped_own.add((p.effector, t))
                self._quiet_until = t + self.design.quarantine
                self._standing.pop(p.effector, None)
                out.append({"effector": p.effector, "kind": p.kind, "time": t, "detection_time": p.detection_time,
                            "detected_applied_time": p.applied_time, "applied_time": None, "by": "monitor",
                            "reason": verdict.reason, "statistics": verdict.statistics()})
        self._probations = keep
        for w in self.detector.detector.pop_withdrawals():
            if (w.effector, w.time) in self._popped_own:
                self._popped_own.discard((w.effector, w.time))
                continue  # ours, popped back
            self._standing.pop(w.effector, None)
            self._probations = [p for p in self._probations if p.effector != w.effector]
            out.append({"effector": w.effector, "kind": w.kind, "time": w.time, "detection_time": w.detection_time,
                        "detected_applied_time": None, "applied_time": None, "by": "detector", "reason": w.reason,
                        "statistics": {"statistic": w.statistic}})
        self.withdrawals.extend(out)
        return out

    # ------------------------------------------------------------------ the rule
    def _judge(self, p: _Probation, t: float) -> Any:
        times = np.asarray(self._t)
        before = (times >= p.onset - self.design.before) & (times < p.onset)
        after = (times > p.applied_time) & (times <= t + 1e-9)
        E = np.asarray(self._e)
        log_evidence, fits = None, False
        if after.sum() >= 2:
            without = dict(self.belief)
            if p.before is None:
                without.pop(p.effector, None)
            else:
                without[p.effector] = p.before
            Y, U = np.asarray(self._y)[after], np.asarray(self._u)[after]
            W = whitener(self._rho, int(after.sum()))
            r_belief = self._residuals(Y, U, self.belief)
            log_evidence = evidence_log_ratio(r_belief, self._residuals(Y, U, without), W)
            white = r_belief if W is None else W @ r_belief
            fits = belief_fits(float(np.sum(white * white)), white.size, self.design)
        return judge(E[before], E[after], log_evidence, self.design, fits=fits,
                     n_looks=looks(self.design, self.detector.sample_time))

    def _fit_since(self, onset: float, t: float) -> tuple[float, int]:
        """Whitened residual sum of squares under the detector's belief now, over the samples
        after ``onset`` up to ``t`` (at most the detector's long window), and their count.

        A surface believed stuck is modelled on its way there: from its healthy position at the
        onset it runs to the believed position at its rate limit, then holds (a hard-over runs to
        its stop, the catalogue's jam to its position: the isolation's run-to-stop signature)."""
        times = np.asarray(self._t)
        span = (times > onset + 1e-9) & (times <= t + 1e-9)
        keep = np.flatnonzero(span)[-max(self.detector.detector.N, self.detector.detector.N_long):]
        if keep.size < 2:
            return 0.0, 0
        U_all = np.asarray(self._u)
        Y, U = np.asarray(self._y)[keep], U_all[keep].copy()
        names = list(self.vehicle.effector_names)
        at_onset = U_all[max(0, int(np.searchsorted(times, onset)) - 1)]
        health = dict(self.detector.health)
        for name, h in list(health.items()):
            if h.jam_position is not None:
                j = names.index(name)
                start, target = at_onset[j], h.jam_position
                reach = float(self.vehicle.rate_max[j]) * (times[keep] - onset)
                U[:, j] = start + np.sign(target - start) * np.minimum(reach, abs(target - start))
                health[name] = replace(h, jam_position=None)  # the column kept, the position modelled above
        r = self._residuals(Y, U, health)
        W = whitener(self._rho, keep.size)
        white = r if W is None else W @ r
        return float(np.sum(white * white)), int(white.size)

    def _residuals(self, Y: np.ndarray, U: np.ndarray, health: dict[str, EffectorHealth]) -> np.ndarray:
        """``(y - B_eff u_known) / sigma`` under ``health`` (jams held, limits clipped, floating
        and effectiveness on ``B``; rate limits not followed: a stated simplification)."""
        B = self._B.copy()
        known = U.copy()
        names = list(self.vehicle.effector_names)
        for name, h in health.items():
            j = names.index(name)
            if h.floating:
                B[:, j] = 0.0
            else:
                B[:, j] *= h.effectiveness
            if h.jam_position is not None:
                known[:, j] = h.jam_position
            elif h.limits is not None:
                known[:, j] = np.clip(known[:, j], h.limits[0], h.limits[1])
        return (Y - known @ B.T) / self._std

    def describe(self) -> dict[str, Any]:
        return {"design": self.design.record(), "held": {self.vehicle.effector_names[j]: v for j, v in self.held.items()}}
