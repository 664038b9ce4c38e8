"""Detection in a world the project did not write: model error, turbulence, heavy-tailed noise.

Closed-loop ``--health detected`` flights of four vehicles -- the seed's ICE and HARV lat-dir
(:func:`sim.scenarios.get_scenario`) and the catalogue's hexa-x and tailless vehicle files
(:func:`sim.user_vehicle.fly`, auto-designed controller) -- in each *condition*
(:data:`CONDITIONS`): the exact world (the plant equal to the model, the seed's Gaussian noise,
no wind), ``--model-error 0.2``, ``--turbulence moderate``, Student-t(4) sensor noise at the
stated standard deviation, and all three together.  The detector is never told the condition.
One JSON line per run in ``--out`` (a stopped measurement resumes, and ``report`` prints what
finished).

``false``
    no-failure flights of ``--flight`` s (fresh seeds: fresh noise, turbulence and model-error
    draws) until ``--hours`` per vehicle and condition; every detection is false.  The rate per
    10 h carries an exact Poisson 95 % interval; the goal (fewer than 1 per 10 h) is called met
    only when the interval's upper end lies below it.
``delays``
    a jam, a hard-over and a loss of 75 % of effectiveness's complement (25 % lost) of one
    effector (ICE's left elevon, HARV's aileron, hexa-x's motor 1, tailless's left elevon) at a
    seeded time uniform in ``[F, F + 1]`` s, ``F = --failure-time`` (10 s: the detector learns
    its nominal residual in flight, and an aircraft has flown for longer than that before any
    failure; a free parameter, disclosed with every table), 3 s flown after it.  The delay is the
    first detection naming the failed effector; a run with none is missed.
``benefit``
    the same failures flown blind, told and detected (7 s after the failure), scored as
    :func:`benchmarks.bench_detection.score` (post-failure RMS tracking error over the blind
    run's pre-failure RMS, root-sum-square over channels) with the surviving fraction of the
    told benefit and a bootstrap 90 % interval over seeds.
``example``
    the docs' example, ``alloc sim ice --method qp --failure seed`` at its defaults (the seed's
    0.5 ms step and 2 kHz loop), blind, told and detected, per condition and seed: the worst
    channel's RMS-after ratio of detected to blind (goal <= 1.25).

Every flight is ``qp`` at a 100 Hz flight-control frame; ``false``, ``delays`` and
``benefit`` integrate at 5 ms (``--dt``; the simulator's coarsest step, which buys the hours:
measured, ICE flies 60 s in 0.6 s of wall time there), the example at its own defaults.

    python -m benchmarks.bench_detection_world run --section false --hours 1 --out /tmp/world
    python -m benchmarks.bench_detection_world report --out /tmp/world --markdown
"""

from __future__ import annotations

import argparse
import math
import os
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.bench_detection import machine_state, poisson_interval, score, surviving_fraction
from benchmarks.compare.failures import failure_effectors
from benchmarks.detection_cases import case_failure
from benchmarks.detection_cases import done_keys as _done
from benchmarks.detection_cases import markdown_table as _table
from benchmarks.detection_cases import write_row as _write

#: the world of each condition, as run settings (the detector is told none of them)
CONDITIONS: dict[str, dict[str, Any]] = {
    "exact": {},
    "model-error 0.2": {"model_error": 0.2},
    "turbulence moderate": {"turbulence": "moderate"},
    "student-t(4)": {"noise_model": "student-t:4"},
    "all three": {"model_error": 0.2, "turbulence": "moderate", "noise_model": "student-t:4"},
}
#: the seed's scenarios and the catalogue's vehicle files
SCENARIOS = ("ice", "harv_latdir")
VEHICLE_FILES = ("hexa-x", "tailless")
VEHICLES = (*SCENARIOS, *VEHICLE_FILES)
#: the failed effector of a vehicle file (the scenarios': the catalogue's, :mod:`benchmarks.compare.failures`)
FILE_EFFECTOR = {"hexa-x": "motor1", "tailless": "elevon_l"}
#: failure cases: the catalogue's jam and hard-over, and a loss of 25 % of effectiveness
CASES = ("jam", "hardover", "loe25")
ARMS = ("blind", "told", "detected")
FALSE_PER_10H_GOAL = 1.0
JAM_P95_GOAL = 0.5
LOE_GOAL = 2.0
BENEFIT_GOAL = 0.8
EXAMPLE_RATIO_GOAL = 1.25
FRAME = 0.01


