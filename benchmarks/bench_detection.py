"""Detection in the closed loop (``alloc sim --health detected``) on ICE and HARV lat-dir.

Three measurements, each a list of closed-loop runs of :func:`sim.scenarios.get_scenario`
written one JSON line per run to ``--out`` (so a long measurement can be stopped and its
tables printed from what finished, ``--report``):

``delays``
    per scenario, detection case (:func:`detection_cases`: the catalogue's kinds of
    :mod:`benchmarks.compare.failures` on a single effector, ICE's left elevon, HARV's
    aileron -- its ``limits`` carries the reduced rate limits, its loss of effectiveness leaves
    25 % -- plus losses of 50 % and 25 % and the reduced rate limits alone) and noise scale (1, 2, 5 times the seed's): ``qp``, detected, failure at a seeded random
    time in [2, 3] s, 3 s flown after it (missed: no detection on the failed effector by then).  Per run: the first detection's delay, whether it
    named the failed effector and the kind; a run with no detection on the failed effector is
    missed; a detection before the failure or on another effector is a false alarm.
``false``
    no-failure flight at the seed's noise (``--noise-false`` for others), ``qp``, detected,
    ``--flight`` seconds per run with fresh noise seeds, until ``--hours`` per scenario; ``--dt``
    0.005 (the simulator's coarsest step, 10 times the seed's) buys ten times the hours: the
    detector's residual is noise only at any step (the nominal actuator copy integrates as the
    plant's actuators do, the plant is exact ZOH) and its noise level is measured at that step.
    The rate per 10 h carries an exact Poisson 95 % interval; the goal is called met only when
    the interval lies below it.
``benefit``
    per scenario, kind and method (``qp``, ``wls``), seeds: the same failure flown blind,
    told and detected, failure at 3 s, 7 s flown after it.  Score ``S`` = root-sum-square over channels of the post-failure RMS
    tracking error, each divided by the blind run's pre-failure RMS of that channel (same
    seed, same pre-failure flight); the oracle's benefit that survives is
    ``(S_blind - S_detected) / (S_blind - S_told)``, from the seeds' mean scores, with a
    bootstrap 90 % interval over seeds (2,000 resamples), and the same of the seeds' median
    scores (finite while fewer than half an arm's runs diverged).  A diverged run scores inf
    and is counted.  ``--frame-rate 0`` flies the seed's single-rate 2 kHz loop (with the 100 Hz
    frame HARV lat-dir's failure runs diverge often in every arm, told included);
    ``--failure-time`` off the detector's 0.1 s samples (3.05) flies an onset between two of
    them.  The runs of an ``alloc bench detected`` sweep copied to
    ``--out``/``sweep-detected/closed_*.csv`` are scored the same way (:func:`sweep_rows`).

Every run flies the seed's plant, actuators and noise at the seed's 0.5 ms step with a 100 Hz
flight-control frame (``--frame-rate``; the seed's single-rate 2 kHz loop costs three times as
much wall time, and hours of it were not affordable here); the detector samples at 10 Hz either
way.  The detector's free parameters are :class:`sim.detection.DetectionDesign`'s defaults (design
false-alarm rate 0.1 per hour, 0.4 s window, 10 Hz, 20 ms processing delay), printed with the
tables; none is chosen per kind or per verdict.

    python -m benchmarks.bench_detection run --section delays --seeds 10 --out /tmp/det
    python -m benchmarks.bench_detection report --out /tmp/det [--markdown]
"""

from __future__ import annotations

import argparse
import importlib
import json
import math
import time
from pathlib import Path
from typing import Any

import numpy as np
from scipy.stats import chi2

from benchmarks.compare.failures import catalogue_kinds, failure_effectors
from benchmarks.detection_cases import (
    JAM_P95_GOAL,
    LOE_GOAL,
    SCENARIOS,
    case_failure,
    case_kind,
    delay_failure_time,
    detection_cases,
    first_on_failed,
)
from benchmarks.detection_cases import done_keys as _done
from benchmarks.detection_cases import markdown_table as _table
from benchmarks.detection_cases import write_row as _write
from sim.detection import DEFAULT_DESIGN, design_with, response_noise_correlation
from sim.scenarios import get_scenario

