"""RotorPy in forward flight: the cascade's velocity loop (sim.plant_control.VelocityHold), --forward-speed,
and the ArduPilot Octa X of the rotor-loss benchmark (benchmarks/bench_rotor_loss.py)."""

from __future__ import annotations

import json

import numpy as np
import pytest
import typer
from typer.testing import CliRunner

from alloc.importers.ardupilot import vehicle_from_frame
from alloc.vehicle_file import vehicle_from_dict
from benchmarks.bench_rotor_loss import octa_document
from sim.cli import sim_command
from sim.plant_control import VelocityHold

app = typer.Typer()
app.command()(sim_command)
runner = CliRunner()


def test_the_ramp_reaches_the_speed_at_the_stated_acceleration():
    hold = VelocityHold(speed=5.0)
    assert hold.reference(0.0) == (0.0, 1.0) and hold.reference(2.5) == (2.5, 1.0)
    assert hold.reference(5.0) == (5.0, 0.0) and hold.reference(12.0) == (5.0, 0.0)
    assert VelocityHold(speed=-3.0).reference(1.0) == (-1.0, -1.0)


def test_octa_x_is_ardupilots_octa_x():
    # each moment row of the geometry's B is ArduPilot's factor row (setup_octa_matrix, FRAME_TYPE 1) times a
    # positive number; thrust is up (fz negative) where ArduPilot's throttle factor is positive
    octa = np.array(vehicle_from_dict(octa_document()).B, dtype=float)
    ap = np.array(vehicle_from_frame("octa-x").B, dtype=float)
    for i in range(3):
        scale = octa[i] / ap[i]
        assert np.all(scale > 0) and np.ptp(scale) < 1e-9 * scale.max()
    assert np.all(octa[3] < 0) and np.all(ap[3] > 0)


rotorpy = pytest.importorskip("rotorpy", reason="rotorpy (the [plants] extra) does not import here")

from sim.plants import fly_on_plant  # noqa: E402


def test_five_metres_per_second_held_level_without_a_failure():
    r = fly_on_plant("hexa-x", "rotorpy", method="qp", failure=None, duration=12.0, forward_speed=5.0)
    e = r.extra
    assert not r.diverged
    # measured: 4.90 m/s at 12 s (the velocity integral still closing the drag), altitude within 1 mm
    assert e["v_north_mps"][-1] == pytest.approx(5.0, abs=0.2) and abs(e["v_east_mps"][-1]) < 0.01
    assert np.max(np.abs(e["altitude_m"])) < 0.05
    assert np.degrees(e["theta_setpoint"][-1]) < -3.0  # nose down against the drag
    assert r.settings["forward_speed"] == 5.0 and r.settings["control_law"]["velocity"]["speed"] == 5.0


def test_rotor_lost_at_five_metres_per_second_told_qp_holds_attitude_and_gives_up_yaw():
    r = fly_on_plant("hexa-x", "rotorpy", method="qp", failure="float:motor1", health="told", duration=20.0,
                     forward_speed=5.0)
    e, after = r.extra, r.t >= 10.0
    assert not r.diverged
    # measured in still air: roll error RMS 3.4 deg, pitch 0.2 deg, 0.23 m lost, heading 73 deg at the end
    roll_rms = np.degrees(np.sqrt(np.mean((e["phi"] - e["phi_setpoint"])[after] ** 2)))
    assert roll_rms < 6.0
    assert np.min(e["altitude_m"][after]) > -1.0
    assert abs(np.degrees(e["psi"][-1])) > 30.0  # the yaw the lost rotor's torque takes is not fought
    assert e["v_north_mps"][-1] == pytest.approx(5.0, abs=0.3)


def test_forward_speed_is_refused_off_rotorpy_and_out_of_range(tmp_path):
    res = runner.invoke(app, ["--vehicle", "hexa-x", "--forward-speed", "5", "--duration", "1"])
    assert res.exit_code == 2 and "--forward-speed" in res.output
    res = runner.invoke(app, ["--vehicle", "hexa-x", "--plant", "rotorpy", "--forward-speed", "50", "--duration",
                              "0.1"])
    assert res.exit_code == 2 and "--forward-speed" in res.output and "20" in res.output
    js = tmp_path / "r.json"
    res = runner.invoke(app, ["--vehicle", "hexa-x", "--plant", "rotorpy", "--forward-speed", "2", "--duration", "1",
                              "--failure", "none", "--json", str(js)])
    assert res.exit_code == 0, res.output
    assert json.loads(js.read_text())["settings"]["forward_speed"] == 2.0
