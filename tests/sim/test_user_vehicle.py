"""A user's aircraft, described only by its vehicle file, in the closed loop (sim.user_vehicle, sim.autodesign).

Reference numbers are physical quantities of the bundled example files, computed here by
hand from the files' own data (rotor geometry, mass, inertia), never read back from the code:

* hexa-x: hover trim ``u0 = m g / (6 CT) = 19.62 / 39``; the pseudo-command map is the
  inertia and the mass, ``diag(Ixx, Iyy, Izz, m) = diag(0.08, 0.08, 0.15, 2)`` (``v`` in N m
  and N per unit rate of p, q, r, w); the yaw reach from trim is ``6 CT KM (1 - u0) / Izz``.
* tailless: the seed's ICE actuators give a 40 rad/s limit frequency, and the reference
  rule ``wn = 0.25 x 40`` reproduces seed Eq 4.22's ``100 / (s^2 + 20 s + 100)``.
"""

from __future__ import annotations

import json
import random

import numpy as np
import pytest
from typer.testing import CliRunner

import alloc
from alloc.cli import app
from alloc.exceptions import AllocError, ProblemError
from alloc.vehicle_file import vehicle_from_dict
from sim.autodesign import DESIGN_OPTIONS, relative_order
from sim.user_vehicle import VehicleScenario, flight_model, fly, vehicle_failure

SEED = 20261202
runner = CliRunner()

U0_HOVER = 19.62 / (6 * 6.5)  # seed-free: the file's mass 2 kg, CT 6.5 N per rotor


@pytest.fixture(scope="module")
def hexa():
    return flight_model("hexa-x")


@pytest.fixture(scope="module")
def tailless():
    return flight_model("tailless")


def test_hexa_design_recovers_the_airframe(hexa):
    report = hexa.design.report
    np.testing.assert_allclose(hexa.trim_u, U0_HOVER, rtol=1e-9)
    np.testing.assert_allclose(hexa.design.demand_map, np.diag([0.08, 0.08, 0.15, 2.0]), atol=1e-12)
    assert report["pseudo_commands"]["model_fit_residual"] < 1e-12  # the model's B is exactly M B_file
    assert report["limit_frequency"]["value"] == 30.0  # motor lag 1/30 s
    assert report["reference_model"]["wn"] == 7.5 and report["reference_model"]["zeta"] == 1.0
    yaw_reach = 6 * 6.5 * 0.05 * (1.0 - U0_HOVER) / 0.15
    np.testing.assert_allclose(report["switching"]["reach"][2], yaw_reach, rtol=1e-9)
    np.testing.assert_allclose(np.asarray(report["switching"]["eps"]) * report["switching"]["K_rho"],
                               report["switching"]["rho"], rtol=1e-12)  # seed step 6: rho / eps = K_rho
    assert report["switching"]["K_rho"] == 600.0  # 20 x 30 rad/s, under 0.5 / T = 1000
    assert report["check"]["max_real_eig"] < -report["options"]["stability_margin"]
    assert report["check"]["neutral_modes"] == 3  # phi, theta, psi integrate the regulated rates
    assert report["baseline"]["found"] and report["baseline"]["K"] > 0
    json.dumps(report, allow_nan=False)  # the report goes into the JSON summary as it is


def test_tailless_reference_rule_is_seed_eq_4_22(tailless):
    ref = tailless.design.references
    assert all(num == (100.0,) and den == (1.0, 20.0, 100.0) for num, den in ref)  # seed Eq 4.22 alpha, p
    assert tailless.design.report["limit_frequency"]["value"] == 40.0
    np.testing.assert_array_equal(tailless.trim_u, 0.0)  # no axis trim: u0 = 0
    assert tailless.design.report["check"]["neutral_modes"] == 1  # bank angle free with alpha, p_s, beta held


def test_relative_order_two_is_refused():
    doc = alloc.load_vehicle("hexa-x").to_dict()
    doc["model"]["controlled"] = ["phi", "theta", "psi", "w"]  # attitudes: relative order 2
    with pytest.raises(ProblemError) as info:
        flight_model(vehicle_from_dict(doc))
    assert info.value.field == "model.controlled[0]" and "relative order 2" in str(info.value)
    A, B, C, D = alloc.load_vehicle("hexa-x").model.arrays()
    assert [relative_order(A, B, C[i], D[i]) for i in range(7)] == [2, 2, 2, 1, 1, 1, 1]


