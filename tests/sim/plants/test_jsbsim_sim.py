"""``alloc sim --plant jsbsim:f22``: the JSBSim F-22 in the plant loop, from the command line.

The reference is :func:`sim.plants.jsbsim_loop.fly`, the F-22's own loop (docs/plants-jsbsim.md): the plant
loop flies the same control law, the same allocator and the same plant, so the outputs agree to the bit.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
import typer
from typer.testing import CliRunner

pytest.importorskip("jsbsim", reason="jsbsim (the [plants] extra) does not import here")

from sim.cli import sim_command
from sim.plants import fly_on_plant
from sim.plants.jsbsim_loop import fly

app = typer.Typer()
app.command()(sim_command)
runner = CliRunner()


def test_the_bar_flies_20_s_without_diverging(tmp_path):
    # the bar, as typed: no --vehicle, the aircraft's own linearisation is the design's model
    js = tmp_path / "f22.json"
    res = runner.invoke(app, ["--plant", "jsbsim:f22", "--method", "qp", "--failure", "none", "--duration", "20",
                              "--json", str(js)])
    assert res.exit_code == 0, res.output
    summary = json.loads(js.read_text())
    assert summary["diverged"] is False and summary["duration"] == pytest.approx(20.0)
    s = summary["settings"]
    assert s["plant"]["name"] == "jsbsim:f22" and s["controller"] == "smc" and s["method"] == "qp"
    assert summary["allocator_calls"] == 2401  # 20 s at JSBSim's 1/120 s, one frame per step
    # the doublets are tracked: roll peaks at 10 deg/s commanded; no channel's error beyond 3 deg/s
    assert all(ch["max_before"] < 3.0 for ch in summary["channels"].values())
    assert s["real_time_factor"] > 1.0


def test_the_plant_loop_is_the_f22_loop_to_the_bit():
    reference = fly(duration=3.0, failure=("stab_l", "jam", {"position": 0.0}), failure_time=1.0, told=True)
    result = fly_on_plant(None, "jsbsim:f22", duration=3.0, method="qp", failure="jam:stab_l@0", failure_time=1.0,
                          health="told")
    for i, name in enumerate(reference.output_names):
        np.testing.assert_array_equal(result.extra[name], reference.outputs[:, i], err_msg=name)
    assert result.settings["failure"] == "jam:stab_l@0" and result.settings["health"] == "told"


def test_stabilator_jam_told_flies_blind_diverges():
    # docs/plants-jsbsim.md: jammed at trim at 5 s, the told loop flies the doublets, the blind one diverges
    # (command-fed observers) 4.6 s after the failure
    kw = {"duration": 12.0, "method": "qp", "failure": "jam:stab_l@0", "failure_time": 5.0}
    told = fly_on_plant(None, "jsbsim:f22", health="told", **kw)
    blind = fly_on_plant(None, "jsbsim:f22", health="blind", **kw)
    assert not told.diverged and told.duration == pytest.approx(12.0)
    assert blind.diverged and blind.duration == pytest.approx(9.6, abs=0.05)


@pytest.mark.parametrize(("args", "flag", "words"), [
    (["--plant", "jsbsim:f16"], "--plant", "jsbsim:f22"),
    (["--plant", "jsbsim:f22", "--turbulence", "light"], "--turbulence", "atmosphere"),
    (["--plant", "jsbsim:f22", "--vehicle", "hexa-x"], "--plant", "not a JSBSim F-22 model"),
])
def test_what_it_cannot_fly_is_refused_in_one_line(args, flag, words):
    res = runner.invoke(app, [*args, "--duration", "1"])
    assert res.exit_code == 2
    assert flag in res.output and words in res.output


def test_sensed_response_is_the_linear_models_near_trim():
    # sensed = x' - A x from JSBSim's own accelerations: zero at the trim, B u after a small stabilator step
    # (the linear model's B; the linearisation's own check allows 5 % on the response)
    from alloc import vehicles
    from sim.plants.jsbsim import JSBSimPlant
    from sim.plants.jsbsim_linear import VEHICLE_FILE

    plant = JSBSimPlant()
    plant.reset(seed=0)
    assert np.max(np.abs(plant.sensed())) < 1e-3
    B = np.asarray(vehicles.get_vehicle(VEHICLE_FILE).model.arrays()[1], dtype=float)
    u = np.array([0.5, 0.5, 0.0, 0.0, 0.0])
    for _ in range(24):  # 0.2 s: the actuators reach the command
        plant.step(u, plant.h)
    q = list(plant.outputs).index("q")
    expected = B[q] @ plant.positions()
    assert plant.sensed()[q] == pytest.approx(expected, rel=0.05)


def test_detected_flies_and_its_beliefs_are_recorded():
    # measured: the linear model's detector believes the nozzle jammed at 2.9 s with nothing failed (the
    # nozzle's table is kinked at trim, 1.9 to 1 nose-down to nose-up); the flight is unharmed
    r = fly_on_plant(None, "jsbsim:f22", method="qp", failure=None, health="detected", duration=6.0)
    assert not r.diverged and r.settings["health"] == "detected"
    assert [d["effector"] for d in r.detections] == ["tvc"]


def test_the_criteria_of_a_plant_loop_are_fractions_of_its_demands():
    from sim.criteria import FAILED_RMS_FRACTION, NOMINAL_PEAK_FRACTION, demand_criteria

    d = np.array([0.0, 2.0, -2.0, 0.0])
    table = demand_criteria("loop", {"q": (d, "q doublet")})
    limits = table.limits()
    assert limits["q_rms_after"] == pytest.approx(FAILED_RMS_FRACTION * np.sqrt(2.0))
    assert limits["q_max_before"] == pytest.approx(NOMINAL_PEAK_FRACTION * 2.0)