NOISE_SCALES = (1.0, 2.0, 5.0)
METHODS = ("qp", "wls")
ARMS = ("blind", "told", "detected")
FALSE_PER_10H_GOAL = 1.0
BENEFIT_GOAL = 0.8
def _fly(scenario: str, case: str | None, *, health: str, method: str, seed: int, failure_time: float,
         duration: float, noise_scale: float = 1.0, frame_period: float | None = None,
         dt: float = 0.0005, excitation: float = 0.0, long_window: float | None = None) -> dict[str, Any]:
    run = get_scenario(scenario)
    failure = None if case is None else case_failure(scenario, case, failure_time)
    t0 = time.perf_counter()
    res = run(method=method, failure=failure, duration=duration, seed=seed, health=health,
              noise_scale=noise_scale, frame_period=frame_period, dt=dt, excitation=excitation,
              detector_long_window=long_window)
    s = res.summary()
    return {"scenario": scenario, "case": case, "kind": None if case is None else case_kind(case), "health": health,
            "method": method, "seed": seed, "failure_time": None if case is None else failure_time, "duration": duration, "noise_scale": noise_scale,
            "frame_period": frame_period, "dt": dt, "excitation": excitation,
            "detector_long_window": design_with(long_window).long_window,
            "diverged": s["diverged"], "simulated": s["duration"],
            "channels": s["channels"], "detections": s.get("detections", []),
            "failed": [res.effector_names[i] for i in failure_effectors(scenario, "jam1")] if case else [],
            "wall": time.perf_counter() - t0}


def machine_state(section: str, argv: list[str]) -> dict[str, Any]:
    """Where and when a measurement ran: commit, CPUs, load, Python, the command."""
    import os
    import platform
    import subprocess

    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                            cwd=Path(__file__).resolve().parent).stdout.strip()
    return {"section": section, "started": time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime()), "commit": commit,
            "cpus": os.cpu_count(), "load": [round(x, 2) for x in os.getloadavg()],
            "python": platform.python_version(), "machine": platform.machine(), "argv": argv}


def run_delays(out: Path, seeds: int, scales: tuple[float, ...], frame_rate: float, excitation: float = 0.0,
               long_window: float | None = None) -> None:
    done = _done(out, "delays")
    for s in range(seeds):
        for scale in scales:
            for scenario in SCENARIOS:
                for case in detection_cases():
                    key = f"{scenario}/{case}/{scale:g}/{s}"
                    if key in done:
                        continue
                    tf = delay_failure_time(s, scenario, case)
                    row = _fly(scenario, case, health="detected", method="qp", seed=100 + s, failure_time=tf,
                               duration=tf + 3.0, noise_scale=scale, excitation=excitation, long_window=long_window,
                               frame_period=1.0 / frame_rate if frame_rate else None)
                    _write(out, "delays", {"key": key, **row})


def run_false(out: Path, hours: float, flight: float, scale: float, frame_rate: float, dt: float,
              first_seed: int = 0, long_window: float | None = None) -> None:
    done = _done(out, "false")
    n = int(math.ceil(hours * 3600.0 / flight))
    for s in range(first_seed, first_seed + n):  # the scenarios in turn, so a stopped measurement has both
        for scenario in SCENARIOS:
            key = f"{scenario}/{scale:g}/{flight:g}/{dt:g}/{s}"
            if key in done:
                continue
            row = _fly(scenario, None, health="detected", method="qp", seed=1000 + s, failure_time=0.0,
                       duration=flight, noise_scale=scale, frame_period=1.0 / frame_rate, dt=dt,
                       long_window=long_window)
            _write(out, "false", {"key": key, **row})