def test_design_override_is_used_and_reported():
    fm = flight_model("hexa-x", design={"crossover": 150.0, "reference_ratio": 0.2})
    assert fm.design.report["switching"]["K_rho"] == 150.0
    assert fm.design.report["reference_model"]["wn"] == pytest.approx(6.0)
    assert fm.design.report["options"]["crossover"] == 150.0


def test_hostile_design_options_raise_alloc_errors():
    rng = random.Random(SEED)
    bad_values = [0, -1.0, float("nan"), float("inf"), "fast", [1.0], True, None]
    names = list(DESIGN_OPTIONS) + ["bogus", "K0", ""]
    for _ in range(40):
        name = rng.choice(names)
        value = rng.choice(bad_values)
        if name in DESIGN_OPTIONS and value is None:
            continue  # None means "the rule's default"
        if name == "observer" and isinstance(value, bool):
            continue
        with pytest.raises(AllocError) as info:
            flight_model("hexa-x", design={name: value})
        assert (info.value.field or "").startswith("design"), (name, value, info.value)


def _failure_name(rng: random.Random) -> str:
    """Seeded: names built from valid and invalid pieces (kinds, effectors, values, separators)."""
    kinds = ["float", "jam", "hardover", "effectiveness", "limits", "bandwidth", "loe", "", "JAM"]
    effectors = ["motor1", "motor6", "motor3", "motor7", "elevon_l", "", "motor1@"]
    values = ["", "@0.5", "@-3", "@2", "@nan", "@inf", "@0.2:0.9", "@0.9:0.2", "@x", "@1:2:3", "@"]
    parts = []
    for _ in range(rng.choice([1, 1, 1, 2, 3])):
        if rng.random() < 0.1:
            parts.append("".join(rng.choice("az:@+.-09 \x00") for _ in range(rng.randint(0, 8))))
        else:
            parts.append(rng.choice(kinds) + rng.choice([":", ":", ""]) + rng.choice(effectors) + rng.choice(values))
    return "+".join(parts)


def test_hostile_failure_names_raise_problem_errors(hexa):
    rng = random.Random(SEED)
    good = 0
    for _ in range(2000):
        name = _failure_name(rng)
        try:
            failure = vehicle_failure(hexa, name, 1.0)
        except ProblemError as exc:
            assert exc.field == "failure", (name, exc)
            continue
        good += 1
        assert failure.name == name and len(failure.actuators) == name.count("+") + 1
    assert 20 < good < 1980  # the generator reaches valid names and invalid ones


def test_failure_positions_are_in_file_units(hexa):
    f = vehicle_failure(hexa, "jam:motor2@0.8+effectiveness:motor1@0.25", 3.0)
    jam, loe = f.actuators
    assert jam.kind == "jam" and jam.index == 1 and jam.position == pytest.approx(0.8 - U0_HOVER)
    assert loe.kind == "effectiveness" and loe.fraction == 0.25 and f.time == 3.0


def _assert_admissible(res, lo, hi):
    assert np.all(np.isfinite(res.effectors)) and np.all(np.isfinite(res.unallocated))
    tol = 1e-9 * np.maximum(1.0, np.abs(hi - lo))
    assert np.all(res.effectors >= lo - tol) and np.all(res.effectors <= hi + tol)


def test_hexa_rotor_loss_told_no_worse_than_blind():
    runs = {told: fly("hexa-x", method="qp", failure="float:motor1", failure_time=4.0, duration=8.0,
                      allocator_knows_failure=told) for told in (False, True)}
    peak = np.asarray(runs[False].settings["design"]["commands"]["peak"])
    rms = {}
    for told, res in runs.items():
        assert not res.diverged
        _assert_admissible(res, 0.0, 1.0)  # the file's limits: rotor commands in [0, 1], trim added back
        summary = res.summary()
        before = np.array([summary["channels"][c]["rms_before"] for c in res.channels])
        assert np.all(before < 0.02 * peak), before / peak  # within 2 % of the command peak before the failure
        rms[told] = np.array([summary["channels"][c]["rms_after"] for c in res.channels]) / peak
        assert res.settings["units"]["effectors"]["motor1"] == "1"
        np.testing.assert_allclose(res.settings["trim_u"], U0_HOVER)
    # seed-free measure: the sum over channels of the post-failure RMS error per command peak
    assert rms[True].sum() <= rms[False].sum(), (rms[True], rms[False])


