"""Estimation, detection and identifiable allocation on a synthetic open-loop model of ICE.

Model (stated, not the simulator): ICE with mid-range preferences (``ice-mid``: the
one-sided AMT and SSD rest at 30 deg, so they can be excited both ways), 100 Hz samples;
demands ``v(t)`` are sums of three sines per axis at 0.17-1.21 Hz (alpha, p, beta axes:
peak amplitudes 2, 4, 1)
allocated by ``qp`` with rate limits (Eq 1.28), optionally with null-space excitation
(multisine, 0.1-1.5 Hz, 2 deg per effector).  The surfaces follow their commands exactly
(static actuators) except where failed; the measured response is ``y = B_eff d + e`` with
white Gaussian ``e`` of 0.7 per axis at the seed's noise (the seed's rate-noise RMS of
0.07 deg/s through its noise filter ``100 / (s^2 + 20 s + 100)`` differentiated: its
derivative's RMS is ``omega_n = 10`` times the rate's, 0.7 deg/s^2), scaled by
``--noise``.  Failures (at a random time 2-4 s, random effector, 6 s observed after it):
jam at a random position, hard-over to the upper limit at the rate limit, float (no
moment), loss of 25 % effectiveness, limits reduced to the lower 45 % of the range, rate
limits reduced to 5 % (a failure that never changes the surface's motion within the run is
counted as "no effect": nothing could detect it).

Printed: the regressor's conditioning with and without excitation and its cost; the error
of a failed column of B versus time after the failure, with and without excitation (RLS
and the frequency-domain estimator); detection delay (median, p95), missed and wrongly
isolated per kind; false alarms per simulated hour of no-failure data; per-update time
(median, p99).

    python -m benchmarks.bench_estimation [--runs 20] [--hours 1] [--noise 1,2,5] [--seed 0]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import alloc
from alloc import vehicles
from alloc.estimation import (
    EffectivenessRLS,
    FailureDetector,
    FrequencyDomainEstimator,
    NullSpaceExcitation,
    RandomWeightAllocator,
    regressor_condition,
)

DT = 0.01
SEED_NOISE = 0.7
KINDS = ("jam", "hardover", "float", "effectiveness", "limits", "rate_limits")


#: demand tones (Hz) per axis: within the frequency-domain band, as a pilot's inputs are
TONES = ((0.17, 0.41, 0.83), (0.23, 0.53, 1.07), (0.29, 0.67, 1.21))
AMPLITUDES = (2.0, 4.0, 1.0)


def demands(n: int, phase: float = 0.0) -> np.ndarray:
    t = np.arange(n) * DT
    return np.column_stack([a / 3 * sum(np.sin(2 * np.pi * f * t + phase * (i + 1) + k) for k, f in enumerate(fs))
                            for i, (a, fs) in enumerate(zip(AMPLITUDES, TONES))])


def commands(p: alloc.Problem, n: int, excite: bool, seed: int, phase: float = 0.0,
             method: str = "qp") -> tuple[np.ndarray, np.ndarray, list[float], np.ndarray]:
    """Rate-limited allocations of the demands, unexcited (``U0``) and excited (``U``); the factors
    tau; and ``Ubase``, the unexcited allocation at the excited run's previous command (what
    the excitation adds to each call, its cost).

    The two are separate runs, each fed its own previous command: an unexcited allocation fed the
    excited run's previous command inherits the excitation through the rate limits, and its
    regressor looks far better conditioned than a truly unexcited flight's."""
    a = alloc.make_allocator(p, method)
    ex = NullSpaceExcitation(a, DT, amplitude=2.0, seed=seed) if excite else None
    U0, U, Ubase, taus, u_prev, u_prev0 = [], [], [], [], p.up.copy(), p.up.copy()
    for v in demands(n, phase):
        r0 = a(v, u_prev=u_prev0, dt=DT)
        if ex is not None:
            r = ex(v, u_prev=u_prev, dt=DT)
            Ubase.append(a(v, u_prev=u_prev, dt=DT).u)
        else:
            r = r0
            Ubase.append(r0.u)
        U0.append(r0.u)
        U.append(r.u)
        taus.append(ex.last_scale if ex is not None else 0.0)
        u_prev, u_prev0 = r.u, r0.u
    return np.array(U0), np.array(U), taus, np.array(Ubase)


