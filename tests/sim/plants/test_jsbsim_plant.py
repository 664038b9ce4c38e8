"""JSBSim's F-22 as a plant: pass-through, trim, linearisation, failures, bad input (sim.plants.jsbsim*)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

jsbsim = pytest.importorskip("jsbsim", reason="jsbsim not installed: pip install 'alloc-toolkit[plants]'")

from alloc.exceptions import AllocError, ProblemError  # noqa: E402
from alloc.health import FAILURE_KINDS  # noqa: E402
from sim.plant import Plant  # noqa: E402
from sim.plants.jsbsim import JSBSimPlant, make_plant  # noqa: E402
from sim.plants.jsbsim_linear import (CONTROLLED, EFFECTORS, VEHICLE_FILE, b_envelope, linearise,  # noqa: E402
                                      write_vehicle)
from sim.plants.jsbsim_model import (DEG, SURFACES, STATES, F22, TrimCondition, aero_inputs,  # noqa: E402
                                     build_aircraft, jsbsim_root)

H = 1.0 / 120.0


@pytest.fixture(scope="module")
def lin():
    return linearise()


@pytest.fixture()
def plant():
    return JSBSimPlant()


# ------------------------------------------------------------------ the aircraft copy
def test_every_property_we_drive_is_read_by_the_aerodynamics():
    source = jsbsim_root() / "aircraft" / "f22" / "f22.xml"
    reads = aero_inputs(source)
    assert {s.reads for s in SURFACES} <= reads
    # the differential stabilator and the right aileron exist in the stock FCS but no aerodynamics reads them
    assert "fcs/right-aileron-pos-rad" not in reads
    assert not any("dht" in r for r in reads)


def test_copy_is_built_outside_the_repository_and_the_package(tmp_path):
    ac = build_aircraft(tmp_path)
    assert ac.is_relative_to(tmp_path)
    files = list(ac.rglob("*.xml"))
    assert len(files) == 1
    assert build_aircraft(tmp_path) == ac  # cached: same content, same place


def test_stock_fcs_rewrites_positions_and_pass_through_holds_them():
    root = jsbsim_root()
    jsbsim.FGJSBBase().debug_lvl = 0
    stock = jsbsim.FGFDMExec(str(root), None)
    stock.set_debug_level(0)
    stock.load_model("f22")
    stock["ic/h-sl-ft"], stock["ic/mach"] = 20000.0, 0.7
    stock.run_ic()
    stock["fcs/elevator-pos-rad"] = 0.2
    stock.run()
    assert abs(stock["fcs/elevator-pos-rad"] - 0.2) > 0.05  # the stock FCS wrote over it

    f22 = F22()
    deg = f22.trim_positions.copy()
    deg[[0, 1]] = (4.0, 2.0)  # stabilator halves -> the aero reads their mean
    deg[2] = -3.0
    f22.set_positions(deg)
    for _ in range(60):
        f22.fdm.run()
    assert f22.fdm["fcs/elevator-pos-rad"] == pytest.approx(3.0 * DEG, abs=1e-12)
    assert f22.fdm["fcs/tvc-pos-rad"] == pytest.approx(-3.0 * DEG, abs=1e-12)


# ------------------------------------------------------------------ trim
def test_trim_residual_and_condition():
    f22 = F22()
    # largest body acceleration left: measured 9.1e-5 ft/s^2 (w-dot) at M0.7, 20,000 ft
    assert f22.trim_residual < 1e-3
    assert f22.fdm["velocities/mach"] == pytest.approx(0.7, abs=1e-6)
    assert 2.0 < f22.trim_state[STATES.index("alpha")] < 4.0
    assert f22.trim_positions[2] == 0.0  # nozzle trims at zero (its kink)
    assert abs(f22.fdm["fcs/pitch-trim-cmd-norm"]) == 0.0  # frozen into our properties


def test_bad_trim_condition_names_the_field():
    with pytest.raises(AllocError) as e:
        TrimCondition(mach=5.0)
    assert e.value.field == "mach" and isinstance(e.value, ValueError)
    with pytest.raises(AllocError) as e:
        TrimCondition(altitude_ft="high")
    assert e.value.field == "altitude_ft"


# ------------------------------------------------------------------ linearisation
def test_committed_vehicle_file_is_what_the_generator_gives(lin, tmp_path):
    import alloc

    fresh = alloc.load_vehicle(write_vehicle(lin, tmp_path / "f22.toml"))
    committed = alloc.load_vehicle(VEHICLE_FILE)
    for a, b in zip(fresh.model.arrays(), committed.model.arrays(), strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-6, atol=1e-9)
    assert committed.effector_names == EFFECTORS and committed.model.controlled == CONTROLLED


def test_model_is_the_statically_unstable_f22(lin):
    eig = np.linalg.eigvals(lin.A)
    # short period diverges (M_alpha > 0): one real eigenvalue about +3.1 1/s
    assert 2.0 < eig.real.max() < 5.0
    assert lin.A[STATES.index("q"), STATES.index("alpha")] > 0
    B = lin.B_axes
    assert B[0, 0] == pytest.approx(B[0, 1])  # the halves: one symmetric stabilator in the aerodynamics
    assert abs(B[1, 0]) < 1e-9 and abs(B[1, 1]) < 1e-9  # ... with no roll to give (round-off only)
    assert "tvc" in lin.one_sided  # the nozzle's pitch table is kinked at its trim, zero
    fwd, bwd = lin.one_sided["tvc"]
    q = STATES.index("q")
    # f22.xml CmDtv, columns +-0.3491 rad, rows alpha 0 and 0.0873 rad, interpolated at the trim alpha
    t = math.radians(lin.trim_state[STATES.index("alpha")]) / 0.0873
    up, down = 0.8366 + t * (0.8808 - 0.8366), 0.4650 + t * (0.4448 - 0.4650)
    assert fwd[q] / bwd[q] == pytest.approx(up / down, rel=1e-3)


def test_linear_model_reproduces_a_small_stabilator_step(lin):
    """Nonlinear minus nonlinear-unforced against the linear model fed the same actuator positions, 0.5 s."""
    import scipy.linalg

    steps = 60
    runs = []
    for size in (0.0, -0.5):
        p = JSBSimPlant()
        y, pos = [p.reset(seed=0)], [p.positions()]
        for _ in range(steps):
            y.append(p.step(np.array([size, size, 0, 0, 0]), H))
            pos.append(p.positions())
        runs.append((np.array(y), np.array(pos)))
    dy = runs[1][0] - runs[0][0]
    M = np.zeros((8 + 5, 8 + 5))
    M[:8, :8], M[:8, 8:] = lin.A, lin.B
    E = scipy.linalg.expm(M * H)
    x, lin_y = np.zeros(8), [np.zeros(8)]
    for k in range(steps):
        # JSBSim integrates each step with the accelerations of the step before (its models run
        # after the propagation), so a position written before step k + 1 acts from step k + 2
        x = E[:8, :8] @ x + E[:8, 8:] @ runs[1][1][k]
        lin_y.append(x)
    lin_y = np.array(lin_y)
    for name in ("alpha", "q", "theta"):
        i = STATES.index(name)
        err = np.max(np.abs(dy[:, i] - lin_y[:, i])) / np.max(np.abs(dy[:, i]))
        assert err < 0.05, (name, err)  # measured: alpha 3.1 %, q 1.1 %, theta 2.8 % of the peak over 0.5 s


def test_b_moves_with_dynamic_pressure_not_much_with_alpha():
    env = b_envelope()
    table = env["relative_change"]
    for label in ("qbar -20%", "qbar +20%"):
        for e in ("stab_l", "aileron", "rudder"):
            assert 0.12 < table[label][e] < 0.30, (label, e, table[label][e])
    for label in ("alpha -3 deg", "alpha +3 deg"):
        assert max(table[label].values()) < 0.10, (label, table[label])


def test_linearise_bad_steps_name_the_field():
    with pytest.raises(AllocError) as e:
        linearise(state_steps=(1.0,))
    assert e.value.field == "state_steps"
    with pytest.raises(AllocError) as e:
        linearise(effector_step=-1)
    assert e.value.field == "effector_step"


# ------------------------------------------------------------------ the plant contract
def test_plant_contract(plant):
    assert isinstance(plant, Plant)
    assert plant.effectors == EFFECTORS and plant.outputs == STATES
    y0 = plant.reset(seed=3)
    np.testing.assert_array_equal(y0, np.zeros(8))
    d = plant.describe()
    json.dumps(d)
    assert d["name"] == "jsbsim:f22" and d["trim"]["mach"] == 0.7 and d["seed"] == 3
    s = plant.state()
    assert s["mach"] == pytest.approx(0.7, abs=1e-6) and s["altitude_m"] == pytest.approx(6096.0, abs=0.1)


def test_reset_returns_to_the_same_trim(plant):
    first = [plant.step(np.array([1.0, 1.0, 0, 2.0, 0]), H) for _ in range(30)]
    plant.reset(seed=0)
    again = [plant.step(np.array([1.0, 1.0, 0, 2.0, 0]), H) for _ in range(30)]
    np.testing.assert_array_equal(np.array(first), np.array(again))


def test_actuator_lag_and_rate_limit(plant):
    plant.step(np.array([0.1, 0, 0, 0, 0]), H)
    assert plant.positions()[0] == pytest.approx(0.1 * (1 - math.exp(-40.0 * H)), rel=1e-12)
    plant.reset(seed=0)
    plant.step(np.array([0, 0, 20.0, 0, 0]), H)
    assert plant.positions()[2] == pytest.approx(40.0 * H, rel=1e-12)  # nozzle: 40 deg/s


def test_jam_at_trim_holds_against_commands(plant):
    plant.step(np.array([2.0, 2.0, 0, 0, 0]), 10 * H)
    plant.fail(0, "jam", {"position": 0.0})
    plant.step(np.array([5.0, 5.0, 0, 0, 0]), 30 * H)
    assert plant.positions()[0] == 0.0 and plant.positions()[1] > 2.0
    # the aerodynamics sees the mean of the jammed half (at trim) and the free one
    trim = plant.trim_u[0]
    assert plant.sim.fdm["fcs/elevator-pos-rad"] == pytest.approx((trim + plant.positions()[1] / 2) * DEG, rel=1e-12)


def test_jam_without_position_holds_where_it_is(plant):
    plant.step(np.array([3.0, 0, 0, 0, 0]), 6 * H)
    at = plant.positions()[0]
    plant.fail(0, "jam")
    plant.step(np.array([-5.0, 0, 0, 0, 0]), 12 * H)
    assert plant.positions()[0] == at and plant.failures[-1]["position"] == at


def test_hardover_runs_to_the_stop_at_the_rate_limit(plant):
    plant.fail(1, "hardover")
    hi = plant.hi0[1]
    plant.step(np.zeros(5), 12 * H)
    assert plant.positions()[1] == pytest.approx(60.0 * 12 * H, rel=1e-9)
    plant.step(np.zeros(5), 60 * H)
    assert plant.positions()[1] == pytest.approx(hi)
    assert plant.sim.fdm["alloc/stab-r-deg"] == pytest.approx(30.0)


def test_loss_of_effectiveness_scales_the_deflection_about_trim(plant):
    plant.fail(3, "effectiveness", {"fraction": 0.25})
    plant.step(np.array([0, 0, 0, 8.0, 0]), 120 * H)
    pos = plant.positions()[3]
    assert pos == pytest.approx(8.0, abs=1e-3)
    trim = plant.trim_u[3]  # the trimmer leaves ~1e-11 deg here
    assert plant.sim.fdm["fcs/left-aileron-pos-rad"] == pytest.approx((trim + 0.25 * pos) * DEG, rel=1e-12)


def test_reduced_rate_limit(plant):
    plant.fail(4, "rate_limits", {"rate_min": -5.0, "rate_max": 5.0})
    plant.step(np.array([0, 0, 0, 0, 10.0]), 24 * H)
    assert plant.positions()[4] == pytest.approx(5.0 * 24 * H, rel=1e-9)


def test_float_streamlines_and_repair_restores(plant):
    plant.fail(0, "float")
    plant.step(np.array([3.0, 0, 0, 0, 0]), 60 * H)
    assert plant.sim.fdm["alloc/stab-l-deg"] == pytest.approx(0.0, abs=1e-12)  # absolute 0 deg
    plant.fail(0, "repair")
    plant.step(np.array([3.0, 0, 0, 0, 0]), 120 * H)
    assert plant.positions()[0] == pytest.approx(3.0, abs=1e-3)


def test_reduced_limits(plant):
    plant.fail(2, "limits", {"lo": -2.0, "hi": 1.0})
    plant.step(np.array([0, 0, 10.0, 0, 0]), 60 * H)
    assert plant.positions()[2] == 1.0


@pytest.mark.parametrize("args, field", [
    ((9, "jam", None), "effector"),
    ((0, "melt", None), "kind"),
    ((0, "jam", {"position": 50.0}), "position"),
    ((0, "effectiveness", {"fraction": 1.5}), "fraction"),
    ((0, "effectiveness", {}), "fraction"),
    ((0, "jam", {"fraction": 0.5}), "fraction"),
])
def test_bad_failures_name_the_field(plant, args, field):
    with pytest.raises(ProblemError) as e:
        plant.fail(*args)
    assert e.value.field == field and isinstance(e.value, ValueError)


@pytest.mark.parametrize("call, field", [
    (lambda p: p.step(np.zeros(4), H), "u_cmd"),
    (lambda p: p.step(np.array([np.nan, 0, 0, 0, 0]), H), "u_cmd"),
    (lambda p: p.step(np.zeros(5), 0.005), "dt"),
    (lambda p: p.step(np.zeros(5), -H), "dt"),
    (lambda p: p.reset(seed=1.5), "seed"),
])
def test_bad_input_names_the_field(plant, call, field):
    with pytest.raises(AllocError) as e:
        call(plant)
    assert e.value.field == field


def test_bad_construction_names_the_field():
    with pytest.raises(AllocError) as e:
        make_plant("jsbsim:f16")
    assert e.value.field == "plant"
    with pytest.raises(AllocError) as e:
        JSBSimPlant(bandwidth={"canard": 10.0})
    assert e.value.field == "bandwidth"
    with pytest.raises(AllocError) as e:
        JSBSimPlant(jsbsim_dt=1.0)
    assert e.value.field == "jsbsim_dt"


@pytest.mark.parametrize("kind", sorted(FAILURE_KINDS))
def test_every_registered_failure_kind_runs_on_the_plant(plant, kind):
    """Each row of the failure-kind table, with its example parameters, is executed (no kind is re-listed here)."""
    plant.fail(0, kind, dict(FAILURE_KINDS[kind].example))
    y = plant.step(np.array([1.0, 1.0, 0, 0, 0]), 12 * H)
    assert np.all(np.isfinite(y)) and plant.failures[-1]["kind"] == kind
    assert plant.lo[0] <= plant.positions()[0] <= plant.hi[0]


def test_positions_respect_limits_and_rates_under_random_commands(plant):
    rng = np.random.default_rng(7)
    span = plant.hi0 - plant.lo0
    prev = plant.positions()
    for _ in range(200):
        u = plant.lo0 - 0.2 * span + rng.random(5) * 1.4 * span  # beyond the limits too
        plant.step(u, H)
        pos = plant.positions()
        assert np.all(pos >= plant.lo0 - 1e-12) and np.all(pos <= plant.hi0 + 1e-12)
        assert np.all(np.abs(pos - prev) <= plant.rate0 * H * (1 + 1e-12))
        prev = pos
