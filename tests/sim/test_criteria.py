"""Engineering pass/fail criteria (sim.criteria) on synthetic trajectories with known answers:
each criterion met, each broken on its own, the recovery clock, and a seeded generator of
hostile trajectories against an independent re-computation of every verdict."""

from __future__ import annotations

import json
from dataclasses import replace
import math

import numpy as np
import pytest

from sim.criteria import (
    AxisLimits, Limit, ScenarioCriteria, back_in_band_time, criteria_for, evaluate, free_parameters, verdict_of,
)
from sim.result import SimResult
from sim.scenarios import harv_latdir, ice  # noqa: F401 - their tables need their scenario objects

OURS = "test table"

#: round limits so every answer below is exact: axis q tracked (RMS, peak), axis b regulated (RMS, excursion)
TABLE = ScenarioCriteria(
    "synthetic",
    axes=(
        AxisLimits("q", rms=(Limit(1.0, OURS), Limit(2.0, OURS)), peak=(Limit(2.0, OURS), Limit(4.0, OURS))),
        AxisLimits("b", rms=(Limit(1.0, OURS), Limit(2.0, OURS)), excursion=(Limit(3.0, OURS), Limit(6.0, OURS))),
    ),
    recovery_hold=Limit(1.0, OURS), recovery_max=Limit(2.0, OURS), saturation_max=Limit(0.5, OURS),
)

T = np.round(np.arange(0.0, 10.0, 0.1), 10)  # 100 samples; the failure at 5 s splits them 50 / 50
FAILURE_T = 5.0


def _run(q_err=None, b=None, pos=None, rate=None, *, failure_time=FAILURE_T, diverged=False) -> SimResult:
    """A run with reference zero on both channels: q's error is -q's output, b's output is b."""
    n = T.size
    q_err = np.zeros(n) if q_err is None else q_err
    b = np.zeros(n) if b is None else b
    out = np.column_stack([-q_err, b])
    ref = np.zeros((n, 2))
    pos = np.zeros(n) if pos is None else pos
    rate = np.zeros(n) if rate is None else rate
    return SimResult(
        "synthetic", "pinv", None if failure_time is None else "f", T, ["q", "b"], ref, out, ref,
        effectors=pos[:, None], effector_rates=rate[:, None],
        effector_limits=(np.array([-1.0]), np.array([1.0])), rate_limits=(np.array([-1.0]), np.array([1.0])),
        failure_time=failure_time, diverged=diverged,
    )


def test_a_quiet_run_passes_with_exact_metrics() -> None:
    q = np.where(T < FAILURE_T, 0.5, 1.5)
    v = evaluate(_run(q_err=q, b=np.full(T.size, 0.25)), TABLE)
    assert v.passed and v.broken == ()
    assert v.metrics["q_rms_before"] == pytest.approx(0.5) and v.metrics["q_rms_after"] == pytest.approx(1.5)
    assert v.metrics["q_max_after"] == pytest.approx(1.5) and v.metrics["b_excursion_after"] == pytest.approx(0.25)
    assert v.metrics["position_saturation_after"] == 0.0 and v.metrics["rate_saturation_before"] == 0.0
    # q's |error| 1.5 after the failure is inside its nominal peak band (2): never left it
    assert v.metrics["back_in_band_s"] == 0.0
    assert v.limits["q_max_before"] == 2.0 and v.limits["back_in_band_s"] == 2.0


@pytest.mark.parametrize(("name", "changes"), [
    ("q_rms_before", {"q_err": np.where(T < FAILURE_T, 1.2, 0.0)}),       # RMS 1.2 > 1, peak 1.2 < 2
    ("q_rms_after", {"q_err": np.where(T >= FAILURE_T, 2.1, 0.0)}),       # RMS 2.1 > 2, peak 2.1 < 4
    ("b_rms_after", {"b": np.where(T >= FAILURE_T, 2.5, 0.0)}),
    ("b_excursion_before", {"b": np.where(np.isclose(T, 1.0), 3.5, 0.0)}),  # one sample: RMS 0.49
    ("position_saturation_after", {"pos": np.where(T >= 7.0, 1.0, 0.0)}),  # 30 of 50 samples on the stop
    ("rate_saturation_before", {"rate": np.where(T < 3.0, -1.0, 0.0)}),   # 30 of 50 at the rate limit
])
def test_each_criterion_breaks_on_its_own(name: str, changes: dict) -> None:
    v = evaluate(_run(**changes), TABLE)
    assert not v.passed
    assert name in v.broken
    assert v.metrics[name] > v.limits[name]