def fail(p: alloc.Problem, U: np.ndarray, kind: str, j: int, i0: int, rng: np.random.Generator) -> tuple:
    """Surface positions and the effective B per sample after a failure at sample ``i0``."""
    D = U.copy()
    f = np.ones(len(U))
    lo, hi, rate = p.umin[j], p.umax[j], p.rate_max[j]
    if kind == "jam":
        D[i0:, j] = rng.uniform(lo, hi)
    elif kind == "hardover":
        for i in range(i0, len(U)):
            D[i, j] = min(hi, D[i - 1, j] + rate * DT)
    elif kind == "float":
        f[i0:] = 0.0
    elif kind == "effectiveness":
        f[i0:] = 0.75
    elif kind == "limits":
        D[i0:, j] = np.minimum(D[i0:, j], lo + 0.45 * (hi - lo))
    elif kind == "rate_limits":
        r = 0.05 * rate
        for i in range(i0, len(U)):
            D[i, j] = D[i - 1, j] + np.clip(U[i, j] - D[i - 1, j], -r * DT, r * DT)
    return D, f


def responses(p: alloc.Problem, D: np.ndarray, f: np.ndarray, j: int, sigma: float,
              rng: np.random.Generator) -> np.ndarray:
    Y = D @ p.B.T
    Y += np.outer((f - 1.0) * D[:, j], p.B[:, j])
    return Y + rng.normal(size=Y.shape) * sigma


def conditioning(p: alloc.Problem) -> None:
    print("## Regressor conditioning, 20 s at 100 Hz (columns scaled by half their range)\n")
    print("| allocation | condition | excitation RMS (deg) | max abs(B u - B u0) | median tau |")
    print("|---|---|---|---|---|")
    scale = (p.umax - p.umin) / 2
    for method in ("qp", "wls", "pinv"):
        U0, U, taus, Ubase = commands(p, 2000, True, 1, method=method)
        act = float(np.sqrt(((U - Ubase) ** 2).mean()))
        dBu = float(np.abs((U - Ubase) @ p.B.T).max())
        print(f"| {method} | {regressor_condition(U0, scale):.2e} | - | - | - |")
        print(f"| {method} + null-space multisine 2 deg | {regressor_condition(U, scale):.2e} | {act:.2f} | "
              f"{dBu:.1e} | {np.median(taus):.2f} |")
    rw = RandomWeightAllocator(p, "pinv", spread=4.0, n_weights=8, dwell=25, seed=3)
    a = alloc.make_allocator(p, "pinv")
    V = demands(2000)
    U0 = np.array([a(v).u for v in V])
    U = np.array([rw(v).u for v in V])
    print(f"| pinv + random weights (seed 1.3.2.5; spread 4, dwell 0.25 s) | {regressor_condition(U, scale):.2e} | "
          f"{np.sqrt(((U - U0) ** 2).mean()):.2f} | {np.abs((U - U0) @ p.B.T).max():.1e} | - |\n")