def test_static_and_baseline_fly(hexa):
    for kw in (dict(method="static"), dict(controller="loopshape")):
        res = fly("hexa-x", duration=2.0, **kw)
        assert not res.diverged and res.settings["controller"] == kw.get("controller", "smc")


def test_vehicle_scenario_refuses_pilots():
    run = VehicleScenario("hexa-x")
    assert run.accepts_failure("float:motor1+jam:motor2@0.6") and not run.accepts_failure("float:motor9")
    with pytest.raises(TypeError, match="pilot"):
        run(pilot="crossover", duration=0.1)


def test_cli_flies_a_users_file(tmp_path):
    path = alloc.load_vehicle("hexa-x").save(tmp_path / "my-hexa.toml")
    out = tmp_path / "run.json"
    res = runner.invoke(app, ["sim", "--vehicle", str(path), "--failure", "float:motor3", "--failure-time", "1",
                              "--duration", "2", "--told", "--design", "crossover=300", "--json", str(out),
                              "--plot", str(tmp_path / "run.png")], prog_name="alloc")
    assert res.exit_code == 0, res.stdout + res.stderr
    summary = json.loads(out.read_text())
    assert summary["failure"] == "float:motor3" and not summary["diverged"]
    assert summary["settings"]["design"]["switching"]["K_rho"] == 300.0
    assert summary["settings"]["units"]["axes"]["roll"] == "N m"
    assert (tmp_path / "run.png").stat().st_size > 10_000
    for args, token in ((["--failure", "float:motor9"], "motor9"), (["--design", "bogus=1"], "bogus"),
                        (["--design", "crossover=-5"], "design.crossover"), (["--pilot", "crossover"], "pilot")):
        bad = runner.invoke(app, ["sim", "--vehicle", str(path), "--duration", "0.1", *args], prog_name="alloc")
        assert bad.exit_code == 2 and token in bad.stderr, (args, bad.stderr)
        assert len(bad.stderr.strip().splitlines()) == 1, bad.stderr
    seed_run = runner.invoke(app, ["sim", "ice", "--design", "crossover=300"], prog_name="alloc")
    assert seed_run.exit_code == 2 and "--design" in seed_run.stderr


def test_plot_units_are_the_files():
    from sim.plots import _units

    res = fly("hexa-x", duration=0.2)
    channels, position, rate = _units(res)
    assert position == "1" and rate == "1/s" and set(channels) == {"p", "q", "r", "w"}


def test_tailless_jammed_surface_flies_blind_and_told():
    """A tip surface (amt_l, 0..60 deg) jammed at 30 deg at t = 4 s.

    Not every jam flies: the same design loses the elevon_l jammed at 0 deg when the jam comes
    at 4 or 6 s (blind and told), and flies it from 8 s on (measured; see the report).
    """
    runs = {told: fly("tailless", method="qp", failure="jam:amt_l@30", failure_time=4.0, duration=8.0,
                      allocator_knows_failure=told) for told in (False, True)}
    peak = np.asarray(runs[False].settings["design"]["commands"]["peak"])
    fv = alloc.load_vehicle("tailless")
    lo, hi = np.array([e.min for e in fv.effectors]), np.array([e.max for e in fv.effectors])
    rms = {}
    for told, res in runs.items():
        assert not res.diverged
        _assert_admissible(res, lo, hi)
        after = res.t >= 4.0 + 0.01
        np.testing.assert_allclose(res.effectors[after, 2], 30.0, atol=1e-9)  # amt_l held where it jammed
        summary = res.summary()
        before = np.array([summary["channels"][c]["rms_before"] for c in res.channels])
        assert np.all(before < 0.02 * peak), before / peak
        rms[told] = np.array([summary["channels"][c]["rms_after"] for c in res.channels]) / peak
        assert np.all(rms[told] < 0.02), rms[told]  # the jam costs little: within 2 % of the command peak
        assert res.settings["units"]["effectors"]["amt_l"] == "deg"
    # jammed at its preferred (mid-range) position, the surface costs a blind allocator little:
    # told is not better here (measured 0.3 % worse in the sum), and no more than 5 % worse
    assert rms[True].sum() <= 1.05 * rms[False].sum(), (rms[True], rms[False])