def run_replay(out: Path, hours: float, scale: float, dt: float = 0.005, flight: float = 120.0,
               long_window: float | None = None) -> None:
    """The in-loop detector, replayed: no-failure hours of the seed's noise model on recorded commands.

    One ``flight``-second no-failure closed-loop run per scenario (``qp``, blind: nothing
    can change the flight) gives the surfaces' positions at the detector's samples -- what the
    in-loop detector's nominal actuator copy computes when nothing fails.  Fresh hours of the
    seed's noise model (its filter, gains and ``scale``) at the step ``dt``, differenced as the
    in-loop detector differences them, are added to ``C B u``: the residual the in-loop
    detector sees in a no-failure flight, without the plant's cost.  The positions repeat
    every ``flight`` seconds; the noise never does.  Two detectors on the same data: the one
    flown (``whitened``, told the measured noise correlation) and the same told none
    (``white``), so the cause of its false alarms is measured, not argued.
    """
    import sim.detection as sd
    from sim.blocks import band_limited_noise

    done = _done(out, "replay")
    for scenario in SCENARIOS:
        res = get_scenario(scenario)(method="qp", failure=None, duration=flight, seed=5000, health="blind",
                                     noise_scale=scale, frame_period=0.01, dt=dt)
        vehicle = importlib.import_module(f"sim.scenarios.{scenario}").vehicle()
        ts = DEFAULT_DESIGN.sample_time
        every = int(round(ts / dt))
        pick = np.searchsorted(res.t, np.arange(1, int(res.t[-1] / ts)) * ts - 1e-9)
        U = np.asarray(res.effectors)[pick]
        inloop = sd.InLoopDetector(vehicle, dt, np.zeros((2, vehicle.C.shape[0])), noise_scale=scale,
                                   actuators=True, preferred=np.zeros(len(vehicle.effector_names)),
                                   design=design_with(long_window))
        made = inloop.detector
        gains = np.zeros(vehicle.C.shape[0])
        gains[np.asarray(vehicle.measured)] = vehicle.noise_gains
        gains = gains[inloop.rows] * scale
        CB = inloop.C @ vehicle.B
        for h in range(int(math.ceil(hours))):
            key = f"{scenario}/{scale:g}/{dt:g}/{h}"
            if key in done:
                continue
            t0 = time.perf_counter()
            rng = np.random.default_rng([7000, SCENARIOS.index(scenario), h])
            n = int(round(3600.0 / dt)) + every
            noise = band_limited_noise(n, dt, gains, rng)
            diff = (noise[every::every] - noise[:-every:every][: noise[every::every].size]) / ts
            row: dict[str, Any] = {"key": key, "scenario": scenario, "noise_scale": scale, "dt": dt, "hour": h,
                                   "detector_long_window": design_with(long_window).long_window,
                                   "flight": flight, "flight_diverged": bool(res.diverged),
                                   "samples": int(diff.shape[0])}
            Uh = U[np.arange(diff.shape[0]) % U.shape[0]]
            Yh = Uh @ CB.T + diff
            for name, corr in (("whitened", made.noise_correlation), ("white", None)):
                row[name] = _replay_hour(made, corr, Uh, Yh, ts)
            row["wall"] = time.perf_counter() - t0
            _write(out, "replay", row)


#: chi-square tail probabilities at which the replay checks the stage-1 statistic's calibration
CALIBRATION_TAILS = (1e-2, 1e-3, 1e-4)


def _replay_hour(made: Any, corr: Any, U: np.ndarray, Y: np.ndarray, ts: float) -> dict[str, Any]:
    """Stage-1 exceedances of one hour (every window at once, :meth:`FailureDetector.window_statistics`)
    and, for each alarm, the streaming detector from a buffer's length before it to a buffer's
    length after it (how long :meth:`FailureDetector.update` keeps an alarm pending): its
    detections are the false alarms.  A first false detection would change a streaming
    detector's model for the rest of the flight; here every alarm meets a healthy model, so
    the count is of first false alarms (each would be followed, in flight, by what it causes)."""
    def make() -> Any:
        return type(made)(made.problem, made.noise_std, made.dt, false_alarm_rate=made.false_alarm_rate,
                          window=made.window_seconds, hop=made.hop, min_confidence=made.min_confidence,
                          noise_correlation=corr, long_window=made.long_window_seconds)

    det = make()
    W = det.window_statistics(U, Y)
    over = np.flatnonzero((W > det.threshold()).any(axis=1)) + det.N - 1
    if det.N_long:  # the long window's exceedances too (the streaming test tries it where the short one is quiet)
        over = np.union1d(over, np.flatnonzero((det.window_statistics(U, Y, long=True) > det.threshold())
                                               .any(axis=1)) + det.N_long - 1)
    # calibration: the share of (window, effector) statistics beyond chi-square's 1e-2 .. 1e-4 points
    tail = {f"{a:g}": float((W > chi2.isf(a, det.dof)).mean()) for a in CALIBRATION_TAILS}
    alarms, found, last = 0, [], -1
    for e in over:
        if e <= last:
            continue
        alarms += 1
        fresh = make()
        for s in range(max(0, e - fresh.L + 1), min(len(U), e + fresh.L + 1)):
            got = fresh.update(U[s], Y[s], time=(s + 1) * ts)
            if got:
                found += got
                break
        last = e + fresh.L
    return {"exceedances": int(over.size), "alarms": alarms, "tail": tail, "windows": int(W.size),
            "detections": [{"effector": d.event.effector, "kind": d.event.kind.value, "time": d.time,
                            "statistic": d.statistic, "threshold": d.threshold} for d in found]}