def _file_failure(vehicle: str, case: str) -> str:
    e = FILE_EFFECTOR[vehicle]
    return {"jam": f"jam:{e}", "hardover": f"hardover:{e}", "loe25": f"effectiveness:{e}@0.75"}[case]


#: The coarsest integration step and frame a vehicle flies at (s): the auto-designed tailless
#: diverges at 5 ms steps, and at 2 ms steps with a 100 Hz frame (at 2.5 s, with no failure), in
#: the exact world; it flies at 2 ms and 250 Hz (measured 2026-12-06).
COARSEST_DT = {"tailless": 0.002}
COARSEST_FRAME = {"tailless": 0.004}


def fly(vehicle: str, case: str | None, *, condition: str, health: str, seed: int, failure_time: float,
        duration: float, dt: float, frame_period: float | None = FRAME, method: str = "qp",
        detector_model: str = "learnt") -> dict[str, Any]:
    """One closed-loop flight and what the tables need of it."""
    world = CONDITIONS[condition]
    dt = min(dt, COARSEST_DT.get(vehicle, dt))
    if frame_period is not None:
        frame_period = min(frame_period, COARSEST_FRAME.get(vehicle, frame_period))
    t0 = time.perf_counter()
    common = dict(method=method, duration=duration, seed=seed, health=health, dt=dt, frame_period=frame_period,
                  **world, **({"detector_model": detector_model} if health == "detected" else {}))
    if vehicle in SCENARIOS or vehicle == "ice-seed":
        from sim.scenarios import get_scenario

        scenario = "ice" if vehicle == "ice-seed" else vehicle
        failure = "seed" if case == "seed" else (None if case is None else case_failure(scenario, case, failure_time))
        res = get_scenario(scenario)(failure=failure, **common)
        failed = [] if case in (None, "seed") else [res.effector_names[i] for i in failure_effectors(scenario, "jam1")]
    else:
        from sim.user_vehicle import fly as fly_file

        extra = {} if case is None else {"failure": _file_failure(vehicle, case), "failure_time": failure_time}
        res = fly_file(vehicle, **common, **extra)
        failed = [] if case is None else [FILE_EFFECTOR[vehicle]]
    s = res.summary()
    return {"vehicle": vehicle, "case": case, "condition": condition, "health": health, "seed": seed,
            "failure_time": None if case is None else failure_time, "duration": duration, "dt": dt,
            "diverged": s["diverged"], "simulated": s["duration"], "channels": s["channels"],
            "detections": s.get("detections", []), "withdrawals": s.get("withdrawals", []), "failed": failed,
            "world": res.settings.get("world"), "detector_model": detector_model if health == "detected" else None,
            "wall": time.perf_counter() - t0}


def _job(key: str, kwargs: dict[str, Any]) -> tuple[str, dict[str, Any]]:
    try:
        return key, fly(**kwargs)
    except Exception as exc:  # noqa: BLE001 - recorded, not lost: a run that raises is a finding
        return key, {"error": f"{type(exc).__name__}: {exc}", **{k: v for k, v in kwargs.items()
                                                                  if isinstance(v, (str, int, float, type(None)))}}


def _run(out: Path, section: str, jobs: list[tuple[str, dict[str, Any]]], workers: int) -> None:
    done = _done(out, section)
    todo = [(k, kw) for k, kw in jobs if k not in done]
    if not todo:
        return
    _write(out, "machine", machine_state(section, [section, str(len(todo))]))
    from tqdm import tqdm

    with ProcessPoolExecutor(max_workers=workers) as pool:
        futures = [pool.submit(_job, k, kw) for k, kw in todo]
        for f in tqdm(as_completed(futures), total=len(futures), desc=section, unit="run", mininterval=2.0):
            key, row = f.result()
            _write(out, section, {"key": key, **row})


def _conditions(arg: str) -> list[str]:
    names = [c.strip() for c in arg.split(",") if c.strip()] if arg else list(CONDITIONS)
    for c in names:
        if c not in CONDITIONS:
            raise SystemExit(f"bench_detection_world: error: --conditions: unknown condition {c!r} (known: {', '.join(CONDITIONS)})")
    return names


