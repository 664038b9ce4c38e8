"""F-18/HARV scenarios (seed sections 4.5 and 4.6).

Measured (seed 0): longitudinal Failure #2 -- the SMC with the modified observer/hedge design stays
bounded (q RMS after ~2.9 deg/s), but the loop-shaped controller ALSO stays bounded (q RMS after
~2.3 deg/s), so Fig 4-39 (loop-shaped fails) is NOT reproduced (xfail).  Lat-dir Failure #1: SMC
bounded (ps RMS after ~2.9 deg/s), loop-shaped unstable (ps RMS after 265 deg/s over 25 s), as seed
Figs 4-67, 4-75.
"""

from __future__ import annotations

import numpy as np
import pytest

from sim.scenarios import get_scenario
from sim.scenarios import harv_latdir, harv_lon

lon = get_scenario("harv_lon")
lat = get_scenario("harv_latdir")


def test_lon_failed_plant_is_half_stabilator():
    assert harv_lon.B_FAIL[:, 0] == pytest.approx(harv_lon.B[:, 0] / 2, rel=1e-3)  # seed Eq 4.10


def test_latdir_alpha0_and_ganging_demand_map():
    assert np.degrees(harv_latdir.ALPHA0) == pytest.approx(29.68, abs=0.05)
    v = harv_latdir.vehicle()
    assert np.allclose(v.demand_map, v.B_alloc @ harv_latdir.SEED_BK)


def test_lon_smc_with_hedging_survives_failure_2_fig_4_32():
    r = lon(method="ganging", failure="failure2", duration=20.0)
    s = r.summary()
    assert not r.diverged
    assert s["channels"]["q"]["rms_after"] < 5.0
    assert s["time_in_rate_saturation"] > 1.0  # thrust vector at its failed 6 deg/s limit


@pytest.mark.xfail(strict=True, reason="measured: loop-shaped controller stays bounded under Failure #2 "
                   "(q RMS after ~2.3 deg/s vs SMC ~2.9); seed Fig 4-39 shows it failing")
def test_lon_loop_shaped_fails_under_failure_2_fig_4_39():
    r = lon(method="ganging", failure="failure2", controller="loopshape", duration=20.0)
    assert r.diverged or r.summary()["channels"]["q"]["rms_after"] > 10.0


def test_lon_smc_without_observer_is_unstable_with_actuators_fig_4_11():
    r = lon(method="ganging", observer=False, hedge=False, noise=False, duration=3.0)
    assert r.summary()["channels"]["q"]["rms_before"] > 20.0


def test_latdir_smc_survives_failure_1_loop_shaped_does_not():
    smc = lat(method="ganging", failure="failure1", failure_time=10.0, duration=20.0).summary()
    ls = lat(method="ganging", failure="failure1", failure_time=10.0, duration=20.0, controller="loopshape")
    assert not smc["diverged"]
    assert smc["channels"]["ps"]["rms_after"] < 5.0
    assert smc["channels"]["beta"]["max_after"] < 2.0  # seed: beta excursions about 1 deg
    # measured: ps RMS after 25.8 deg/s 10 s after the failure (growing; 265 over 25 s)
    assert ls.diverged or ls.summary()["channels"]["ps"]["rms_after"] > 5 * smc["channels"]["ps"]["rms_after"]


# --------------------------------------------------------------- lat-dir Failure #2 (seed Fig 4-81)
lat2 = get_scenario("harv_latdir_failure2")


def _phi_error_rms(r):
    e = r.extra["phi_command"] - r.extra["phi"]
    return float(np.sqrt(np.mean(e**2)))


def test_latdir_failure2_input_is_the_seed_filtered_steps():
    # seed 4.6: steps filtered by (100/(s^2+20s+100)) (1/(s^2+2s+1)), unit DC gain
    t = np.arange(0.0, 40.0, 0.01)
    phi_c = harv_latdir.filtered_steps(t)
    assert phi_c[0] == 0.0
    assert phi_c[np.searchsorted(t, 10.9)] == pytest.approx(harv_latdir.STEP_LEVELS[0], abs=0.05)
    assert np.max(np.abs(np.diff(phi_c))) < 0.5  # smooth (a raw 40-deg reversal would jump 40)


def test_latdir_filtered_steps_tracked_without_failure():
    r = lat2(failure=None)
    assert not r.diverged
    assert _phi_error_rms(r) < 5.0  # measured 2.3 deg


def test_latdir_failure2_is_the_told_effector_failure():
    from sim.allocation import allocation_problem

    p = allocation_problem(harv_latdir.vehicle(), harv_latdir.failure("failure2"))
    assert p.B[:, 4] == pytest.approx(0.1 * harv_latdir.vehicle().B_alloc[:, 4])
    assert (p.umin[4], p.umax[4], p.rate_max[4]) == (-3.0, 3.0, 6.0)


@pytest.mark.xfail(strict=True, reason="measured: with the filtered steps and the stand-in pilot (gain 2, 0.2 s) "
                   "the SMC loses the bank-angle loop under Failure #2 and diverges near t = 27 s (ganging, "
                   "static, qp told alike); seed Fig 4-81 shows it tracking as well as the reconfigured QFT design")
def test_latdir_smc_tracks_failure2_fig_4_81():
    r = lat2()
    assert not r.diverged
    assert _phi_error_rms(r) < 10.0