def report_replay(rows: list[dict[str, Any]]) -> str:
    header = ["scenario", "noise", "recorded flight", "detector", "hours", "windows over threshold", "alarms",
              "detections (false)", "per 10 h",
              "95 % interval per 10 h", "goal (< 1 per 10 h)"]
    out = []
    for scenario in SCENARIOS:
        for scale in sorted({r["noise_scale"] for r in rows}):
            sel = [r for r in rows if r["scenario"] == scenario and r["noise_scale"] == scale]
            if not sel:
                continue
            hours = sum(r["samples"] for r in sel) * DEFAULT_DESIGN.sample_time / 3600.0
            for name in ("whitened", "white"):
                n = sum(len(r[name]["detections"]) for r in sel)
                lo, hi = (10.0 * x / hours for x in poisson_interval(n))
                rate = 10.0 * n / hours
                flown = "diverged: not a valid replay" if any(r["flight_diverged"] for r in sel) else "ok"
                out.append([scenario, f"x{scale:g}", flown, name + (" (flown)" if name == "whitened" else " (as before)"),
                            f"{hours:.1f}", str(sum(r[name]["exceedances"] for r in sel)),
                            str(sum(r[name]["alarms"] for r in sel)), str(n), f"{rate:.2f}",
                            f"[{lo:.2f}, {hi:.2f}]", false_verdict(rate, hi) if scale == 1.0 and flown == "ok" else ""])
    table = _table(header, out)
    cal_rows = []
    for scenario in SCENARIOS:
        sel = [r for r in rows if r["scenario"] == scenario and r["noise_scale"] == 1.0 and "tail" in r["white"]]
        for name in ("whitened", "white"):
            if not sel:
                continue
            n = sum(r[name]["windows"] for r in sel)
            cells = []
            for a in CALIBRATION_TAILS:
                share = sum(r[name]["tail"][f"{a:g}"] * r[name]["windows"] for r in sel) / n
                cells.append(f"{share / a:.2f} +- {math.sqrt(a / n) / a:.2f}")
            cal_rows.append([scenario, name, f"{n:,}", *cells])
    if cal_rows:
        table += ("\n\nCalibration of the stage-1 statistic (no failure, seed's noise): observed share of "
                  "(window, effector) statistics beyond chi-square's upper point over its nominal probability "
                  "(1 = calibrated; +- one binomial standard error, ignoring the windows' overlap).\n\n"
                  + _table(["scenario", "detector", "statistics", *(f"beyond the {a:g} point" for a in CALIBRATION_TAILS)],
                           cal_rows))
    return table


def run_benefit(out: Path, seeds: int, frame_rate: float, first_seed: int = 0,
                arms: tuple[str, ...] = ARMS, kinds: tuple[str, ...] | None = None,
                failure_time: float = 3.0, scenarios: tuple[str, ...] = SCENARIOS, excitation: float = 0.0,
                long_window: float | None = None) -> None:
    """Seed by seed (an interrupted run leaves whole seeds); ``arms``, ``kinds``, ``scenarios`` subsets, so the
    arms that do not depend on the detector (blind, told) can be flown apart from the one that
    does; ``failure_time`` off the detector's 0.1 s samples (e.g. 3.05) flies the onset between
    two of them (write those runs to their own ``--out``: the report does not tell them apart)."""
    done = _done(out, "benefit")
    for s in range(first_seed, first_seed + seeds):
        for scenario in scenarios:
            for kind in kinds or catalogue_kinds():
                for method in METHODS:
                    for arm in arms:
                        key = f"{scenario}/{kind}/{method}/{arm}/{frame_rate:g}/{s}"
                        if key in done or key.replace(f"/{frame_rate:g}/", "/") in done and frame_rate == 100:
                            continue
                        row = _fly(scenario, kind, health=arm, method=method, seed=200 + s, failure_time=failure_time,
                                   duration=10.0, frame_period=1.0 / frame_rate if frame_rate else None,
                                   excitation=excitation, long_window=long_window)
                        _write(out, "benefit", {"key": key, **row})