def failure_time(seed: int, vehicle: str, case: str, first: float) -> float:
    rng = np.random.default_rng([seed, VEHICLES.index(vehicle), CASES.index(case)])
    return float(np.round(first + rng.uniform(0.0, 1.0), 2))


def jobs_false(conditions: list[str], vehicles: list[str], hours: float, flight: float, dt: float,
               first_seed: int) -> list[tuple[str, dict[str, Any]]]:
    n = int(math.ceil(hours * 3600.0 / flight))
    return [(f"{c}/{v}/{flight:g}/{dt:g}/{s}",
             dict(vehicle=v, case=None, condition=c, health="detected", seed=s, failure_time=0.0, duration=flight, dt=dt))
            for s in range(first_seed, first_seed + n) for c in conditions for v in vehicles]


def jobs_delays(conditions: list[str], vehicles: list[str], seeds: int, first: float,
                dt: float) -> list[tuple[str, dict[str, Any]]]:
    out = []
    for s in range(seeds):
        for c in conditions:
            for v in vehicles:
                for case in CASES:
                    tf = failure_time(s, v, case, first)
                    out.append((f"{c}/{v}/{case}/{s}", dict(vehicle=v, case=case, condition=c, health="detected",
                                                             seed=100 + s, failure_time=tf, duration=tf + 3.0, dt=dt)))
    return out


def jobs_benefit(conditions: list[str], vehicles: list[str], seeds: int, first: float,
                 dt: float) -> list[tuple[str, dict[str, Any]]]:
    out = []
    for s in range(seeds):
        for c in conditions:
            for v in vehicles:
                for case in CASES:
                    for arm in ARMS:
                        out.append((f"{c}/{v}/{case}/{arm}/{s}",
                                    dict(vehicle=v, case=case, condition=c, health=arm, seed=200 + s,
                                         failure_time=first, duration=first + 7.0, dt=dt)))
    return out


def jobs_example(conditions: list[str], seeds: int) -> list[tuple[str, dict[str, Any]]]:
    from sim.blocks import DEFAULT_DT

    return [(f"{c}/{arm}/{s}", dict(vehicle="ice-seed", case="seed", condition=c, health=arm, seed=s,
                                    failure_time=0.0, duration=40.0, dt=DEFAULT_DT, frame_period=None))
            for s in range(seeds) for c in conditions for arm in ARMS]


# ---------------------------------------------------------------- report

def _rows(out: Path, section: str) -> list[dict[str, Any]]:
    import json

    path = out / f"{section}.jsonl"
    if not path.exists():
        return []
    return [json.loads(x) for x in path.read_text().splitlines() if x.strip()]


def _first_on_failed(row: dict[str, Any]) -> dict[str, Any] | None:
    for d in row["detections"]:
        if d.get("delay") is not None and d["effector"] in row["failed"] and not d.get("withdrawn"):
            return d
    return None


def report_false(rows: list[dict[str, Any]]) -> str:
    header = ["condition", "vehicle", "runs", "errors", "diverged", "hours", "false detections", "withdrawn",
              "per 10 h", "95 % interval per 10 h", "goal (< 1 per 10 h)"]
    out = []
    for c in CONDITIONS:
        for v in VEHICLES:
            sel = [r for r in rows if r.get("condition") == c and r.get("vehicle") == v]
            if not sel:
                continue
            ok = [r for r in sel if "error" not in r]
            hours = sum(r["simulated"] for r in ok) / 3600.0
            n = sum(len(r["detections"]) for r in ok)
            w = sum(len(r.get("withdrawals", [])) for r in ok)
            if hours <= 0:
                continue
            lo, hi = (10.0 * x / hours for x in poisson_interval(n))
            verdict = "met" if hi < FALSE_PER_10H_GOAL else ("not shown" if 10 * n / hours < 1 else "NOT met")
            out.append([c, v, str(len(sel)), str(len(sel) - len(ok)), str(sum(r["diverged"] for r in ok)),
                        f"{hours:.2f}", str(n), str(w), f"{10 * n / hours:.2f}", f"[{lo:.2f}, {hi:.2f}]", verdict])
    return _table(header, out)