def test_each_broken_alone_with_known_numbers() -> None:
    v = evaluate(_run(q_err=np.where(T < FAILURE_T, 1.2, 0.0)), TABLE)
    assert v.broken == ("q_rms_before",) and v.metrics["q_rms_before"] == pytest.approx(1.2)
    v = evaluate(_run(b=np.where(np.isclose(T, 1.0), 3.5, 0.0)), TABLE)
    assert v.broken == ("b_excursion_before",) and v.metrics["b_rms_before"] == pytest.approx(3.5 / math.sqrt(50))
    v = evaluate(_run(pos=np.where(T >= 7.0, 1.0, 0.0)), TABLE)
    assert v.broken == ("position_saturation_after",) and v.metrics["position_saturation_after"] == pytest.approx(0.6)
    v = evaluate(_run(rate=np.where(T < 3.0, -1.0, 0.0)), TABLE)
    assert v.broken == ("rate_saturation_before",) and v.metrics["rate_saturation_before"] == pytest.approx(0.6)


def test_peak_and_recovery_break_and_the_clock_reads_the_band() -> None:
    # q's error 5 (over the failed peak 4, outside the nominal band 2) for 3 s after the failure
    q = np.where((T >= FAILURE_T) & (T < 8.0), 5.0, 0.0)
    v = evaluate(_run(q_err=q), TABLE)
    assert v.metrics["back_in_band_s"] == pytest.approx(3.0)  # back at 8.0, held to 9.9 >= 1 s
    assert set(v.broken) == {"q_rms_after", "q_max_after", "back_in_band_s"}
    # out of the nominal band for 1.5 s, inside the failed peak limit: back in time, passes
    q = np.where((T >= FAILURE_T) & (T < 6.5), 3.0, 0.0)
    v = evaluate(_run(q_err=q), TABLE)
    assert v.metrics["back_in_band_s"] == pytest.approx(1.5) and v.passed
    # back in band only for the last 0.5 s of the run: less than the hold, never recovered
    q = np.where((T >= FAILURE_T) & (T < 9.5), 3.0, 0.0)
    v = evaluate(_run(q_err=q), TABLE)
    assert v.metrics["back_in_band_s"] == math.inf and "back_in_band_s" in v.broken


def test_back_in_band_time_known_answers() -> None:
    t = np.arange(0.0, 10.0001, 0.5)
    inside = np.ones(t.size, dtype=bool)
    assert back_in_band_time(t, inside, 4.0, 2.0) == 0.0
    inside[(t >= 4.0) & (t < 6.0)] = False
    assert back_in_band_time(t, inside, 4.0, 2.0) == pytest.approx(2.0)
    inside[t >= 9.0] = False  # out again at 9 s: the stretch 6..8.5 holds 2.5 s, still counts
    assert back_in_band_time(t, inside, 4.0, 2.0) == pytest.approx(2.0)
    assert back_in_band_time(t, inside, 4.0, 3.0) == math.inf  # no stretch of 3 s
    inside[:] = False
    assert back_in_band_time(t, inside, 4.0, 0.5) == math.inf


def test_diverged_no_failure_and_failure_at_start() -> None:
    v = evaluate(_run(diverged=True), TABLE)
    assert v.broken[0] == "diverged" and v.metrics["back_in_band_s"] == math.inf
    nominal = evaluate(_run(failure_time=None), TABLE)
    assert nominal.passed and nominal.metrics["back_in_band_s"] is None and nominal.metrics["q_rms_after"] is None
    at_start = evaluate(_run(failure_time=0.0), TABLE)
    assert at_start.metrics["back_in_band_s"] is None and at_start.metrics["q_rms_before"] is None


def _independent(run: SimResult) -> tuple[set[str], dict[str, float | None]]:
    """The table's verdict re-computed sample by sample, without sim.criteria's helpers."""
    err_q, b = -run.output[:, 0], run.output[:, 1]
    pos_sat = np.abs(run.effectors[:, 0]) >= 1.0 - 2e-3
    rate_sat = np.abs(run.effector_rates[:, 0]) >= 1.0 - 2e-3
    metrics: dict[str, float | None] = {}
    for phase, mask in (("before", T < FAILURE_T), ("after", T >= FAILURE_T)):
        metrics[f"q_rms_{phase}"] = math.sqrt(sum(x * x for x in err_q[mask]) / mask.sum())
        metrics[f"q_max_{phase}"] = max(abs(x) for x in err_q[mask])
        metrics[f"b_rms_{phase}"] = math.sqrt(sum(x * x for x in b[mask]) / mask.sum())
        metrics[f"b_excursion_{phase}"] = max(abs(x) for x in b[mask])
        metrics[f"position_saturation_{phase}"] = pos_sat[mask].mean()
        metrics[f"rate_saturation_{phase}"] = rate_sat[mask].mean()
    inside = (np.abs(err_q) <= 2.0) & (np.abs(b) <= 3.0)
    back = math.inf
    for i in np.flatnonzero(T >= FAILURE_T):
        j = i
        while j < T.size and inside[j]:
            j += 1
        if j > i and T[j - 1] - T[i] >= 1.0 - 1e-9:
            back = T[i] - FAILURE_T
            break
    metrics["back_in_band_s"] = math.inf if run.diverged else back
    limits = TABLE.limits()
    broken = {k for k, v in metrics.items() if v > limits[k]} | ({"diverged"} if run.diverged else set())
    return broken, metrics