# ---------------------------------------------------------------------------- report
def _rows(out: Path, section: str) -> list[dict[str, Any]]:
    path = out / f"{section}.jsonl"
    return [json.loads(line) for line in path.read_text().splitlines() if line.strip()] if path.exists() else []


def last_on_failed(row: dict[str, Any]) -> dict[str, Any] | None:
    """The last detection after the failure naming a failed effector (the detector's final belief)."""
    found = [d for d in row["detections"] if d["delay"] is not None and d["effector"] in row["failed"]]
    return found[-1] if found else None


def false_alarms(row: dict[str, Any]) -> int:
    """Detections before the failure, or on an effector that did not fail (all of them without a failure)."""
    return sum(1 for d in row["detections"] if d["delay"] is None or d["effector"] not in row["failed"])


def report_delays(rows: list[dict[str, Any]]) -> str:
    header = ["scenario", "case", "noise", "runs", "isolated", "kind right first", "kind right finally", "missed",
              "other detections", "delay median (s)", "delay p95 (s)", "goal"]
    out = []
    for scenario in SCENARIOS:
        for case in detection_cases():
            kind = case_kind(case)
            for scale in NOISE_SCALES:
                sel = [r for r in rows if r["scenario"] == scenario and r.get("case", r["kind"]) == case
                       and r["noise_scale"] == scale]
                if not sel:
                    continue
                firsts = [first_on_failed(r) for r in sel]
                delays = np.array([d["delay"] for d in firsts if d is not None])
                right = sum(1 for d in firsts if d is not None and d["kind"] == kind)
                finally_right = sum(1 for r in sel if (last := last_on_failed(r)) is not None and last["kind"] == kind)
                missed = sum(1 for d in firsts if d is None)
                goal = ""
                if kind in ("jam", "hardover"):
                    p95 = np.percentile(delays, 95) if delays.size else math.inf
                    goal = f"p95 < {JAM_P95_GOAL} s: {'met' if missed == 0 and p95 < JAM_P95_GOAL else 'NOT met'}"
                elif kind == "effectiveness":
                    ok = missed == 0 and delays.size and delays.max() <= LOE_GOAL
                    goal = f"all within {LOE_GOAL} s: {'met' if ok else 'NOT met'}"
                out.append([scenario, case, f"x{scale:g}", str(len(sel)), str(len(delays)), str(right), str(finally_right), str(missed),
                            str(sum(false_alarms(r) for r in sel)),
                            f"{np.median(delays):.2f}" if delays.size else "-",
                            f"{np.percentile(delays, 95):.2f}" if delays.size else "-", goal])
    return _table(header, out)


def poisson_interval(n: int, level: float = 0.95) -> tuple[float, float]:
    """Exact (Garwood) two-sided interval of a Poisson mean from ``n`` events."""
    tail = (1.0 - level) / 2.0
    lo = 0.0 if n == 0 else float(chi2.ppf(tail, 2 * n)) / 2.0
    return lo, float(chi2.ppf(1.0 - tail, 2 * n + 2)) / 2.0


def false_verdict(rate: float, upper: float) -> str:
    """Met when the 95 % interval lies below the goal; the point alone below it is not a demonstration."""
    if upper < FALSE_PER_10H_GOAL:
        return "met"
    if rate < FALSE_PER_10H_GOAL:
        return "not shown (interval reaches the goal)"
    return "NOT met"