def report_delays(rows: list[dict[str, Any]]) -> str:
    header = ["condition", "vehicle", "case", "runs", "detected", "right kind", "p50 (s)", "p95 (s)",
              "false before/elsewhere", "goal"]
    out = []
    for c in CONDITIONS:
        for v in VEHICLES:
            for case in CASES:
                sel = [r for r in rows if (r.get("condition"), r.get("vehicle"), r.get("case")) == (c, v, case)
                       and "error" not in r]
                if not sel:
                    continue
                firsts = [_first_on_failed(r) for r in sel]
                delays = np.array([d["delay"] if d else math.inf for d in firsts])
                kind = {"loe25": "effectiveness"}.get(case, case)
                right = sum(1 for d in firsts if d and (d["kind"] == kind or (case == "hardover" and d["kind"] == "jam")))
                other = sum(1 for r in sel for d in r["detections"]
                            if d.get("delay") is None or d["effector"] not in r["failed"])
                p50, p95 = (float(np.percentile(delays, q)) for q in (50, 95))
                goal_s = LOE_GOAL if case == "loe25" else JAM_P95_GOAL
                stat = p95 if case != "loe25" else float(delays.max())
                verdict = "met" if stat < goal_s else "NOT met"
                out.append([c, v, case, str(len(sel)), str(int(np.isfinite(delays).sum())), str(right),
                            f"{p50:.2f}", f"{p95:.2f}", str(other),
                            f"{verdict} ({'p95' if case != 'loe25' else 'all'} < {goal_s:g} s)"])
    return _table(header, out)


def report_benefit(rows: list[dict[str, Any]], resamples: int = 2000) -> str:
    header = ["condition", "vehicle", "case", "seeds", "blind S", "told S", "detected S", "detected/blind",
              "surviving fraction", "90 % CI", "goal"]
    out = []
    rng = np.random.default_rng(0)
    by = {(r["condition"], r["vehicle"], r["case"], r["health"], r["seed"]): r for r in rows if "error" not in r}
    for c in CONDITIONS:
        for v in VEHICLES:
            for case in CASES:
                seeds = sorted({k[4] for k in by if k[:3] == (c, v, case)
                                and all((c, v, case, a, k[4]) in by for a in ARMS)})
                if not seeds:
                    continue
                S = {a: np.array([score(by[(c, v, case, a, s)], by[(c, v, case, "blind", s)]) for s in seeds])
                     for a in ARMS}
                frac = surviving_fraction(S["blind"], S["told"], S["detected"])
                boots = []
                for _ in range(resamples):
                    i = rng.integers(len(seeds), size=len(seeds))
                    boots.append(surviving_fraction(S["blind"][i], S["told"][i], S["detected"][i]))
                boots = np.array(boots)
                boots = boots[np.isfinite(boots)]
                ci = f"[{np.percentile(boots, 5):.2f}, {np.percentile(boots, 95):.2f}]" if boots.size > 0.9 * resamples else "-"
                ratio = np.median(S["detected"] / S["blind"]) if np.isfinite(S["blind"]).all() else math.nan
                # never worse than blind beyond its interval: the detected-minus-blind mean's 90 % interval must reach 0
                diff = S["detected"] - S["blind"]
                if np.isfinite(diff).all():
                    bd = np.array([diff[rng.integers(len(seeds), size=len(seeds))].mean() for _ in range(resamples)])
                    worse = np.percentile(bd, 5) > 0
                else:
                    worse = bool(np.isinf(S["detected"]).sum() > np.isinf(S["blind"]).sum())
                told_helps = np.isfinite(frac)
                verdict = "worse than blind" if worse else ("met" if (not told_helps or frac >= BENEFIT_GOAL)
                                                            else "below 0.8 of told")
                out.append([c, v, case, str(len(seeds)),
                            *(f"{S[a].mean():.3f}" if np.isfinite(S[a]).all() else f"inf ({int(np.isinf(S[a]).sum())})"
                              for a in ARMS),
                            f"{ratio:.2f}", f"{frac:.2f}" if told_helps else "told no better", ci, verdict])
    return _table(header, out)