def test_hostile_trajectories_against_an_independent_verdict() -> None:
    """100 seeded trajectories: heavy tails, spikes, long out-of-band stretches, effectors on and off the stops."""
    rng = np.random.default_rng(20261202)
    for case in range(100):
        scale = rng.choice([0.1, 1.0, 3.0, 1e3])
        q = rng.standard_t(2, T.size) * scale * rng.uniform(0, 1)
        b = rng.standard_normal(T.size) * rng.choice([0.2, 2.0, 10.0])
        if rng.random() < 0.5:  # a failure transient that may or may not settle
            end = rng.uniform(FAILURE_T, 10.0)
            q[(T >= FAILURE_T) & (T < end)] *= 10.0
        pos = np.clip(rng.uniform(-1.5, 1.5, T.size), -1.0, 1.0)
        rate = np.clip(rng.uniform(-1.2, 1.2, T.size), -1.0, 1.0)
        run = _run(q_err=q, b=b, pos=pos, rate=rate, diverged=bool(rng.random() < 0.1))
        v = evaluate(run, TABLE)
        broken, metrics = _independent(run)
        assert set(v.broken) == broken, case
        assert v.passed == (not broken), case
        for name, value in metrics.items():
            assert v.metrics[name] == pytest.approx(value, rel=1e-12, abs=1e-12), (case, name)
        json.dumps(v.to_json(), allow_nan=False)


def test_the_ice_and_harv_tables_and_the_summary_verdict() -> None:
    ice = criteria_for("ice").limits()
    # 0.25 x the RMS of the seed's alpha sum of sines (xi = 5) over the seed's 40 s: 6.435 deg
    assert ice["alphaw_rms_before"] == pytest.approx(0.25 * 6.435, rel=1e-3)
    assert ice["betaw_excursion_before"] == 6.0 and ice["betaw_excursion_after"] == 15.0  # MIL-F-8785C Table VIII
    # 0.5 x the peak rate of the HARV bank-angle command (xi = 6): 21.36 deg/s
    assert criteria_for("harv_latdir").limits()["ps_max_after"] == pytest.approx(21.36, rel=1e-3)
    assert criteria_for("pendulum") is None
    n = 50
    t = np.linspace(0.0, 4.9, n)
    z = np.zeros((n, 3))
    out = z.copy()
    out[t >= 2.0, 2] = 20.0  # sideslip 20 deg after the failure: over the 15 deg Level 2 line
    run = SimResult("ice", "qp", "seed", t, ["alphaw", "ps", "betaw"], z, out, z, failure_time=2.0)
    verdict = run.summary()["verdict"]
    assert verdict["pass"] is False
    assert verdict["broken"] == ["betaw_rms_after", "betaw_excursion_after", "back_in_band_s"]
    assert verdict["metrics"]["back_in_band_s"] == "inf"
    json.dumps(run.summary(), allow_nan=False)
    assert verdict_of(SimResult("x", "qp", None, t, ["q"], z[:, :1], z[:, :1], z[:, :1])) is None


def test_every_free_parameter_is_listed() -> None:
    names = {name for name, _, _ in free_parameters()}
    assert {"criteria RECOVERY_HOLD_S", "criteria SATURATION_MAX_FRACTION", "criteria NOMINAL_RMS_FRACTION"} <= names
    sources = criteria_for("ice").sources()
    assert all(s.startswith("ours") or s.startswith("MIL-F-8785C") for s in sources.values())


def test_the_comparison_page_holds_the_criteria_tables() -> None:
    from pathlib import Path

    from sim.criteria import render_markdown

    page = Path(__file__).resolve().parents[2] / "docs" / "comparison.md"
    assert render_markdown() in page.read_text()