def report_false(rows: list[dict[str, Any]]) -> str:
    header = ["scenario", "noise", "step (ms)", "runs", "diverged", "simulated hours", "false alarms",
              "flights with one", "per 10 h", "95 % interval per 10 h", "goal (< 1 per 10 h)"]
    out = []
    for scenario in SCENARIOS:
        for scale, dt in sorted({(r["noise_scale"], r.get("dt", 0.0005)) for r in rows}):
            sel = [r for r in rows if r["scenario"] == scenario and r["noise_scale"] == scale
                   and r.get("dt", 0.0005) == dt]
            if not sel:
                continue
            hours = sum(r["simulated"] for r in sel) / 3600.0
            n = sum(false_alarms(r) for r in sel)
            rate = 10.0 * n / hours
            lo, hi = (10.0 * x / hours for x in poisson_interval(n))
            out.append([scenario, f"x{scale:g}", f"{1e3 * dt:g}", str(len(sel)), str(sum(r["diverged"] for r in sel)),
                        f"{hours:.2f}", str(n), str(sum(false_alarms(r) > 0 for r in sel)), f"{rate:.2f}",
                        f"[{lo:.2f}, {hi:.2f}]", false_verdict(rate, hi) if scale == 1.0 else ""])
    return _table(header, out)


def score(row: dict[str, Any], blind: dict[str, Any]) -> float:
    """Post-failure RMS error, root-sum-square over channels of each divided by the blind run's pre-failure RMS."""
    if row["diverged"]:
        return math.inf
    total = 0.0
    for ch, m in row["channels"].items():
        ref = blind["channels"][ch]["rms_before"] or 1.0
        total += (m["rms_after"] / ref) ** 2
    return math.sqrt(total)


def surviving_fraction(blind: np.ndarray, told: np.ndarray, detected: np.ndarray, centre: Any = np.mean) -> float:
    """``(c blind - c detected) / (c blind - c told)``, ``c`` the mean (or the median: finite while
    fewer than half the runs of an arm diverged); nan when told does not help or it is not finite."""
    b, t, d = centre(blind), centre(told), centre(detected)
    with np.errstate(invalid="ignore"):  # inf - inf (both arms diverged): nan, undefined below
        gain = b - t
    if not np.isfinite(gain) or gain <= 0 or not np.isfinite(d):
        return math.nan
    return float((b - d) / gain)


def sweep_rows(csv_path: Path) -> list[dict[str, Any]]:
    """The runs of an ``alloc bench detected`` sweep (its ``closed_<scenario>.csv``) as this script's
    rows: the same arms, seeds and per-channel RMS, scored here by :func:`score` (the sweep's own
    score needs a ``static`` baseline the detected sweep does not fly)."""
    import csv

    rows = []
    with open(csv_path, newline="") as fh:
        for r in csv.DictReader(fh):
            chans = sorted({k[: -len("_rms_before")] for k in r if k.endswith("_rms_before")})
            frame = float(r["setting"].split("=", 1)[1]) if r["setting"].startswith("frame_period=") else None
            rows.append({"scenario": r["scenario"], "kind": r["failure"].rstrip("12"), "method": r["method"],
                         "health": r["health"], "seed": int(r["seed"]), "diverged": r["diverged"] == "True",
                         "frame_period": frame,
                         "channels": {c: {"rms_before": float(r[f"{c}_rms_before"]),
                                          "rms_after": float(r[f"{c}_rms_after"])} for c in chans}})
    return rows


