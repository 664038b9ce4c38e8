"""What a late detection waits on: the evidence of the data at the goal's deadline.

For the ``delays`` runs of :mod:`benchmarks.bench_detection` (the same seeds, failure times,
noise and frame), each flown again with the in-loop detector traced: after every detector
sample, whether stage 1 has alarmed, and, once it has, the posterior the isolation gives each
(effector, kind) on the data so far (:meth:`alloc.estimation.FailureDetector.evidence`, equal
priors less the BIC penalty: the numbers the 0.95 decision rule reads).  Reported at the goal's
deadline after the onset (0.5 s for jams and hard-overs, 2 s for losses of effectiveness):

- stage 1 had not alarmed: the residual had not left the noise at the design's false-alarm
  rate, a limit of the sensors, the noise and the rate, not of the isolation;
- it had, and the failed effector's posterior (``effector``) or the right kind's share within
  it (``kind``) was below 0.95: the data did not yet support naming it at the confidence the
  detector reports, and the strongest other hypothesis is given.

The trace reads the detector and changes nothing: a traced run's detections are the untraced
run's (checked in ``tests/benchmarks/test_detection_sweep.py``).
"""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np

import sim.engine as engine
from benchmarks import detection_cases as dc
from benchmarks.compare.failures import failure_effectors
from sim.detection import DEFAULT_DESIGN, design_with
from sim.scenarios import get_scenario

#: the goal's deadline after the onset, per kind (s): issue 26's
DEADLINE = {"jam": dc.JAM_P95_GOAL, "hardover": dc.JAM_P95_GOAL, "effectiveness": dc.LOE_GOAL}


def fly_traced(scenario: str, case: str, scale: float, s: int, frame_rate: float = 100.0,
               excitation: float = 0.0, long_window: float | None = None) -> dict[str, Any]:
    """The ``delays`` run of seed index ``s``, with its detector's evidence after every sample."""
    tf = dc.delay_failure_time(s, scenario, case)
    trace: list[dict[str, Any]] = []
    made_detector: list[Any] = []
    made = engine._detector

    def traced_detector(spec: Any, inputs: np.ndarray) -> Any:
        inloop = made(spec, inputs)
        det, sample = inloop.detector, inloop.sample
        made_detector.append(det)
        isolate = det._isolate
        weighed: list[Any] = []

        def traced_isolate(pending: Any, gamma: float) -> Any:  # the evidence the decision reads
            ev = det.evidence()
            failed = det.problem.names[failure_effectors(scenario, "jam1")[0]]
            # kept: the three strongest and every hypothesis on the failed effector (the rest is small)
            weighed.append([[e, k, round(p, 6)] for i, (e, k, p) in enumerate(ev) if i < 3 or e == failed])
            return isolate(pending, gamma)

        def traced_sample(step: int, x: np.ndarray, surfaces: np.ndarray, A_now: np.ndarray,
                          B_now: np.ndarray) -> Any:
            # the failure's signature as the detector sees it: the noise-free response less the
            # nominal model's prediction (before the sample advances anything)
            signature = (inloop.C @ ((A_now - inloop.A) @ x + B_now @ surfaces) - det.problem.B @ inloop.pos) \
                / det.noise_std
            weighed.clear()
            found = sample(step, x, surfaces, A_now, B_now)
            t = step * spec.dt - tf
            if t >= -0.5:  # the trace keeps the half second before the onset and what follows
                trace.append({"t": round(t, 6), "alarmed": bool(weighed), "evidence": weighed[0] if weighed else [],
                              "signature": [round(v, 9) for v in signature]})
            return found

        det._isolate, inloop.sample = traced_isolate, traced_sample
        return inloop

    engine._detector = traced_detector
    t0 = time.perf_counter()
    try:
        res = get_scenario(scenario)(method="qp", failure=dc.case_failure(scenario, case, tf), duration=tf + 3.0,
                                     seed=100 + s, health="detected", noise_scale=scale,
                                     frame_period=1.0 / frame_rate if frame_rate else None, excitation=excitation,
                                     detector_long_window=long_window)
    finally:
        engine._detector = made
    failed = res.effector_names[failure_effectors(scenario, "jam1")[0]]
    return {"key": f"{scenario}/{case}/{scale:g}/{s}", "scenario": scenario, "case": case, "kind": dc.case_kind(case),
            "noise_scale": scale, "seed": 100 + s, "failure_time": tf, "failed": failed,
            "excitation": excitation, "detector_long_window": design_with(long_window).long_window, "detections": res.summary().get("detections", []), "trace": trace,
            "noise_correlation": list(made_detector[0].noise_correlation), "per_sample_alpha": per_sample_alpha(),
            "wall": time.perf_counter() - t0}


