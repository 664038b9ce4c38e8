"""The seed-claim table: every figure of the seed the project reproduces or fails to, measured.

Each :class:`Claim` names a figure (or a printed claim) of the seed, what the seed says of it,
the run that measures it (the same settings as the test named in ``test``), the criterion that
decides "reproduced", and the free parameters the result depends on.  ``measure`` flies the runs
and writes every measured number to a CSV (``figure, quantity, value``); ``page`` renders
``docs/seed-claims.md`` from that CSV, the verdicts computed from the numbers by each claim's
criterion.  For the claims that are one run of the one-factor sensitivity sweep
(``benchmarks/bench_sensitivity.py``), the "depends on" column adds the choices whose change
flips that run's verdict, read from the sweep's committed ``runs*.csv``.

    python -m benchmarks.seed_claims measure --csv benchmarks/reference/seed-claims-2026-12-02.csv
    python -m benchmarks.seed_claims page --csv benchmarks/reference/seed-claims-2026-12-02.csv
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse
import csv
import sys
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from benchmarks import bench_sensitivity

Numbers = dict[str, float]

REFERENCE = Path(__file__).resolve().parent / "reference" / "seed-claims-2026-12-02.csv"
PAGE = Path(__file__).resolve().parents[1] / "docs" / "seed-claims.md"


@dataclass(frozen=True)
class Claim:
    """One figure or printed claim of the seed and how the project measures it."""

    figure: str
    seed_says: str
    criterion: str
    #: flies the runs (None: not implemented, ``test`` says why)
    measure: Callable[[], Numbers] | None
    verdict: Callable[[Mapping[str, float]], str]
    free: str
    test: str
    #: (scenario, case, method) of the sensitivity sweep run this claim is
    sweep_run: tuple[str, str, str] | None = None


def _scenario(name: str) -> Callable[..., object]:
    from sim.scenarios import get_scenario

    return get_scenario(name)


def _window(r: object, t0: float, t1: float) -> np.ndarray:
    return (r.t >= t0) & (r.t < t1)


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(x**2)))


def _crossings(r: object, t0: float, t1: float) -> int:
    s = r.extra["sigma"][_window(r, t0, t1)]
    return int(np.count_nonzero(np.diff(np.sign(s)) != 0))


def _yes(flag: bool) -> str:
    return "reproduced" if flag else "not reproduced"


# ------------------------------------------------------------------ pendulum (seed chapters 2, 3.1)


def _fig_2_15() -> Numbers:
    run = _scenario("pendulum")
    kw = dict(controller="smc", equivalent_control=True, switching_until=0.15, rho=50.0, epsilon=0.1)
    lin, non = run(model="linear", **kw), run(model="nonlinear", **kw)
    return {"linear max |sigma| after 1 s": float(np.max(np.abs(lin.extra["sigma"][lin.t > 1.0]))),
            "nonlinear max |sigma| after 1 s": float(np.max(np.abs(non.extra["sigma"][non.t > 1.0]))),
            "nonlinear max |state| after 5 s": float(np.max(np.abs(non.output[non.t > 5.0]))),
            "nonlinear diverged": float(non.diverged)}


def _fig_2_15_verdict(m: Mapping[str, float]) -> str:
    if m["linear max |sigma| after 1 s"] < 1e-6 and m["nonlinear max |state| after 5 s"] > 0.05:
        return "reproduced as 'no longer regulated'" if not m["nonlinear diverged"] else "reproduced"
    return "not reproduced"


def _fig_2_19() -> Numbers:
    run = _scenario("pendulum")
    kw = dict(model="nonlinear", disturbance_bias=10.0, noise_std=1.0, seed=3)
    lqr = run(controller="lqr", **kw)
    smc = run(controller="smc", equivalent_control=True, rho=50.0, epsilon=0.1, **kw)
    return {"LQR mean x 8-10 s (m)": float(lqr.output[lqr.t >= 8.0, 0].mean()),
            "SMC mean x 8-10 s (m)": float(smc.output[smc.t >= 8.0, 0].mean())}


def _pendulum_actuator_runs() -> dict[str, object]:
    from sim.scenarios.pendulum import ACTUATOR_CASES

    run = _scenario("pendulum")
    return {name: run(actuator_bandwidth=a, duration=10.0) for name, a in ACTUATOR_CASES.items()}


def _fig_3_1() -> Numbers:
    r = _pendulum_actuator_runs()["none"]
    late = _window(r, 5.0, 10.0)
    return {"RMS x 5-10 s (m)": _rms(r.output[late, 0]), "RMS theta 5-10 s (rad)": _rms(r.output[late, 1]),
            "sigma zero crossings 0.5-1 s": float(_crossings(r, 0.5, 1.0))}


def _fig_3_2() -> Numbers:
    r = _pendulum_actuator_runs()["actuator_20"]
    return {"force peak to peak 0.5-1 s (N)": float(np.ptp(r.effectors[_window(r, 0.5, 1.0), 0])),
            "sigma zero crossings 0.5-1 s": float(_crossings(r, 0.5, 1.0)),
            "RMS theta 5-10 s (rad)": _rms(r.output[_window(r, 5.0, 10.0), 1]), "diverged": float(r.diverged)}


def _fig_3_3() -> Numbers:
    r = _pendulum_actuator_runs()["actuator_13"]
    return {"diverged": float(r.diverged), "time of divergence (s)": r.duration}


# ------------------------------------------------------------------ F-16 (seed section 3.2.1)


def _f16(name: str) -> object:
    from sim.scenarios.f16 import SEED_CASES

    return _scenario("f16")(**SEED_CASES[name])


def _f16_numbers(name: str) -> Numbers:
    r = _f16(name)
    q = r.summary()["channels"]["q"]
    return {"diverged": float(r.diverged), "max error (rad/s)": float(np.max(np.abs(r.error))),
            "max error after failure (rad/s)": float(q["max_after"] if q["max_after"] is not None else np.nan),
            "position saturation (s)": r.time_in_position_saturation,
            "rate saturation (s)": r.time_in_rate_saturation}


# ------------------------------------------------------------------ DC-8 (seed section 3.2.2)


def _fig_3_18() -> Numbers:
    run = _scenario("dc8")
    kw = dict(duration=30.0, failure_time=10.0)
    healthy, failed = run(**kw), run(failure="aileron_and_stability", **kw)
    after = healthy.t >= 10.0
    return {"max bank difference after failure (rad)":
            float(np.max(np.abs(failed.output[after, 0] - healthy.output[after, 0]))),
            "aileron max ratio failed / healthy":
            float(np.max(np.abs(failed.effectors[after, 0])) / np.max(np.abs(healthy.effectors[after, 0]))),
            "diverged": float(healthy.diverged or failed.diverged)}


# ------------------------------------------------------------------ HARV (seed sections 4.5, 4.6)


def _harv_lon(**options: object) -> Numbers:
    r = _scenario("harv_lon")(method="ganging", **options)
    q = r.summary()["channels"]["q"]
    return {"diverged": float(r.diverged), "q RMS before (deg/s)": q["rms_before"],
            **({"q RMS after (deg/s)": q["rms_after"]} if q["rms_after"] is not None else {})}


def _harv_latdir_failure1(controller: str) -> Numbers:
    r = _scenario("harv_latdir")(method="ganging", failure="failure1", failure_time=10.0, duration=20.0,
                                 controller=controller)
    ch = r.summary()["channels"]
    return {"diverged": float(r.diverged), "ps RMS after (deg/s)": ch["ps"]["rms_after"],
            "beta max after (deg)": ch["beta"]["max_after"]}


def _fig_4_75() -> Numbers:
    loop = _harv_latdir_failure1("loopshape")
    return {**loop, "SMC ps RMS after (deg/s)": _harv_latdir_failure1("smc")["ps RMS after (deg/s)"]}


def _fig_4_81() -> Numbers:
    run = _scenario("harv_latdir_failure2")
    out: Numbers = {}
    for method in ("ganging", "static"):
        r = run(method=method)
        e = r.extra["phi_command"] - r.extra["phi"]
        out[f"{method} diverged"] = float(r.diverged)
        out[f"{method} time of divergence (s)"] = r.duration
        out[f"{method} phi error RMS (deg)"] = _rms(e)
    nominal = run(failure=None)
    out["nominal phi error RMS (deg)"] = _rms(nominal.extra["phi_command"] - nominal.extra["phi"])
    return out


# ------------------------------------------------------------------ ICE (seed section 4.7)


def _fig_4_95() -> Numbers:
    r = _scenario("ice")(method="static", observer=False, hedge=False, noise=False, duration=5.0)
    return {"diverged": float(r.diverged), "time of divergence (s)": r.duration}


def _fig_4_110() -> Numbers:
    run = _scenario("ice")
    full = run(method="static", failure="seed", duration=40.0)
    quiet = run(method="static", failure="seed", failure_time=5.0, duration=15.0, noise=False, pilot_gain=1.0)
    return {"seed run diverged": float(full.diverged), "seed run time of divergence (s)": full.duration,
            "noise-free gain-1 run diverged": float(quiet.diverged),
            "noise-free gain-1 alpha max after (deg)": quiet.summary()["channels"]["alphaw"]["max_after"]}


def _fig_4_110_verdict(m: Mapping[str, float]) -> str:
    if not m["seed run diverged"]:
        return "reproduced"
    return "not reproduced (reproduced noise-free at pilot gain 1)" if not m["noise-free gain-1 run diverged"] \
        else "not reproduced"


def _fig_4_119() -> Numbers:
    r = _scenario("ice")(method="static", controller="loopshape", failure="seed", failure_time=5.0, duration=20.0,
                         noise=False)
    return {"diverged": float(r.diverged), "time of divergence (s)": r.duration,
            "alpha RMS before (deg)": r.summary()["channels"]["alphaw"]["rms_before"]}


_MIMO_FREE = "pilot model and gain, divergence bound, noise seed"

CLAIMS: tuple[Claim, ...] = (
    Claim("Figs 2-21 to 2-25", "the two-input decoupled SMC of the pendulum through the section 2.2 plant change",
          "", None, lambda m: "not implemented", "", "not implemented (tests/sim/test_classic.py::"
          "test_pendulum_plant_change_switches_the_plant_at_failure_time flies the plant change on the "
          "single-input regulator instead)"),
    Claim("Fig 2-15", "equivalent control alone keeps sliding on the linear model; on the nonlinear simulation "
          "\"stable control is lost\"", "linear |sigma| < 1e-6 after 1 s and nonlinear |state| > 0.05 after 5 s",
          _fig_2_15, _fig_2_15_verdict, "0.15 s reaching phase (seed), rho 50, eps 0.1",
          "tests/sim/test_classic.py::test_pendulum_equivalent_control_holds_the_surface_only_on_the_design_model"),
    Claim("Figs 2-19/2-20", "LQR shows \"a noticeable bias\" under a 10 N force bias; SMC regulation \"very good\"",
          "|LQR mean x| > 10 |SMC mean x| and |SMC mean x| < 0.02 m", _fig_2_19,
          lambda m: _yes(abs(m["LQR mean x 8-10 s (m)"]) > 10 * abs(m["SMC mean x 8-10 s (m)"])
                         and abs(m["SMC mean x 8-10 s (m)"]) < 0.02),
          "noise std 1 N and seed 3 (ours: the seed prints no noise level)",
          "tests/sim/test_classic.py::test_pendulum_matched_disturbance_rejected_by_smc_not_lqr"),
    Claim("Fig 3-1", "\"excellent regulation of the states\" (no actuator)", "RMS x and theta over 5-10 s < 1e-4",
          _fig_3_1, lambda m: _yes(m["RMS x 5-10 s (m)"] < 1e-4 and m["RMS theta 5-10 s (rad)"] < 1e-4),
          "none", "tests/sim/test_classic.py::test_pendulum_smc_regulates_without_actuator"),
    Claim("Fig 3-2", "actuator 20/(s+20): \"Already, undesired oscillations appear\"",
          ">= 10 sigma zero crossings in 0.5-1 s (the oscillation; it decays, which the figure cannot confirm)",
          _fig_3_2, lambda m: _yes(m["sigma zero crossings 0.5-1 s"] >= 10 and not m["diverged"]), "none",
          "tests/sim/test_classic.py::test_pendulum_smc_oscillates_with_20_rad_s_actuator"),
    Claim("Fig 3-3", "actuator 13/(s+13): \"it drives both states unstable\"", "diverged (|theta| > 90 deg)",
          _fig_3_3, lambda m: _yes(bool(m["diverged"])), "divergence bound 90 deg (ours)",
          "tests/sim/test_classic.py::test_pendulum_smc_diverges_with_13_rad_s_actuator"),
    *(Claim(fig, "no limits: \"excellent tracking\"" + (" through the 5 s tail loss" if fig == "Fig 3-8" else ""),
            "bounded, max |q_r - q| < 0.02 rad/s", (lambda n=name: _f16_numbers(n)),
            lambda m: _yes(not m["diverged"] and m["max error (rad/s)"] < 0.02), "pulse amplitude 0.1 rad/s (seed)",
            "tests/sim/test_classic.py::test_f16_tracks_without_limits")
      for fig, name in (("Fig 3-7", "fig_3_7"), ("Fig 3-8", "fig_3_8"))),
    Claim("Fig 3-9", "\"some minor rate limiting occurs, but the position limit is never reached\"",
          "rate saturation > 0 s, position saturation 0 s", lambda: _f16_numbers("fig_3_9"),
          lambda m: _yes(m["rate saturation (s)"] > 0 and m["position saturation (s)"] == 0), "none",
          "tests/sim/test_classic.py::test_f16_small_pulses_rate_limit_but_no_position_limit"),
    Claim("Fig 3-10", "static layer, 0.2 rad/s pulses: \"no longer tracks the input and it becomes unstable\"",
          "diverged", lambda: _f16_numbers("fig_3_10"), lambda m: _yes(bool(m["diverged"])),
          "actuator integrator clamped at the limit (ours; output saturation measured the same)",
          "tests/sim/test_classic.py::test_f16_static_layer_loses_control_as_in_seed (strict xfail)"),
    Claim("Fig 3-11", "dynamic layer (Eqs 3.6-3.8) \"keeps the system stable\", tracking degraded somewhat",
          "bounded, no position saturation", lambda: _f16_numbers("fig_3_11"),
          lambda m: _yes(not m["diverged"] and m["position saturation (s)"] == 0), "none",
          "tests/sim/test_classic.py::test_f16_dynamic_layer_keeps_control_within_limits"),
    Claim("Fig 3-12", "actuator and Eq 3.7 design both 10 rad/s: \"comparable to the last case\"",
          "bounded, no position saturation", lambda: _f16_numbers("fig_3_12"),
          lambda m: _yes(not m["diverged"] and m["position saturation (s)"] == 0), "none",
          "tests/sim/test_classic.py::test_f16_dynamic_layer_with_known_slow_actuator"),
    Claim("Fig 3-13", "true actuator 10 rad/s, Eq 3.7 designed for 20: \"The system fails\"", "diverged",
          lambda: _f16_numbers("fig_3_13"), lambda m: _yes(bool(m["diverged"])), "none",
          "tests/sim/test_classic.py::test_f16_unknown_slow_actuator_fails_as_in_seed (strict xfail)"),
    Claim("Fig 3-18", "DC-8: \"no difference in the tracking performance\" between failed and un-failed",
          "bank angles of the two runs within 1e-3 rad after the failure",
          _fig_3_18, lambda m: _yes(m["max bank difference after failure (rad)"] < 1e-3 and not m["diverged"]),
          "0.2 rad square-wave bank command, period 20 s (ours: not printed); failure at 10 s (seed: 40 s)",
          "tests/sim/test_classic.py::test_dc8_tracking_is_invariant_to_the_failure"),
    Claim("Fig 4-11", "HARV lon SMC without observer, actuators in the loop: unstable",
          "q RMS > 20 deg/s in 3 s", lambda: _harv_lon(observer=False, hedge=False, noise=False, duration=3.0),
          lambda m: _yes(m["q RMS before (deg/s)"] > 20.0), "none",
          "tests/sim/test_harv.py::test_lon_smc_without_observer_is_unstable_with_actuators_fig_4_11"),
    Claim("Fig 4-32", "HARV lon Failure #2: SMC (modified observer/hedge design) survives",
          "bounded, q RMS after < 5 deg/s", lambda: _harv_lon(failure="failure2", duration=20.0),
          lambda m: _yes(not m["diverged"] and m["q RMS after (deg/s)"] < 5.0), _MIMO_FREE + "; 20 s (seed: longer)",
          "tests/sim/test_harv.py::test_lon_smc_with_hedging_survives_failure_2_fig_4_32"),
    Claim("Fig 4-39", "HARV lon Failure #2: the loop-shaped baseline fails",
          "diverged or q RMS after > 10 deg/s", lambda: _harv_lon(failure="failure2", duration=20.0,
                                                                  controller="loopshape"),
          lambda m: _yes(bool(m["diverged"]) or m["q RMS after (deg/s)"] > 10.0), _MIMO_FREE + "; 20 s",
          "tests/sim/test_harv.py::test_lon_loop_shaped_fails_under_failure_2_fig_4_39 (strict xfail)"),
    Claim("Fig 4-67", "HARV lat-dir Failure #1: SMC survives, beta excursions about 1 deg",
          "bounded, ps RMS after < 5 deg/s, beta max after < 2 deg", lambda: _harv_latdir_failure1("smc"),
          lambda m: _yes(not m["diverged"] and m["ps RMS after (deg/s)"] < 5.0 and m["beta max after (deg)"] < 2.0),
          _MIMO_FREE + "; failure at 10 s, 20 s", "tests/sim/test_harv.py::"
          "test_latdir_smc_survives_failure_1_loop_shaped_does_not"),
    Claim("Fig 4-75", "HARV lat-dir Failure #1: the loop-shaped baseline is unstable",
          "diverged or ps RMS after > 5 x the SMC's", _fig_4_75,
          lambda m: _yes(bool(m["diverged"]) or m["ps RMS after (deg/s)"] > 5.0 * m["SMC ps RMS after (deg/s)"]),
          _MIMO_FREE + "; failure at 10 s, 20 s", "tests/sim/test_harv.py::"
          "test_latdir_smc_survives_failure_1_loop_shaped_does_not"),
    Claim("Fig 4-81", "HARV lat-dir Failure #2, filtered bank steps: SMC tracks as well as the reconfigured QFT",
          "ganging bounded, phi error RMS < 10 deg", _fig_4_81,
          lambda m: _yes(not m["ganging diverged"] and m["ganging phi error RMS (deg)"] < 10.0),
          "Fig 4-81 step sizes and times (ours), " + _MIMO_FREE,
          "tests/sim/test_harv.py::test_latdir_smc_tracks_failure2_fig_4_81 (strict xfail)",
          sweep_run=("harv_latdir", "failed", "static")),
    Claim("Fig 4-95", "ICE SMC without observer, actuators in the loop: unstable", "diverged within 4 s",
          _fig_4_95, lambda m: _yes(bool(m["diverged"]) and m["time of divergence (s)"] < 4.0),
          "divergence bound ICE", "tests/sim/test_ice.py::test_no_observer_diverges_fig_4_95"),
    Claim("Fig 4-110", "ICE, Table 4-6 observers and hedges: stable through the t = 20 s failure",
          "the seed's 40 s run with noise stays bounded", _fig_4_110, _fig_4_110_verdict,
          "ICE alpha pilot (none), " + _MIMO_FREE,
          "tests/sim/test_ice.py::test_full_seed_run_with_noise_stays_bounded (slow, strict xfail)",
          sweep_run=("ice", "failed", "static")),
    Claim("Fig 4-119", "ICE, Eq 4.28 loop-shaped baseline: diverges after the failure",
          "diverged after the failure (5 s here)", _fig_4_119,
          lambda m: _yes(bool(m["diverged"]) and m["time of divergence (s)"] > 5.0), "divergence bound ICE",
          "tests/sim/test_ice.py::test_loop_shaped_baseline_diverges_after_failure_fig_4_119"),
)


def measure(claims: tuple[Claim, ...] = CLAIMS) -> list[dict[str, str]]:
    """Fly every claim's runs: rows ``figure, quantity, value`` (values with 6 significant digits)."""
    rows = []
    for claim in claims:
        if claim.measure is None:
            continue
        start = time.process_time()
        numbers = claim.measure()
        print(f"{claim.figure}: {time.process_time() - start:.1f} s CPU", file=sys.stderr, flush=True)
        rows += [{"figure": claim.figure, "quantity": q, "value": f"{v:.6g}"} for q, v in numbers.items()]
    return rows


