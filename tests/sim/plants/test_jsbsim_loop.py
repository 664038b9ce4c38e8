"""The JSBSim F-22 in closed loop: seed 4.3 SMC designed on the linearisation, qp allocator (sim.plants.jsbsim_loop)."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("jsbsim", reason="jsbsim not installed: pip install 'alloc-toolkit[plants]'")

from alloc.exceptions import AllocError
from sim.plants.jsbsim_loop import OUTPUT_BOUND, doublets, fly

JAM_AT_TRIM = ("stab_l", "jam", {"position": 0.0})


@pytest.fixture(scope="module")
def cruise():
    return fly(duration=20.0)


@pytest.fixture(scope="module")
def jammed():
    return {told: fly(duration=20.0, failure=JAM_AT_TRIM, failure_time=5.0, told=told) for told in (True, False)}


def test_cruise_20s_holds_and_tracks(cruise):
    assert not cruise.diverged and cruise.t[-1] == pytest.approx(20.0)
    assert set(cruise.status) == {"exact"}
    # measured: alpha within 1.3 deg, airspeed within 0.6 m/s through 2 deg/s pitch and 10 deg/s roll doublets
    assert cruise.peak("alpha") < 3.0 and cruise.peak("vt") < 3.0
    # the roll doublet is followed: peak roll rate near its 10 deg/s, and back to level after it
    assert 8.0 < cruise.peak("p") < 12.0
    assert cruise.peak("p", after=12.0) < 0.5 and cruise.peak("q", after=18.0) < 0.5


def test_cruise_without_commands_stays_at_trim():
    f = fly(duration=20.0, commands=None)
    assert not f.diverged
    # the open-loop airframe doubles a disturbance every 0.22 s; closed, the trim holds
    assert f.peak("alpha") < 0.05 and f.peak("q") < 0.05 and f.peak("phi") < 0.05


def test_stabilator_jam_at_trim_told_flies_blind_does_not(jammed, cruise):
    told, blind = jammed[True], jammed[False]
    assert not told.diverged
    # told: the pitch doublet after the failure is flown as without it (the other half and the nozzle)
    assert told.rms_error("q", after=5.0) < 1.2 * cruise.rms_error("q", after=5.0)
    assert told.peak("alpha", after=5.0) < 3.0
    # blind: the allocator keeps commanding the jammed half; the observers, fed that command, see
    # pitch authority that is not there (measured: diverged 4.6 s after the failure)
    assert blind.diverged or blind.rms_error("q", after=5.0) > 3.0 * told.rms_error("q", after=5.0)


def test_blind_jam_flies_when_the_observers_see_the_positions(jammed):
    """The blind loop's failure is its observers' input: fed the measured positions it flies the doublet."""
    told = fly(duration=20.0, failure=JAM_AT_TRIM, told=True, observer_input="position")
    blind = fly(duration=20.0, failure=JAM_AT_TRIM, told=False, observer_input="position")
    assert not told.diverged and not blind.diverged
    # measured: RMS q error 0.472 blind against 0.455 told (8.6 and diverged with command-fed observers)
    assert blind.rms_error("q", after=5.0) < 1.2 * told.rms_error("q", after=5.0)
    assert blind.rms_error("q", after=5.0) < 0.2 * jammed[False].rms_error("q", after=5.0)
    assert blind.settings["observer_input"] == "position"


def test_divergence_is_detected_and_stops_the_flight():
    # an aileron jammed at 5 deg asks for more roll moment than the rudder can oppose
    f = fly(duration=20.0, failure=("aileron", "jam", {"position": 5.0}), told=True)
    assert f.diverged and f.t[-1] < 20.0
    assert np.any(np.abs(f.outputs[-1]) > OUTPUT_BOUND)


def test_doublets_shape_and_timing():
    t = np.array([0.0, 2.5, 3.5, 6.5, 10.5, 14.5])
    c = doublets(t)
    np.testing.assert_array_equal(c[:, 0], [0, 2, -2, 0, 2, 0])
    np.testing.assert_array_equal(c[:, 1], [0, 0, 0, 10, 0, 0])
    np.testing.assert_array_equal(c[:, 2], [0, 0, 0, 0, 0, 2])


def test_bad_input_names_the_field():
    with pytest.raises(AllocError) as e:
        fly(duration=-1.0)
    assert e.value.field == "duration"
    with pytest.raises(AllocError) as e:
        fly(duration=1.0, failure=("canard", "jam", {}))
    assert e.value.field == "failure"
    with pytest.raises(AllocError) as e:
        fly(duration=1.0, observer_input="estimate")
    assert e.value.field == "observer_input"


def test_real_time_factor_is_recorded(cruise):
    # measured 50-70x real time on 2 shared cores (plant, controller and qp allocator at 120 Hz)
    assert cruise.real_time_factor > 1.0
    assert cruise.settings["plant"]["name"] == "jsbsim:f22" and cruise.settings["design"]["K_rho"] > 0


# ------------------------------------------------------------------ command line (sim.plants.cli)
def test_failure_names_parse_by_the_kind_table():
    from sim.plants.cli import parse_failure

    eff = ("stab_l", "tvc")
    assert parse_failure("jam:stab_l@0", eff) == ("stab_l", "jam", {"position": 0.0})
    assert parse_failure("hardover:stab_l", eff) == ("stab_l", "hardover", {})
    assert parse_failure("rate_limits:tvc@-5:5", eff) == ("tvc", "rate_limits", {"rate_min": -5.0, "rate_max": 5.0})
    for bad in ("melt:stab_l", "jam:canard@1", "jam:stab_l@x", "jam:stab_l@1:2", "jam", "jam:stab_l@nan"):
        with pytest.raises(AllocError) as e:
            parse_failure(bad, eff)
        assert e.value.field == "failure", bad


def test_cli_flies_and_linearises(tmp_path):
    import json

    import alloc
    from typer.testing import CliRunner

    from sim.plants.cli import app

    runner = CliRunner()
    out = runner.invoke(app, ["fly", "jsbsim:f22", "--duration", "3", "--failure", "jam:stab_l@0"])
    assert out.exit_code == 0, out.output
    summary = json.loads(out.output)
    assert summary["diverged"] is False and summary["told"] is True
    out = runner.invoke(app, ["linearise", "jsbsim:f22", "--out", str(tmp_path / "f22.toml")])
    assert out.exit_code == 0, out.output
    assert alloc.load_vehicle(tmp_path / "f22.toml").model.controlled == ("q", "p", "r")
    out = runner.invoke(app, ["fly", "jsbsim:f16"])
    assert out.exit_code != 0 and isinstance(out.exception, AllocError) and out.exception.field == "plant"