def column_error(p: alloc.Problem, seed: int) -> None:
    """A 50 % loss of elevon_l at 10 s: relative error of its column versus time."""
    print("## Column error after a failure (elevon_l effectiveness 0.5 at t = 10 s), seed noise\n")
    j = p.index("elevon_l")
    times = (-0.01, 0.5, 1.0, 2.0, 5.0, 10.0)
    print("| estimator | " + " | ".join(f"t - 10 = {t:g} s" for t in times) + " |")
    print("|---" * (len(times) + 1) + "|")
    n, i0 = 2001, 1000
    b = p.B[:, j]
    for excite in (False, True):
        rng = np.random.default_rng(seed)
        _, U, _, _ = commands(p, n, excite, seed)
        D, f = U.copy(), np.ones(n)
        f[i0:] = 0.5
        Y = responses(p, D, f, j, SEED_NOISE, rng)
        rls = EffectivenessRLS(p.B, prior_std=0.5, noise_std=SEED_NOISE, forgetting=0.99, penalty=1.0)
        fde = FrequencyDomainEstimator(p.k, p.m, DT, band=(0.2, 2.0), spacing=0.1, window=6.0, noise_std=SEED_NOISE)
        err_r, err_f, sd_r, sd_f = {}, {}, {}, {}
        for i in range(n):
            rls.update(D[i], Y[i])
            fde.update(D[i], Y[i])
            t = (i - i0) * DT
            for tt in times:
                if abs(t - tt) < DT / 2:
                    truth = b * f[i]
                    norm = np.linalg.norm(truth)
                    err_r[tt] = np.linalg.norm(rls.B[:, j] - truth) / norm
                    sd_r[tt] = np.linalg.norm(rls.B_std[:, j]) / norm
                    e = fde.estimate()
                    ok = np.isfinite(e.std[:, j]).all()
                    err_f[tt] = np.linalg.norm(e.theta[:, j] - truth) / norm if ok else float("nan")
                    sd_f[tt] = np.linalg.norm(e.std[:, j]) / norm if ok else float("nan")
        label = "with excitation" if excite else "without excitation"
        print(f"| RLS (lambda 0.99), {label} | " + " | ".join(f"{err_r[t]:.3f} ({sd_r[t]:.3f})" for t in times)
              + " |")
        print(f"| frequency domain (6 s window), {label} | "
              + " | ".join(f"{err_f[t]:.3f} ({sd_f[t]:.3f})" for t in times) + " |")
    print("\n(relative error of the column (its stated 1-sigma, relative); nan: not identifiable from the data)\n")


def detection(p: alloc.Problem, runs: int, noise: float, seed: int) -> None:
    sigma = SEED_NOISE * noise
    print(f"## Detection, noise x{noise:g} (sigma {sigma:g} per axis), {runs} runs per kind, design 0.1 false "
          "alarms per hour\n")
    print("| kind | isolated | kind right first | kind right finally | missed | no effect | wrong effector | "
          "delay median (s) | delay p95 (s) |")
    print("|---|---|---|---|---|---|---|---|---|")
    n = 1000
    base = {}
    for kind in KINDS:
        delays, kind_ok, final_ok, missed, no_effect, wrong = [], 0, 0, 0, 0, 0
        for r in range(runs):
            rng = np.random.default_rng(seed + 7919 * r + KINDS.index(kind))
            phase = float(rng.uniform(0, 2 * np.pi))
            key = round(phase, 6)
            if key not in base:
                base[key] = commands(p, n, True, r, phase)[1]
            U = base[key]
            j = int(rng.integers(p.m))
            i0 = int(rng.integers(200, 400))
            D, f = fail(p, U, kind, j, i0, rng)
            Y = responses(p, D, f, j, sigma, rng)
            det = FailureDetector(p, sigma, DT, false_alarm_rate=0.1)
            first = None
            for i in range(n):
                for d in det.update(U[i], Y[i]):
                    if first is None:
                        first = d
            effect = np.abs(D - U).max() > 1e-9 or (f != 1).any()
            h = det.health.get(p.names[j])
            final_ok += h is not None and _believes(h, kind)
            if first is None:
                missed += effect
                no_effect += not effect
            elif first.event.effector != p.names[j]:
                wrong += 1
            else:
                delays.append(first.time - i0 * DT)
                kind_ok += first.event.kind.value == kind
        med = f"{np.median(delays):.2f}" if delays else "-"
        p95 = f"{np.percentile(delays, 95):.2f}" if delays else "-"
        print(f"| {kind} | {len(delays)}/{runs} | {kind_ok}/{runs} | {final_ok}/{runs} | {missed} | {no_effect} | "
              f"{wrong} | {med} | {p95} |")
    print()


