"""The schedule in the simulator: ``alloc sim --vehicle FILE --schedule tilt=0:45`` (sim.plants.scheduled).

The reference of the scheduled plant is the linear plant itself (sim.plant.LinearPlant): at a schedule
that stays at the nominal point the two are the same physics; the reference of ``B(x)`` is the vehicle
file's evaluator (alloc.vehicle_file.schedule, tested against a rebuild in tests/alloc/test_schedule.py).
"""

from __future__ import annotations

import json

import numpy as np
import pytest
import typer
from schedule_files import tilting_hexa_document
from typer.testing import CliRunner

from alloc.vehicle_file import vehicle_from_dict
from alloc.vehicle_file.toml_writer import to_toml
from sim.cli import sim_command
from sim.plant import LinearPlant
from sim.plants.scheduled import (
    ScheduledLinearPlant,
    SchedulePath,
    fly_scheduled,
    parse_schedule,
)
from sim.settings import SettingError
from sim.user_vehicle import flight_model

app = typer.Typer()
app.command()(sim_command)
runner = CliRunner()
DT = 0.0005


@pytest.fixture(scope="module")
def tilting():
    fv = vehicle_from_dict(tilting_hexa_document())
    return fv, flight_model(fv)


def test_at_the_nominal_point_the_scheduled_plant_is_the_linear_plant(tilting):
    fv, fm = tilting
    sched = ScheduledLinearPlant(fm.vehicle, DT, fv=fv, path=SchedulePath({"tilt": (0.0, 0.0)}, 1.0),
                                 trim_u=fm.trim_u)
    plain = LinearPlant(fm.vehicle, DT)
    rng = np.random.default_rng(0)
    for _ in range(200):
        u = rng.uniform(-0.05, 0.05, len(plain.effectors))
        ys, yp = sched.step(u, DT), plain.step(u, DT)
    np.testing.assert_allclose(ys, yp, rtol=1e-9, atol=1e-12)


def test_the_plant_follows_b_of_x_and_the_trim_moves_with_it(tilting):
    fv, fm = tilting
    plant = ScheduledLinearPlant(fm.vehicle, DT, fv=fv, path=SchedulePath({"tilt": (45.0, 45.0)}, 1.0),
                                 trim_u=fm.trim_u)
    B45 = fv.scheduled().evaluate({"tilt": 45.0})
    # at rest at the trim command, the tilted rotors' trim thrust no longer holds the weight: the heave
    # acceleration is (B_fz(45) - B_fz(0)) u0 / m (the hover model's w row is B_fz / m)
    w = list(plant.outputs).index("w")
    fz = [a.component for a in fv.axes].index("fz")
    expected = (B45[fz] - np.asarray(fv.B)[fz]) @ fm.trim_u / fv.body.mass
    assert plant.sensed()[w] == pytest.approx(expected, rel=1e-12)
    assert expected > 0  # down: a weaker vertical thrust
    np.testing.assert_allclose(plant.M @ np.asarray(fv.B), fm.vehicle.B, atol=1e-12)


def test_a_schedule_is_read_against_the_declared_variables(tilting):
    fv, _ = tilting
    assert parse_schedule(["tilt=0:45"], fv) == {"tilt": (0.0, 45.0)}
    for bad, words in (("tilt=0:90", "must stay in [0, 60]"), ("speed=0:1", "unknown variable 'speed'"),
                       ("tilt=0", "NAME=START:END"), ("tilt=a:b", "numbers")):
        with pytest.raises(SettingError, match="^schedule: ") as info:
            parse_schedule([bad], fv)
        assert words in str(info.value)
    assert SchedulePath({"tilt": (0.0, 45.0)}, 20.0).at(10.0) == {"tilt": 22.5}


def test_follow_and_frozen_fly_and_say_so(tilting):
    fv, _ = tilting
    follow = fly_scheduled(fv, ["tilt=0:45"], method="qp", duration=3.0, failure=None, allocator="follow")
    frozen = fly_scheduled(fv, ["tilt=0:45"], method="qp", duration=3.0, failure=None, allocator="frozen")
    for r, mode in ((follow, "follow"), (frozen, "frozen")):
        assert not r.diverged and r.t[-1] == pytest.approx(3.0)
        assert r.settings["schedule"] == {"tilt": [0.0, 45.0]} and r.settings["schedule_allocator"] == mode
        assert r.settings["plant"]["name"] == "linear-scheduled" and r.settings["frame_period"] == 0.004
    # the same plant and commands; only the allocator's B differs, so the runs differ
    assert not np.array_equal(follow.effectors, frozen.effectors)


def test_the_command_line_flies_a_schedule_and_refuses_what_it_cannot(tilting, tmp_path):
    path = tmp_path / "hexa-tilt.toml"
    path.write_text(to_toml(tilting_hexa_document()))
    js = tmp_path / "r.json"
    res = runner.invoke(app, ["--vehicle", str(path), "--schedule", "tilt=0:30", "--schedule-allocator", "frozen",
                              "--duration", "1", "--failure", "none", "--json", str(js)])
    assert res.exit_code == 0, res.output
    assert json.loads(js.read_text())["settings"]["schedule"] == {"tilt": [0.0, 30.0]}
    for args, flag in ((["--vehicle", "hexa-x", "--schedule", "tilt=0:30"], "--schedule"),
                       (["--vehicle", str(path), "--schedule", "tilt=0:90"], "--schedule"),
                       (["--vehicle", str(path), "--schedule", "tilt=0:30", "--plant", "rotorpy"], "--schedule"),
                       (["--vehicle", str(path), "--schedule", "tilt=0:30", "--schedule-allocator", "x"],
                        "--schedule-allocator")):
        res = runner.invoke(app, [*args, "--duration", "1"])
        assert res.exit_code == 2 and flag in res.output, res.output
