"""ICE 6-DOF scenario (seed section 4.7): transcription checks and the seed's qualitative results.

Measured (seed 0, dt = 0.5 ms; see the report table in README):

* no observer, actuators in the loop: alpha leaves +-45 deg within ~2 s -> diverged (Fig 4-95 reproduced);
* Table 4-6 observers and hedges, noise-free, pilot gain 1: bounded through the failure (Fig 4-110
  reproduced in that setting);
* with the default pilot stand-in (gain 2, 0.2 s) and the seed's noise, the SMC loop also diverges
  about 10 s after the t = 20 s failure: NOT reproduced (xfail below);
* Eq 4.28 loop-shaped baseline: diverges after the failure (Fig 4-119 reproduced, ~14 s after it).
"""

from __future__ import annotations

import numpy as np
import pytest

import alloc
from sim.scenarios import get_scenario
from sim.scenarios import ice

run = get_scenario("ice")


def test_eq_4_24_reproduced_from_design_rows():
    # seed Eq 4.23 with Wu = diag(2, 2, 1, ...) on the w, pb, v rows of B (spoilers out of pitch)
    Wi = np.diag(1.0 / ice.WU)
    B = ice.B_DESIGN
    Bk = Wi @ B.T @ np.linalg.inv(B @ Wi @ B.T)
    assert np.allclose(Bk, ice.SEED_BK, atol=0.01 + 0.01 * np.abs(ice.SEED_BK))


def test_actuator_frequencies_quoted_in_failure_list():
    wn = {a.name: a.wn for a in ice.vehicle().actuators}
    assert wn["de4"] == pytest.approx(63.2, abs=0.1)  # "reduced from 63 rad/s"
    assert wn["de10"] == pytest.approx(39.2, abs=0.1)  # "reduced from 39 rad/s"


def test_allocation_problem_matches_table_4_5():
    p = ice.allocation_problem()
    assert p.k == 3 and p.m == 11
    assert p.umin[3] == 0.0 and p.umax[3] == 60.0  # all-moving tip
    assert p.rate_max[2] == 50.0  # symmetric pitch flap


def test_no_observer_diverges_fig_4_95():
    r = run(method="static", observer=False, hedge=False, noise=False, duration=5.0)
    assert r.diverged
    assert r.duration < 4.0


def test_observers_and_hedges_bounded_through_failure_fig_4_110():
    """Noise-free, pilot stand-in gain 1, failure at 5 s instead of 20 s to keep the test short."""
    r = run(method="static", failure="seed", failure_time=5.0, duration=15.0, noise=False, pilot_gain=1.0)
    s = r.summary()["channels"]
    assert not r.diverged
    assert s["alphaw"]["max_after"] < 10.0
    assert s["betaw"]["max_after"] < 5.0
    assert s["alphaw"]["rms_before"] < 0.6


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason="measured: with the seed's noise and our pilot stand-in (gain 2, "
                   "0.2 s) ps reaches 200 deg/s about 12 s after the t = 20 s failure; seed Fig 4-110 "
                   "shows the loop stable")
def test_full_seed_run_with_noise_stays_bounded():
    r = run(method="static", failure="seed", duration=40.0)
    assert not r.diverged


def test_loop_shaped_baseline_diverges_after_failure_fig_4_119():
    r = run(method="static", controller="loopshape", failure="seed", failure_time=5.0, duration=20.0, noise=False)
    assert r.diverged
    assert r.duration > 5.0  # tracked before the failure
    assert r.summary()["channels"]["alphaw"]["rms_before"] < 1.0


@pytest.mark.parametrize("method", alloc.methods())
def test_every_registry_method_runs_in_the_loop(method):
    r = run(method=method, failure="seed", failure_time=0.5, duration=1.0, allocator_knows_failure=True)
    assert np.all(np.isfinite(r.output))
    assert np.all(np.isfinite(r.effectors))
    assert r.t[-1] == pytest.approx(1.0)