def _believes(h: alloc.EffectorHealth, kind: str) -> bool:
    """Whether a detector's final health of an effector is a failure of ``kind``."""
    return {"jam": h.jam_position is not None, "hardover": h.jam_position is not None, "float": h.floating,
            "effectiveness": h.effectiveness < 1.0 and not h.floating, "limits": h.limits is not None,
            "rate_limits": h.rate_limits is not None}[kind]


def false_alarms(p: alloc.Problem, hours: float, seed: int) -> None:
    rng = np.random.default_rng(seed)
    U = commands(p, 6000, True, seed)[1]  # one minute of commands, repeated with fresh noise
    n = int(hours * 3600 / DT)
    det = FailureDetector(p, SEED_NOISE, DT, false_alarm_rate=0.1)
    found = 0
    block = 6000
    for start in range(0, n, block):
        Y = U @ p.B.T + rng.normal(size=(len(U), p.k)) * SEED_NOISE
        for i in range(min(block, n - start)):
            found += len(det.update(U[i], Y[i]))
    print(f"## False alarms: {hours:g} simulated hours without failure, seed noise, design 0.1 per hour\n")
    print(f"detections {found}, stage-1 alarms {det.alarm_count} ({det.alarm_count / hours:.2f} per hour; "
          f"design at most 0.1 per hour; the overlapping default tests alarm less than the bound)\n")


def timing(p: alloc.Problem, seed: int) -> None:
    rng = np.random.default_rng(seed)
    _, U, _, _ = commands(p, 3000, True, seed)
    Y = U @ p.B.T + rng.normal(size=(len(U), p.k)) * SEED_NOISE
    rls = EffectivenessRLS(p.B, noise_std=SEED_NOISE)
    fde = FrequencyDomainEstimator(p.k, p.m, DT, band=(0.2, 2.0), spacing=0.1, window=6.0, noise_std=SEED_NOISE)
    det = FailureDetector(p, SEED_NOISE, DT)
    a = alloc.make_allocator(p, "qp")
    ex = NullSpaceExcitation(a, DT, amplitude=2.0)
    V = demands(3000)
    rows = []
    for name, step in (("EffectivenessRLS.update", lambda i: rls.update(U[i], Y[i])),
                       ("FrequencyDomainEstimator.update", lambda i: fde.update(U[i], Y[i])),
                       ("FailureDetector.update", lambda i: det.update(U[i], Y[i])),
                       ("qp allocation", lambda i: a(V[i])),
                       ("qp + NullSpaceExcitation", lambda i: ex(V[i]))):
        ts = []
        for i in range(3000):
            t0 = time.perf_counter()
            step(i)
            ts.append(time.perf_counter() - t0)
        rows.append((name, np.median(ts) * 1e6, np.percentile(ts, 99) * 1e6))
    t0 = time.perf_counter()
    for _ in range(20):
        fde.estimate()
    rows.append(("FrequencyDomainEstimator.estimate", (time.perf_counter() - t0) / 20 * 1e6, float("nan")))
    print("## Per-update time (ICE, 3 x 11; microseconds)\n")
    print("| step | median | p99 |")
    print("|---|---|---|")
    for name, med, p99 in rows:
        print(f"| {name} | {med:.0f} | {p99:.0f} |")
    print()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=20, help="runs per failure kind")
    ap.add_argument("--hours", type=float, default=1.0, help="simulated hours of no-failure data")
    ap.add_argument("--noise", default="1,2,5", help="noise scales of the seed's (comma-separated)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--only", default="", help="comma-separated sections: cond,column,detect,false,time")
    args = ap.parse_args()
    only = set(filter(None, args.only.split(",")))
    p = vehicles.problem("ice-mid")
    if not only or "cond" in only:
        conditioning(p)
    if not only or "column" in only:
        column_error(p, args.seed)
    if not only or "detect" in only:
        for scale in (float(s) for s in args.noise.split(",")):
            detection(p, args.runs, scale, args.seed)
    if not only or "false" in only:
        false_alarms(p, args.hours, args.seed)
    if not only or "time" in only:
        timing(p, args.seed)


if __name__ == "__main__":
    main()
