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
    (["--plant", "jsbsim:f22", "--health", "detected"], "--health", "blind or told"),
    (["--plant", "jsbsim:f22", "--turbulence", "light"], "--turbulence", "atmosphere"),
    (["--plant", "jsbsim:f22", "--vehicle", "hexa-x"], "--plant", "not a JSBSim F-22 model"),
])
def test_what_it_cannot_fly_is_refused_in_one_line(args, flag, words):
    res = runner.invoke(app, [*args, "--duration", "1"])
    assert res.exit_code == 2
    assert flag in res.output and words in res.output
