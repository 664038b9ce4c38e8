"""PX4 ULog replay (alloc.importers.ulog) on a real log.

Fixture ``tests/alloc/data/px4_sitl_quad.ulg`` (152 kB): PX4 SITL quadrotor (SYS_AUTOSTART 10017,
PX4 commit cb09dde6), cut from pyulog's ``test/sample_px4_events.ulg`` (PX4/pyulog commit 3cf1779,
BSD-3-Clause) by pyulog's own reader and writer: the topics vehicle_torque_setpoint,
vehicle_thrust_setpoint and actuator_motors from 15 s to 29 s of the log, every parameter kept.

The check is independent of our allocators: where PX4's motors sit strictly inside (0, 1), its
``control_allocator`` (CA_METHOD 2, pseudo-inverse with desaturation) met the demand exactly, so
PX4's normalised effectiveness times PX4's motors must give the logged demand -- which holds for
the matrix our PX4 importer computes (``normalize="px4"``) to float32 precision, and our
pseudo-inverse then reproduces PX4's motor commands.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("pyulog")

from alloc.exceptions import ProblemError
from alloc.importers.px4 import vehicle_from_params
from alloc.importers.ulog import read_ulog, replay, replay_command

LOG = Path(__file__).parent / "data" / "px4_sitl_quad.ulg"
#: float32 log values: a residual of a few float32 epsilons of the demand (~1e-7)
FLOAT32 = 1e-6


@pytest.fixture(scope="module")
def log():
    return read_ulog(LOG)


def test_reads_the_paired_demands_and_motor_commands(log):
    assert LOG.stat().st_size < 200_000
    assert log.t.size == 140 and log.demand.shape == (140, 6) and log.motors.shape == (140, 4)
    assert np.all(np.diff(log.t) > 0) and 15.0 <= log.t[0] < log.t[-1] <= 29.0
    assert log.params["CA_AIRFRAME"] == 0 and log.params["CA_ROTOR_COUNT"] == 4 and log.params["CA_METHOD"] == 2
    assert np.all((log.motors >= 0.0) & (log.motors <= 1.0))


def test_px4_met_the_demand_through_our_normalised_matrix_where_unsaturated(log):
    fv = vehicle_from_params(log.params, normalize="px4")
    assert fv.axis_names == ("roll", "pitch", "yaw", "fz")
    inside = np.all((log.motors > 1e-3) & (log.motors < 1.0 - 1e-3), axis=1)
    assert inside.sum() >= 100  # most of the flight
    residual = np.array(fv.B) @ log.motors[inside].T - log.demand[inside][:, [0, 1, 2, 5]].T
    assert np.max(np.abs(residual)) < FLOAT32


def test_pinv_reproduces_px4_where_unsaturated_and_every_method_stays_admissible(log):
    inside = np.all((log.motors > 1e-3) & (log.motors < 1.0 - 1e-3), axis=1)
    ours = replay(log, "pinv")
    assert np.max(np.abs(ours.difference[inside])) < FLOAT32
    assert set(np.array(ours.status)[inside]) == {"exact"}
    for method in ("pinv", "qp"):
        r = ours if method == "pinv" else replay(log, method)
        assert np.all(np.isfinite(r.u)) and np.all((r.u >= 0.0) & (r.u <= 1.0)), method
        s = r.summary()
        assert s["samples"] == 140 and len(s["rms_difference"]) == 4 and abs(sum(s["status"].values()) - 1) < 1e-12


def test_bad_logs_and_vehicles_are_named(tmp_path, log):
    with pytest.raises(ProblemError, match="^ulog: cannot read") as info:
        read_ulog(Path(__file__))
    assert info.value.field == "ulog"
    from pyulog import ULog

    partial = ULog(str(LOG), ["vehicle_torque_setpoint"])
    partial.write_ulog(str(tmp_path / "partial.ulg"))
    with pytest.raises(ProblemError, match="has no vehicle_thrust_setpoint, actuator_motors"):
        read_ulog(tmp_path / "partial.ulg")
    with pytest.raises(ProblemError, match="^vehicle: 6 effectors, but the log commands 4 motors"):
        replay(log, vehicle="hexa-x")


def test_command_prints_the_summary_and_writes_csv(tmp_path):
    from typer.testing import CliRunner
    import typer

    app = typer.Typer()
    app.command()(replay_command())
    res = CliRunner().invoke(app, ["--ulog", str(LOG), "--method", "pinv", "--csv", str(tmp_path / "r.csv")])
    assert res.exit_code == 0, res.output
    assert json.loads(res.stdout)["samples"] == 140
    lines = (tmp_path / "r.csv").read_text().splitlines()
    assert len(lines) == 141 and lines[0].startswith("t,v_roll,v_pitch,v_yaw,v_fz,u_motor1")
    bad = CliRunner().invoke(app, ["--ulog", str(tmp_path / "r.csv")])
    assert bad.exit_code == 2


def test_alloc_replay_is_a_registered_command(tmp_path):
    """`alloc replay` reaches the same function through the alloc.commands entry point."""
    from typer.testing import CliRunner

    from alloc.cli import app

    out = tmp_path / "replay.json"
    res = CliRunner().invoke(app, ["replay", "--ulog", str(LOG), "--method", "pinv", "--json", str(out)])
    assert res.exit_code == 0, res.output
    assert json.loads(out.read_text()) == replay(read_ulog(LOG), "pinv").summary()
    bad = CliRunner().invoke(app, ["replay", "--ulog", str(tmp_path / "absent.ulg")])
    assert bad.exit_code == 2 and "ulog: cannot read" in bad.output