def report_example(rows: list[dict[str, Any]]) -> str:
    header = ["condition", "seed", "blind worst RMS after", "told", "detected", "detected/blind", "detections",
              "withdrawn", "diverged (b/t/d)", "goal (<= 1.25)"]
    out = []
    by = {(r["condition"], r["health"], r["seed"]): r for r in rows if "error" not in r}
    for c in CONDITIONS:
        for s in sorted({k[2] for k in by if k[0] == c}):
            if not all((c, a, s) in by for a in ARMS):
                continue
            worst = {a: (math.inf if by[(c, a, s)]["diverged"] else
                         max(m["rms_after"] / (by[(c, "blind", s)]["channels"][ch]["rms_after"] or 1.0)
                             for ch, m in by[(c, a, s)]["channels"].items())) for a in ARMS}
            rms = {a: "diverged" if by[(c, a, s)]["diverged"] else
                   " / ".join(f"{m['rms_after']:.2f}" for m in by[(c, a, s)]["channels"].values()) for a in ARMS}
            ratio = worst["detected"]
            out.append([c, str(s), rms["blind"], rms["told"], rms["detected"],
                        f"{ratio:.2f}" if math.isfinite(ratio) else "inf",
                        str(len(by[(c, "detected", s)]["detections"])), str(len(by[(c, "detected", s)]["withdrawals"])),
                        "/".join(str(int(by[(c, a, s)]["diverged"])) for a in ARMS),
                        "met" if ratio <= EXAMPLE_RATIO_GOAL else "NOT met"])
    return _table(header, out)


def report(out: Path, markdown: bool) -> str:
    parts = []
    machine = _rows(out, "machine")
    if machine:
        parts.append("Machine state per measurement:\n\n" + _table(
            ["section", "started (UTC)", "commit", "cpus", "load", "runs"],
            [[m["section"], m["started"], m["commit"], str(m["cpus"]), " ".join(map(str, m["load"])), m["argv"][-1]]
             for m in machine]))
    for section, fn in (("false", report_false), ("delays", report_delays), ("benefit", report_benefit),
                        ("example", report_example)):
        rows = _rows(out, section)
        if rows:
            parts.append(f"### {section}\n\n" + fn(rows))
    text = "\n\n".join(parts)
    return text if markdown else text.replace("|", " ")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run", help="fly a section (resumes what --out already holds)")
    r.add_argument("--section", choices=("false", "delays", "benefit", "example"), required=True)
    r.add_argument("--out", type=Path, required=True)
    r.add_argument("--conditions", default="", help=f"comma-separated (default all: {', '.join(CONDITIONS)})")
    r.add_argument("--vehicles", default=",".join(VEHICLES), help="comma-separated")
    r.add_argument("--hours", type=float, default=1.0, help="simulated hours per vehicle and condition (false)")
    r.add_argument("--flight", type=float, default=300.0, help="seconds per no-failure flight (false)")
    r.add_argument("--seeds", type=int, default=8, help="seeds per cell (delays, benefit, example)")
    r.add_argument("--first-seed", type=int, default=0, help="first seed of the false section")
    r.add_argument("--failure-time", type=float, default=10.0,
                   help="s of flight before the failure (delays: uniform in [F, F+1]; benefit: F)")
    r.add_argument("--dt", type=float, default=0.005, help="integration step (s) of false/delays/benefit")
    r.add_argument("--detector-model", choices=("learnt", "exact"), default="learnt",  # what these tables are about
                   help="the in-loop detector's model (sim setting detector_model); use a separate --out per model")
    r.add_argument("--workers", type=int, default=os.cpu_count() or 1, help="processes")
    p = sub.add_parser("report", help="print the tables of what finished")
    p.add_argument("--out", type=Path, required=True)
    p.add_argument("--markdown", action="store_true")
    a = ap.parse_args()
    if a.cmd == "report":
        print(report(a.out, a.markdown))
        return
    conds = _conditions(a.conditions)
    vehicles = [v.strip() for v in a.vehicles.split(",") if v.strip()]
    for v in vehicles:
        if v not in VEHICLES:
            raise SystemExit(f"bench_detection_world: error: --vehicles: unknown vehicle {v!r} (known: {', '.join(VEHICLES)})")
    if a.section == "false":
        jobs = jobs_false(conds, vehicles, a.hours, a.flight, a.dt, a.first_seed)
    elif a.section == "delays":
        jobs = jobs_delays(conds, vehicles, a.seeds, a.failure_time, a.dt)
    elif a.section == "benefit":
        jobs = jobs_benefit(conds, vehicles, a.seeds, a.failure_time, a.dt)
    else:
        jobs = jobs_example(conds, a.seeds)
    jobs = [(key, {**kw, "detector_model": a.detector_model}) for key, kw in jobs]
    _run(a.out, a.section, jobs, a.workers)
    print(report(a.out, markdown=True))


if __name__ == "__main__":
    main()