def test_bench_closedloop_compares_methods_on_a_file(tmp_path):
    path = alloc.load_vehicle("hexa-x").save(tmp_path / "my-hexa.toml")
    args = ["bench", "closedloop", "--vehicle", str(path), "--failure", "float:motor1", "--method", "qp",
            "--method", "static", "--duration", "3", "--failure-time", "1.5", "--json"]
    res = runner.invoke(app, args, prog_name="alloc")
    assert res.exit_code == 0, res.stdout + res.stderr
    rows = {(r["method"], r["told"]): r for r in json.loads(res.stdout)}
    assert set(rows) == {("qp", False), ("qp", True), ("static", False), ("static", True)}
    for r in rows.values():
        assert not r["diverged"] and r["scenario"] == "hexa-x" and r["failure"] == "float:motor1"
        assert np.isfinite(r["p_rms_before"]) and r["p_rms_before"] < 0.1
    assert rows["qp", True]["p_rms_after"] <= rows["qp", False]["p_rms_after"]
    # a fixed matrix cannot be told anything: static's told and blind runs are the same run
    assert rows["static", True]["p_rms_after"] == rows["static", False]["p_rms_after"]
    bad = runner.invoke(app, ["bench", "closedloop", "--vehicle", str(path), "--failure", "jam:rotor9"],
                        prog_name="alloc")
    assert bad.exit_code == 2 and "rotor9" in bad.stderr and len(bad.stderr.strip().splitlines()) == 1


def _random_vehicle(rng: random.Random) -> dict:
    """Seeded: a small vehicle document with a random model (scales 1e-3..1e3, singular columns, unobservable
    outputs, unreachable outputs, trims, every form of actuator dynamics)."""
    g = np.random.default_rng(rng.randrange(2**32))
    n, m = rng.randint(1, 5), rng.randint(1, 5)
    k = rng.randint(1, min(m, 3))
    p = rng.randint(k, n + 2)
    scale = 10.0 ** g.uniform(-3, 3)
    B_axes = g.normal(size=(k, m)) * scale
    if rng.random() < 0.2:
        B_axes[:, 0] = 0.0
    M = g.normal(size=(n, k))
    if rng.random() < 0.2:
        M[:, -1] = 0.0
    B = M @ B_axes + (g.normal(size=(n, m)) * 0.1 * scale if rng.random() < 0.5 else 0.0)
    A = g.normal(size=(n, n)) * rng.choice([0.0, 0.1, 1.0, 10.0])
    C = g.normal(size=(p, n)) if rng.random() < 0.3 else np.eye(p, n)
    if rng.random() < 0.5:  # a well-posed one: every state measured, k rate-like states driven by the axes
        n = p = max(n, k)
        A = g.normal(size=(n, n)) * rng.choice([0.0, 0.1, 1.0])
        M = np.vstack([np.diag(10.0 ** g.uniform(-1, 1, k)), g.normal(size=(n - k, k)) * 0.1])
        B, C = M @ B_axes, np.eye(n)
    dynamics = rng.choice([{"bandwidth": 30.0}, {"poles": [40.0, 100.0]}, {"wn": 20.0, "zeta": 0.7}, None,
                           {"time_constant": 0.05}])
    effectors = []
    for j in range(m):
        lo = rng.choice([-1.0, 0.0, -30.0])
        e = {"name": f"e{j}", "min": lo, "max": max(rng.choice([1.0, 30.0, 0.5]), lo + 0.1)}
        if rng.random() < 0.7:
            e["rate_max"] = rng.choice([1.0, 100.0])
        if dynamics:
            e["dynamics"] = dynamics
        effectors.append(e)
    return {"format": "alloc-vehicle/1", "name": "hostile",
            "axes": [{"name": f"a{i}", "trim": rng.choice([0.0, 0.0, 0.3])} for i in range(k)],
            "effectors": effectors, "effectiveness": {"B": B_axes.tolist()},
            "model": {"states": [f"x{i}" for i in range(n)], "outputs": [f"y{i}" for i in range(p)], "A": A.tolist(),
                      "B": B.tolist(), "C": C.tolist(), "controlled": rng.sample([f"y{i}" for i in range(p)], k)}}