def read_measured(path: Path = REFERENCE) -> dict[str, dict[str, float]]:
    with path.open(newline="") as fh:
        out: dict[str, dict[str, float]] = {}
        for r in csv.DictReader(fh):
            out.setdefault(r["figure"], {})[r["quantity"]] = float(r["value"])
    return out


def _measured_text(numbers: Mapping[str, float]) -> str:
    def text(q: str, v: float) -> str:
        if q.endswith("diverged"):
            return f"{q}: {'yes' if v else 'no'}"
        return f"{q} {v:.3g}"
    return "; ".join(text(q, v) for q, v in numbers.items())


def _flipping_choices(sweep: Path, run: tuple[str, str, str]) -> str:
    """The sweep's factor levels that flip this run's verdict (2000 Hz base)."""
    flips = [r for r in bench_sensitivity.flips(bench_sensitivity.all_runs(sweep)) if r["base"] == "2000 Hz"]
    prefix = " ".join(run) + ":"
    hits = [f"{r['factor']} = {r['level']}" for r in flips
            if any(part.strip().startswith(prefix) for part in str(r["flipped"]).split(";"))]
    return "flips with " + ", ".join(hits) if hits else "no one-factor change flips it"


def render(measured: Mapping[str, Mapping[str, float]], csv_name: str,
           sweep: Path = bench_sensitivity.REFERENCE) -> str:
    """``docs/seed-claims.md`` from the measured numbers."""
    lines = ["# What the seed shows and what we measure", "",
             f"Generated by `python -m benchmarks.seed_claims page` from `{csv_name}` (written by "
             "`python -m benchmarks.seed_claims measure`); a test checks this page against it. Each row is one "
             "figure the tests or benchmarks touch; \"reproduced\" is decided by the criterion column, applied "
             "to the measured numbers, with the settings of the test named in the last column. \"Depends on\" "
             "lists the free parameters the result rests on; for the rows that are a run of the one-factor "
             f"sensitivity sweep (`{sweep.relative_to(PAGE.parents[1]).as_posix()}`, static, 40 s) it adds the "
             "choices whose change flips the verdict.", "",
             "| figure | seed says | we measured | criterion | verdict | depends on | test |",
             "|---|---|---|---|---|---|---|"]
    for c in CLAIMS:
        numbers = measured.get(c.figure)
        if c.measure is None:
            cells = [c.figure, c.seed_says, "", c.criterion, c.verdict({}), c.free, c.test]
        elif numbers is None:
            cells = [c.figure, c.seed_says, "not measured", c.criterion, "not measured", c.free, c.test]
        else:
            free = c.free + ("; " + _flipping_choices(sweep, c.sweep_run) if c.sweep_run else "")
            cells = [c.figure, c.seed_says, _measured_text(numbers), c.criterion, c.verdict(numbers), free, c.test]
        lines.append("| " + " | ".join(x.replace("|", "\\|") for x in cells) + " |")
    verdicts = [c.verdict(measured[c.figure]) for c in CLAIMS if c.measure is not None and c.figure in measured]
    reproduced = sum(v.startswith("reproduced") for v in verdicts)
    lines += ["", f"Of {len(CLAIMS)} rows: {reproduced} reproduced, {len(verdicts) - reproduced} not reproduced, "
              f"{sum(c.measure is None for c in CLAIMS)} not implemented."]
    return "\n".join(lines) + "\n"


def page(path: Path = REFERENCE) -> str:
    return render(read_measured(path), path.relative_to(PAGE.parents[1]).as_posix())


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="seed_claims", description=__doc__.split("\n")[0])
    parser.add_argument("command", choices=("measure", "page"))
    parser.add_argument("--csv", type=Path, default=REFERENCE)
    parser.add_argument("--only", nargs="*", default=None, help="figures (\"Fig 3-1\" ...)")
    args = parser.parse_args(argv)
    if args.command == "measure":
        claims = CLAIMS if args.only is None else tuple(c for c in CLAIMS if c.figure in args.only)
        rows = measure(claims)
        args.csv.parent.mkdir(parents=True, exist_ok=True)
        with args.csv.open("w", newline="") as fh:
            writer = csv.DictWriter(fh, fieldnames=["figure", "quantity", "value"])
            writer.writeheader()
            writer.writerows(rows)
        print(f"{len(rows)} numbers -> {args.csv}")
        return 0
    PAGE.write_text(page(args.csv.resolve()))
    print(f"wrote {PAGE}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