def report_benefit(rows: list[dict[str, Any]], resamples: int = 2000) -> str:
    header = ["scenario", "frame", "kind", "method", "seeds", "blind S", "told S", "detected S", "surviving fraction",
              "90 % CI", "of medians", "90 % CI ", "goal (>= 0.8, jam/hardover)"]
    out = []
    rng = np.random.default_rng(0)
    by = {(r["scenario"], r["kind"], r["method"], r["health"], r["seed"]): r for r in rows}
    frame = rows[0]["frame_period"]
    for scenario in SCENARIOS:
        for kind in catalogue_kinds():
            for method in METHODS:
                seeds = sorted({s for (sc, k, me, h, s) in by if (sc, k, me) == (scenario, kind, method)
                                and all((sc, k, me, a, s) in by for a in ARMS)})
                if not seeds:
                    continue
                S = {a: np.array([score(by[(scenario, kind, method, a, s)], by[(scenario, kind, method, "blind", s)])
                                  for s in seeds]) for a in ARMS}
                fracs, cis = [], []
                for centre in (np.mean, np.median):
                    frac = surviving_fraction(S["blind"], S["told"], S["detected"], centre)
                    boots = []
                    for _ in range(resamples):
                        i = rng.integers(len(seeds), size=len(seeds))
                        boots.append(surviving_fraction(S["blind"][i], S["told"][i], S["detected"][i], centre))
                    boots = np.array(boots)
                    boots = boots[np.isfinite(boots)]
                    fracs.append(frac)
                    cis.append(f"[{np.percentile(boots, 5):.2f}, {np.percentile(boots, 95):.2f}]"
                               if boots.size > 0.9 * resamples else "-")
                frac = fracs[0]
                goal = ""
                if kind in ("jam", "hardover"):
                    goal = "met" if np.isfinite(frac) and frac >= BENEFIT_GOAL else "NOT met"
                    if not np.isfinite(frac) and np.isfinite(fracs[1]):
                        goal += f" (median-based {'met' if fracs[1] >= BENEFIT_GOAL else 'NOT met'})"
                out.append([scenario, "seed's 2 kHz" if frame is None else f"{1 / frame:g} Hz", kind, method,
                            str(len(seeds)),
                            *(f"{S[a].mean():.3f}" if np.isfinite(S[a]).all() else f"inf ({np.isinf(S[a]).sum()})"
                              for a in ARMS),
                            f"{frac:.2f}" if np.isfinite(frac) else "undefined (an arm diverged, or told no better)", cis[0],
                            f"{fracs[1]:.2f}" if np.isfinite(fracs[1]) else "undefined", cis[1], goal])
    return _table(header, out)


def _variant(row: dict[str, Any]) -> tuple[float, float]:
    """How a run's loop differed from the default: (excitation deg, second detector window s; 0: none)."""
    return float(row.get("excitation") or 0.0), float(row.get("detector_long_window") or 0.0)