def _hostile_models(cases: int, flights: int) -> None:
    rng = random.Random(SEED)
    designed = flown = 0
    for _ in range(cases):
        try:
            vehicle = vehicle_from_dict(_random_vehicle(rng))
        except ProblemError:
            continue
        try:
            fm = flight_model(vehicle)
        except ProblemError as exc:
            assert (exc.field or "").startswith(("model", "axes")), exc
            continue
        designed += 1
        report = fm.design.report
        assert report["check"]["max_real_eig"] < -report["options"]["stability_margin"]
        assert np.all(np.isfinite(fm.design.smc.rho)) and np.all(fm.design.smc.eps > 0)
        if flown < flights:
            flown += 1
            res = fly(vehicle, duration=0.3, noise=False)
            lo = np.array([e.min for e in vehicle.effectors])
            hi = np.array([e.max for e in vehicle.effectors])
            _assert_admissible(res, lo, hi)
    assert designed > 0


def test_hostile_models_design_or_refuse():
    _hostile_models(cases=20, flights=2)


@pytest.mark.slow
def test_hostile_models_design_or_refuse_many():
    _hostile_models(cases=300, flights=30)


def test_ice_design_file_crosses_near_the_seeds_design():
    """The auto-design of the ICE design file against the seed's own ICE design (Eq 4.27, Table 4-6).

    The seed's switching gain ``rho / eps`` is in axis units (w', p', v' per unit sigma); times the
    rate each axis gives its channel (``C_ctl B W`` with the seed's weighted pseudo-inverse ``W``)
    it is the crossover of step 4b: 868, 966 and 903 rad/s.  The rule here gives 800 (20 x the
    40 rad/s limit frequency).
    """
    import sim.scenarios.ice as ice
    from sim.autodesign import weighted_pinv

    seed = ice.smc_design()
    v = ice.vehicle()
    gain = ice.C[list(ice.CONTROLLED)] @ ice.B @ weighted_pinv(v.B_alloc, v.Wu)
    seed_crossover = seed.rho / seed.eps * np.diag(gain)
    np.testing.assert_allclose(seed_crossover, [868.0, 966.0, 903.0], rtol=2e-3)
    ours = flight_model("ice-design").design
    ratio = ours.report["switching"]["K_rho"] / seed_crossover
    assert np.all((0.8 <= ratio) & (ratio <= 1.25)), ratio
    assert all(num == (100.0,) and den == (1.0, 20.0, 100.0) for num, den in ours.references)  # seed Eq 4.22


# --------------------------------------------------------------------------- the seed's files fly their scenarios
def assert_same_run(a, b) -> None:
    """Every array of two runs equal bit for bit (dtype too), every other field equal; the file's
    ``units`` label is the only setting the file run adds."""
    assert set(vars(a)) == set(vars(b))
    for name, x in vars(a).items():
        y = getattr(b, name)
        if isinstance(x, np.ndarray):
            assert x.dtype == y.dtype and np.array_equal(x, y, equal_nan=True), name
        elif isinstance(x, tuple) and x and isinstance(x[0], np.ndarray):
            assert all(np.array_equal(p, q, equal_nan=True) for p, q in zip(x, y, strict=True)), name
        elif name == "settings":
            assert {k: v for k, v in y.items() if k != "units"} == x
        else:
            assert repr(x) == repr(y), name


SEED_FILE_RUNS = [
    pytest.param("ice", dict(method="qp", failure="seed", failure_time=0.5), id="ice-seed-failure-qp"),
    pytest.param("harv_latdir", dict(method="ganging", failure="failure1", failure_time=0.5,
                                     allocator_knows_failure=True), id="harv-failure1-ganging-told"),
    pytest.param("harv_latdir", dict(method="pinv", failure="failure2", failure_time=0.3, phi_command="filtered_steps",
                                     cross_hedge=False), marks=pytest.mark.slow, id="harv-failure2-steps-no-cross-hedge"),
    pytest.param("ice", dict(method="daisy", controller="loopshape", noise=False), marks=pytest.mark.slow,
                 id="ice-daisy-loopshape"),
    pytest.param("ice", dict(method="static", failure="seed", failure_time=0.5, observer=False),
                 marks=pytest.mark.slow, id="ice-static-no-observer"),
]