# ----------------------------------------------------------------------------- failed effectors
def _two_effector_run(pos: np.ndarray, rate: np.ndarray) -> SimResult:
    """A quiet run with two effectors (limits +-1, rates +-1) and a failure at 5 s."""
    zeros = np.zeros((T.size, 2))
    return SimResult(
        "synthetic", "pinv", "f", T, ["q", "b"], zeros, zeros, zeros, effectors=pos, effector_rates=rate,
        effector_limits=(np.array([-1.0, -1.0]), np.array([1.0, 1.0])),
        rate_limits=(np.array([-1.0, -1.0]), np.array([1.0, 1.0])), failure_time=FAILURE_T,
    )


def test_the_failed_effector_leaves_the_saturation_share_after_its_failure() -> None:
    """Seeded jams: effector 0 runs to its stop at the failure and stays (a hard-over), effector 1
    is healthy and on a stop for a random share of each phase.  With the rule (``failed=(0,)``) the
    after-share is effector 1's alone; without it (``failed=()``) every after-sample counts."""
    rng = np.random.default_rng(27)
    after = T >= FAILURE_T
    for _ in range(50):
        healthy = np.where(rng.random(T.size) < rng.uniform(0.0, 0.6), rng.choice([-1.0, 1.0]), 0.3)
        jammed = np.where(after, 1.0, rng.uniform(-0.9, 0.9, T.size))
        rate = np.column_stack([np.where(after & (T < FAILURE_T + 0.5), 1.0, 0.0), np.zeros(T.size)])
        run = _two_effector_run(np.column_stack([jammed, healthy]), rate)
        with_rule, without = evaluate(run, TABLE, failed=(0,)), evaluate(run, TABLE, failed=())
        own = float(np.mean(np.abs(healthy[after]) >= 1.0))
        assert with_rule.metrics["position_saturation_after"] == pytest.approx(own)
        assert without.metrics["position_saturation_after"] == 1.0
        assert with_rule.metrics["rate_saturation_after"] == 0.0
        assert without.metrics["rate_saturation_after"] == pytest.approx(0.1)  # 5 of 50 samples running
        # before the failure the rule changes nothing
        for kind in ("position", "rate"):
            assert with_rule.metrics[f"{kind}_saturation_before"] == without.metrics[f"{kind}_saturation_before"]
        assert ("position_saturation_after" in without.broken) and (
            ("position_saturation_after" in with_rule.broken) == (own > 0.5))


def test_failed_effectors_are_the_ones_out_of_command() -> None:
    from sim.actuator_failure import ActuatorFailure
    from sim.criteria import failed_effectors, known_failed_effectors
    from sim.model import Failure

    failure = Failure("f", 1.0, "test", actuators=(
        ActuatorFailure(0, "jam", position=0.5), ActuatorFailure(1, "hardover"), ActuatorFailure(2, "float"),
        ActuatorFailure(3, "limits", lo=-0.5, hi=0.5), ActuatorFailure(4, "effectiveness", fraction=0.5),
        ActuatorFailure(5, "jam", position=0.0), ActuatorFailure(5, "repair"),
    ))
    assert failed_effectors(failure) == (0, 1, 2)
    assert failed_effectors(None) == ()
    # the seed's ICE failure jams the left LEF (seed section 4.7); HARV lat-dir Failure #2 jams nothing
    ice_run = SimResult("ice", "pinv", "seed", T, [], np.zeros((T.size, 0)), np.zeros((T.size, 0)),
                        np.zeros((T.size, 0)), failure_time=20.0)
    assert known_failed_effectors(ice_run) == (ice.EFFECTORS.index("de2"),)
    assert known_failed_effectors(replace(ice_run, scenario="harv_latdir", failure="failure2")) == ()
    assert known_failed_effectors(replace(ice_run, failure="not a failure")) == ()
    assert "injected failure jams" in criteria_for("ice").sources()["position_saturation_after"]


def test_a_catalogue_hardover_is_found_by_its_name():
    """The comparison sweep's catalogue registers its failures: a hard-over there is out of command."""
    from benchmarks.compare import failures as catalogue
    from sim.criteria import known_failed_effectors

    run = SimResult("ice", "pinv", "hardover2", T, [], np.zeros((T.size, 0)), np.zeros((T.size, 0)),
                    np.zeros((T.size, 0)), failure_time=5.0)
    assert known_failed_effectors(run) == tuple(catalogue.FAILED_EFFECTORS["ice"][:2])
    assert known_failed_effectors(replace(run, failure="effectiveness1")) == ()  # still commanded