def report(out: Path, markdown: bool) -> str:
    # the second window is a run setting: each table's title says when its runs had one
    design = ", ".join(f"{k} {v:g}" if isinstance(v, (int, float)) else f"{k} {v}"
                       for k, v in DEFAULT_DESIGN.record().items() if k != "long_window")
    rho = ", ".join(f"{x:+.3f}" for x in response_noise_correlation(0.0005, DEFAULT_DESIGN.sample_time)[:5])
    parts = [f"Detector design (sim.detection.DEFAULT_DESIGN): {design}; noise autocorrelation told to it "
             f"(measured, lags 1-5 of {DEFAULT_DESIGN.sample_time:g} s): {rho}.\n"]
    machines = _rows(out, "machine")
    if machines:
        walls = {s: sum(r.get("wall", 0.0) for r in _rows(out, s)) / 3600.0
                 for s in ("delays", "false", "replay", "benefit", "evidence")}
        parts.append("## Machine state\n\n" + _table(
            ["section", "started", "commit", "CPUs", "load (1, 5, 15 min)", "Python", "command"],
            [[m["section"], m["started"], m["commit"], str(m["cpus"]), ", ".join(f"{x:g}" for x in m["load"]),
              m["python"], "`" + " ".join(m["argv"]) + "`"] for m in machines])
            + "\n\nRun wall time (hours, summed over runs, processes in parallel): "
            + ", ".join(f"{s} {w:.2f}" for s, w in walls.items()) + ".\n")
    from benchmarks.detection_evidence import report_evidence

    for title, section, fn in (("Detection delay per kind and noise (qp, detected)", "delays", report_delays),
                               ("What a late detection waited on: the evidence at the goal's deadline", "evidence",
                                report_evidence),
                               ("False alarms over no-failure flight (qp, detected)", "false", report_false),
                               ("False alarms of the detector replayed on the noise model (no-failure commands)",
                                "replay", report_replay),
                               ("Oracle benefit that survives detection", "benefit", report_benefit)):
        rows = _rows(out, section)
        if section == "benefit":
            rows += [r for path in sorted(out.glob("sweep-detected/closed_*.csv")) for r in sweep_rows(path)]
        groups = ([[r for r in rows if r["frame_period"] == f] for f in sorted({r["frame_period"] for r in rows},
                                                                                key=lambda f: f or 0.0)]
                  if section == "benefit" else [rows])
        for group in groups:
            for variant in sorted({_variant(r) for r in group}):
                sel = [r for r in group if _variant(r) == variant]
                amp, long = variant
                with_ = (f", with null-space excitation {amp:g} deg" if amp else "") + (
                    f", with a second {long:g} s detector window" if long else "")
                parts.append(f"## {title}{with_}\n\n{fn(sel)}\n")
    text = "\n".join(parts)
    return text if markdown else text.replace("## ", "")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="command", required=True)
    r = sub.add_parser("run")
    r.add_argument("--section", choices=("delays", "false", "replay", "benefit", "evidence"), required=True)
    r.add_argument("--out", type=Path, required=True)
    r.add_argument("--seeds", type=int, default=10)
    r.add_argument("--noise", default="1,2,5", help="noise scales (delays)")
    r.add_argument("--hours", type=float, default=5.0, help="simulated hours per scenario (false)")
    r.add_argument("--flight", type=float, default=300.0, help="seconds per no-failure run (false)")
    r.add_argument("--noise-false", type=float, default=1.0)
    r.add_argument("--first-seed", type=int, default=0,
                   help="first noise seed index (false, benefit; parallel processes)")
    r.add_argument("--arms", default=",".join(ARMS), help="arms flown (benefit)")
    r.add_argument("--kinds", default=None, help="catalogue kinds flown (benefit; default all)")
    r.add_argument("--failure-time", type=float, default=3.0, help="failure time (s, benefit)")
    r.add_argument("--scenarios", default=",".join(SCENARIOS), help="scenarios flown (benefit)")
    r.add_argument("--dt", type=float, default=0.0005, help="integration step of the false section (s)")
    r.add_argument("--excitation", type=float, default=0.0,
                   help="null-space excitation in every arm (deg, each effector's peak; delays, benefit; "
                        "sim --excitation; write to its own --out)")
    r.add_argument("--detector-long-window", type=float, default=None,
                   help="the detector's second stage-1 window (s; 0: none; default: the design's; every "
                        "section; sim --detector-long-window; write to its own --out)")
    r.add_argument("--frame-rate", type=float, default=100.0,
                   help="flight-control frame rate (Hz); 0: the seed's single-rate 2 kHz loop")
    p = sub.add_parser("report")
    p.add_argument("--out", type=Path, required=True)
    p.add_argument("--markdown", action="store_true")
    args = ap.parse_args()
    if args.command == "run":
        import sys

        _write(args.out, "machine", machine_state(args.section, sys.argv[1:]))
    if args.command == "report":
        print(report(args.out, args.markdown))
    elif args.section == "delays":
        run_delays(args.out, args.seeds, tuple(float(x) for x in args.noise.split(",")), args.frame_rate,
                   args.excitation, args.detector_long_window)
    elif args.section == "evidence":
        from benchmarks.detection_evidence import run_evidence

        run_evidence(args.out, args.seeds, tuple(float(x) for x in args.noise.split(",")), args.frame_rate,
                     args.excitation, args.detector_long_window)
    elif args.section == "replay":
        run_replay(args.out, args.hours, args.noise_false, args.dt, long_window=args.detector_long_window)
    elif args.section == "false":
        run_false(args.out, args.hours, args.flight, args.noise_false, args.frame_rate, args.dt, args.first_seed,
                  args.detector_long_window)
    else:
        arms = tuple(args.arms.split(","))
        if not set(arms) <= set(ARMS):
            ap.error(f"--arms: {args.arms!r}; expected a comma-separated subset of {','.join(ARMS)}")
        kinds = None if args.kinds is None else tuple(args.kinds.split(","))
        if kinds is not None and not set(kinds) <= set(catalogue_kinds()):
            ap.error(f"--kinds: {args.kinds!r}; expected a comma-separated subset of {','.join(catalogue_kinds())}")
        scenarios = tuple(args.scenarios.split(","))
        if not set(scenarios) <= set(SCENARIOS):
            ap.error(f"--scenarios: {args.scenarios!r}; expected a comma-separated subset of {','.join(SCENARIOS)}")
        run_benefit(args.out, args.seeds, args.frame_rate, args.first_seed, arms, kinds, args.failure_time,
                    scenarios, args.excitation, args.detector_long_window)


if __name__ == "__main__":
    main()