@pytest.mark.parametrize("scenario, options", SEED_FILE_RUNS)
def test_seed_vehicle_files_fly_their_scenarios_bit_for_bit(scenario, options):
    """ice.toml and harv.toml carry the scenario's loop ([simulation]): the same run, every array equal."""
    from sim.scenarios import get_scenario

    path = {"ice": "alloc/data/vehicles/ice.toml", "harv_latdir": "alloc/data/vehicles/harv.toml"}[scenario]
    expected = get_scenario(scenario)(duration=1.0, **options)
    assert_same_run(expected, fly(path, duration=1.0, **options))


def test_seed_file_takes_run_settings_and_records_its_units():
    from sim.settings import RunSettings

    settings = RunSettings(method="qp", duration=0.2, noise=False)
    res = fly("alloc/data/vehicles/harv.toml", settings, method="pinv")  # a keyword overrides the settings
    assert res.method == "pinv" and res.settings["duration"] == 0.2 and res.settings["noise"] is False
    assert res.settings["units"]["effectors"] == {n: "deg" for n in res.effector_names}
    with pytest.raises(TypeError, match="design"):
        fly("alloc/data/vehicles/ice.toml", settings, design={"crossover": 100.0})
    with pytest.raises(TypeError, match="unknown option"):
        fly("alloc/data/vehicles/ice.toml", settings, cross_hedge=False)  # ICE's hedges have no groups
    with pytest.raises(TypeError, match="not a run setting"):
        fly("hexa-x", settings, observer=False)
    hexa = fly("hexa-x", settings)  # the auto-designed loop takes the same settings
    assert hexa.method == "qp" and hexa.settings["duration"] == 0.2 and hexa.settings["noise"] is False
    # what plots label the channels and effectors with: the file's [model] units and effector units
    assert hexa.settings["units"]["channels"] == {"p": "rad/s", "q": "rad/s", "r": "rad/s", "w": "m/s"}
    assert set(hexa.settings["units"]["effectors"].values()) == {"1"}


def test_cli_seed_file_and_scenario_print_the_same_summary(tmp_path):
    """``alloc sim --vehicle alloc/data/vehicles/ice.toml`` and ``alloc sim ice``: the same summary and CSV."""
    common = ["--method", "qp", "--failure", "seed", "--failure-time", "0.2", "--duration", "0.4"]
    by_name = runner.invoke(app, ["sim", "ice", *common, "--csv", str(tmp_path / "a.csv")])
    by_file = runner.invoke(app, ["sim", "--vehicle", "alloc/data/vehicles/ice.toml", *common,
                                  "--csv", str(tmp_path / "b.csv")])
    assert by_name.exit_code == 0 and by_file.exit_code == 0, (by_name.output[-500:], by_file.output[-500:])
    a, b = json.loads(by_name.stdout), json.loads(by_file.stdout)
    b["settings"].pop("units", None)
    assert a == b
    assert (tmp_path / "a.csv").read_bytes() == (tmp_path / "b.csv").read_bytes()
    bad = runner.invoke(app, ["sim", "--vehicle", "alloc/data/vehicles/ice.toml", "--failure", "float:de3"])
    assert bad.exit_code == 2 and "unknown failure" in bad.output
    bench = runner.invoke(app, ["bench", "closedloop", "--vehicle", "alloc/data/vehicles/ice.toml",
                                "--failure", "float:de3"])  # refused before any run: the file's failures by name
    # the file's own failures and the failure grammar on its effectors (de3 is the seed's code, not a name)
    assert bench.exit_code == 2 and "unknown failure 'float:de3' for ice" in bench.output
    assert "unknown effector 'de3'" in bench.output and "its failures: seed" in bench.output


def test_comparison_row_of_the_seed_file_is_the_scenarios():
    """One sweep row (benchmarks/compare), the scenario by name and the vehicle file: equal but for timings."""
    from benchmarks.compare.closedloop import run_closed
    from benchmarks.compare.sweep import closed_spec

    spec = closed_spec("ice", "seed", "qp", told=True, seed=3, duration=0.6, failure_time=0.3)
    by_name = run_closed(spec)[0]  # (row, timings, history): the timings are apart from the row
    by_file = run_closed({**spec, "vehicle": "alloc/data/vehicles/ice.toml"})[0]
    assert len(by_name) > 30
    assert json.dumps(by_name, sort_keys=True) == json.dumps(by_file, sort_keys=True)  # nan == nan, floats exact
