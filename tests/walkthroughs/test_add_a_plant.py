"""docs/ARCHITECTURE.md "Add a plant", performed end to end: a plant defined in one module of
this test (the hover's linear model behind the :class:`sim.plant.Plant` contract, its rotors'
lag declared), registered once with :func:`sim.plants.register_plant`, then flown by
``alloc sim --plant NAME`` and :func:`sim.plants.fly_on_plant` through a rotor loss, told;
what it cannot do (a velocity loop, a schedule, a seed scenario) is refused by what it
declares, naming the flag.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from alloc.cli import app
from sim.plant import LinearPlant
from sim.plants import PLANTS, PlantSpec, fly_multirotor, fly_on_plant, register_plant

runner = CliRunner()
NAME = "walk-hover"


class HoverPlant(LinearPlant):
    """The plant of this walk-through: the vehicle's hover model (any physics keeping the
    contract would do) with the rotors' first-order lag the cascade's gains are set from."""

    motor_time_constant = 0.033  # s: the hexa-x rotors' dynamics bandwidth, 30 rad/s

    def __init__(self, fm, *, dt_step, wind=None):
        super().__init__(fm.vehicle, dt_step)
        self.name = NAME


@pytest.fixture(scope="module")
def registered():
    if NAME not in PLANTS:  # step 2: one registration
        register_plant(PlantSpec(NAME, "the hover's linear model (walk-through)", fly_multirotor(NAME, HoverPlant)))
    return NAME


def test_flies_through_a_rotor_loss_from_the_command_line(registered, tmp_path) -> None:
    summary = tmp_path / "run.json"
    r = runner.invoke(app, ["sim", "--vehicle", "hexa-x", "--plant", registered, "--method", "qp", "--failure",
                            "float:motor1", "--failure-time", "1", "--health", "told", "--duration", "3", "--json",
                            str(summary)])
    assert r.exit_code == 0, r.output
    out = json.loads(summary.read_text())
    assert out["settings"]["plant"]["name"] == NAME
    assert not out["diverged"]


def test_the_library_flies_it_and_records_it(registered) -> None:
    result = fly_on_plant("hexa-x", registered, method="qp", failure="float:motor1", failure_time=1.0,
                          health="told", duration=3.0)
    assert result.settings["plant"]["name"] == NAME
    assert np.isfinite(result.output).all() and not result.diverged and result.t[-1] >= 3.0 - 1e-9


@pytest.mark.parametrize("extra, flag", [(["--forward-speed", "2"], "--forward-speed"),
                                         (["--schedule", "tilt=0:10"], "--plant")])
def test_what_it_does_not_declare_is_refused_naming_the_flag(registered, extra, flag) -> None:
    r = runner.invoke(app, ["sim", "--vehicle", "hexa-x", "--plant", registered, "--duration", "1", *extra])
    assert r.exit_code == 2 and flag in r.output, r.output


def test_a_name_is_registered_once(registered) -> None:
    with pytest.raises(ValueError, match=NAME):
        register_plant(PlantSpec(NAME, "again", fly_multirotor(NAME, HoverPlant)))