#: the cases traced: the kinds with a delay goal
TRACED_CASES = ("jam", "hardover", "effectiveness", "loe50", "loe25")


def run_evidence(out: Any, seeds: int, scales: tuple[float, ...], frame_rate: float, excitation: float = 0.0,
                 long_window: float | None = None) -> None:
    """Every traced case of the ``delays`` section, seed by seed (resumable like it)."""
    done = dc.done_keys(out, "evidence")
    for s in range(seeds):
        for scale in scales:
            for scenario in dc.SCENARIOS:
                for case in TRACED_CASES:
                    key = f"{scenario}/{case}/{scale:g}/{s}"
                    if key not in done:
                        dc.write_row(out, "evidence", fly_traced(scenario, case, scale, s, frame_rate, excitation,
                                                                    long_window))


def per_sample_alpha() -> float:
    """The design's false-alarm probability per detector sample (its rate per hour times the sample time)."""
    return DEFAULT_DESIGN.false_alarm_rate * DEFAULT_DESIGN.sample_time / 3600.0


def oracle_power(row: dict[str, Any], deadline: float) -> float:
    """Detection probability at ``deadline`` of the oracle's matched filter: told the effector,
    kind, onset and size (the exact noise-free signature of the run), whitened with the
    noise's measured correlation, one test at the deadline at the design's per-sample
    false-alarm probability: ``Phi(sqrt(D) - z_alpha)``, ``D`` the signature's energy.  No
    detector that does not know the failure can do better at that false-alarm probability
    (Neyman-Pearson), so a low value is a limit of the sensors and the noise."""
    from scipy.linalg import cholesky, solve_triangular, toeplitz
    from scipy.stats import norm

    S = np.array([p["signature"] for p in row["trace"] if 0.0 < p["t"] <= deadline + 1e-9])
    if S.size == 0:
        return 0.0
    n = S.shape[0]
    lags = np.zeros(n)
    lags[0] = 1.0
    rho = np.asarray(row["noise_correlation"])[: n - 1]
    lags[1:1 + rho.size] = rho
    W = solve_triangular(cholesky(toeplitz(lags), lower=True), np.eye(n), lower=True)
    energy = float(((W @ S) ** 2).sum())
    return float(norm.cdf(math.sqrt(energy) - norm.isf(row["per_sample_alpha"])))


def at_deadline(row: dict[str, Any]) -> dict[str, Any]:
    """The evidence at the last detector sample at or before the kind's deadline."""
    deadline = DEADLINE[row["kind"]]
    before = [p for p in row["trace"] if 0.0 <= p["t"] <= deadline + 1e-9]
    point = before[-1] if before else {"t": None, "alarmed": False, "evidence": []}
    ev = point["evidence"]
    on_failed = sum(p for e, _, p in ev if e == row["failed"])
    right = sum(p for e, k, p in ev if e == row["failed"] and k == row["kind"])
    others = [(e, k, p) for e, k, p in ev if not (e == row["failed"] and k == row["kind"])]
    first = dc.first_on_failed({"detections": row["detections"], "failed": [row["failed"]]})
    return {"t": point["t"], "alarmed": point["alarmed"], "effector": on_failed,
            "kind": right / on_failed if on_failed > 0 else 0.0, "other": others[0] if others else None,
            "delay": None if first is None else first["delay"]}


def report_evidence(rows: list[dict[str, Any]]) -> str:
    """One line per run decided after its deadline (or missed)."""
    header = ["scenario", "case", "noise", "seed", "first detection (s)", "at the deadline (s)", "stage 1",
              "failed effector's posterior", "right kind's share", "strongest other hypothesis",
              "oracle's detection probability"]
    out = []
    for r in rows:
        deadline = DEADLINE[r["kind"]]
        a = at_deadline(r)
        if a["delay"] is not None and a["delay"] <= deadline:
            continue
        other = "-" if a["other"] is None else f"{a['other'][0]} {a['other'][1]} ({a['other'][2]:.2f})"
        out.append([r["scenario"], r["case"], f"x{r['noise_scale']:g}", str(r["seed"]),
                    "missed" if a["delay"] is None else f"{a['delay']:.2f}", f"{deadline:g}",
                    "alarmed" if a["alarmed"] else "no alarm",
                    f"{a['effector']:.2f}" if a["alarmed"] else "-", f"{a['kind']:.2f}" if a["alarmed"] else "-",
                    other if a["alarmed"] else "-", f"{oracle_power(r, deadline):.2f}"])
    decided = len(rows) - len(out)
    return (f"{len(rows)} runs traced; {decided} decided by their deadline (not listed).\n\n"
            + dc.markdown_table(header, out))
