"""docs/ARCHITECTURE.md "Add a vehicle", performed end to end: a user's quad X described only
by a file (rotor geometry and a hover model written here, not bundled), named through
``ALLOC_VEHICLE_PATH``, then read by every tool: the library, ``alloc vehicles``,
``allocate``, ``ams``, the controllability report after a rotor loss and a closed-loop flight
with the auto-designed controller through that loss.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from typer.testing import CliRunner

import alloc
from alloc import controllability, vehicles
from alloc.health import EffectorHealth
from alloc.cli import app

runner = CliRunner()
MASS, INERTIA = 1.2, (0.011, 0.011, 0.021)  # kg, kg m^2: this walk-through's quad, nobody's airframe
ARM = 0.18  # m

AXES = (("roll", "N m"), ("pitch", "N m"), ("yaw", "N m"), ("thrust", "N"))
HEADER = ('format = "alloc-vehicle/1"\nname = "walk-quad"\ndescription = "walk-through quad X, 1.2 kg"\n'
          + "".join(f'\n[[axes]]\nname = "{a}"\nunit = "{u}"\n' for a, u in AXES)
          + 'wrench = "fz"\ntrim = {trim!r}\n')  # the thrust axis: body z force, hover at -m g
ROTOR = """
[[effectors]]
name = "m{i}"
kind = "rotor"
unit = "1"
min = 0.0
max = 1.0
rate_max = 8.0
dynamics = {{ bandwidth = 25.0 }}
rotor = {{ position = [{x!r}, {y!r}, 0.0], axis = [0.0, 0.0, -1.0], ct = 5.0, km = {km!r} }}
"""


def _rows(a: np.ndarray) -> str:
    return "[\n" + "".join("  [" + ", ".join(repr(float(x)) for x in row) + "],\n" for row in a) + "]"


def quad_text(with_model: bool) -> str:
    """Step 1: the file.  Rotors at 45, 135, 225, 315 deg, alternating spin."""
    text = HEADER.format(trim=-MASS * 9.81)
    for i, deg in enumerate((45, 135, 225, 315), start=1):
        a = math.radians(deg)
        text += ROTOR.format(i=i, x=ARM * math.cos(a), y=ARM * math.sin(a), km=0.05 if i % 2 else -0.05)
    if not with_model:
        return text
    # the hover model the closed loop needs: attitude kinematics, rate and heave dynamics,
    # its input matrix the effectiveness divided by the inertia and the mass
    B = _load(text).problem().B
    n = 7  # phi theta psi p q r w
    A = np.zeros((n, n))
    A[0, 3] = A[1, 4] = A[2, 5] = 1.0
    Bm = np.zeros((n, B.shape[1]))
    Bm[3:6] = B[:3] / np.array(INERTIA)[:, None]
    Bm[6] = B[3] / MASS
    names = '["phi", "theta", "psi", "p", "q", "r", "w"]'
    return text + (f"\n[model]\nstates = {names}\noutputs = {names}\nA = {_rows(A)}\nB = {_rows(Bm)}\n"
                   f"C = {_rows(np.eye(n))}\nD = {_rows(np.zeros((n, B.shape[1])))}\n"
                   'controlled = ["p", "q", "r", "w"]\n')


def _load(text: str, tmp=None):
    import tempfile
    from pathlib import Path

    folder = Path(tmp or tempfile.mkdtemp())
    path = folder / "walk-quad.toml"
    path.write_text(text)
    return alloc.load_vehicle(path)


@pytest.fixture
def fleet(tmp_path, monkeypatch):
    """Step 2: a folder of vehicle files on ALLOC_VEHICLE_PATH makes each file a name."""
    folder = tmp_path / "fleet"
    folder.mkdir()
    path = folder / "walk-quad.toml"
    path.write_text(quad_text(with_model=True))
    monkeypatch.setenv(vehicles.VEHICLE_PATH_ENV, str(folder))
    return path


def cli(*args: str) -> dict:
    out = runner.invoke(app, list(args))
    assert out.exit_code == 0, out.output
    return json.loads(out.stdout)


def test_step1_the_file_is_validated_with_the_field_path(tmp_path):
    bad = quad_text(with_model=False).replace("rate_max = 8.0", "rate_max = -8.0", 2)
    path = tmp_path / "bad.toml"
    path.write_text(bad)
    with pytest.raises(alloc.AllocError, match=r"effectors\[0\]\.rate_max"):
        alloc.load_vehicle(path)


def test_steps_2_and_3_every_tool_reads_the_users_vehicle(fleet):
    vehicle = alloc.load_vehicle(fleet)
    p = vehicle.problem()
    assert (p.k, p.m) == (4, 4) and vehicle.axis_names == ("roll", "pitch", "yaw", "thrust")
    # X geometry: equal and opposite roll arms, the four rotors sharing the hover thrust
    assert np.allclose(p.B[3], -5.0) and np.allclose(np.abs(p.B[0]), 5.0 * ARM * math.sqrt(0.5))

    listed = cli("vehicles", "--json")
    assert any(r["name"] == "walk-quad" and r["origin"] == str(fleet) for r in listed)

    hover = alloc.allocate(p, [0.0, 0.0, 0.0, -MASS * 9.81], "qp")
    by_name = cli("allocate", "--vehicle", "walk-quad", "--v", f"0,0,0,{-MASS * 9.81!r}", "--method", "qp", "--json")
    assert by_name["u"] == hover.u.tolist() and hover.status is alloc.Status.EXACT
    assert np.allclose(hover.u, MASS * 9.81 / 20.0)  # 4 rotors x 5 N each

    assert cli("ams", "summary", "--vehicle", "walk-quad", "--json")["k"] == 4

    # a quad that loses a rotor keeps three independent directions out of four, no axis on its
    # own, and cannot hover with zero yaw moment: the lost direction is mostly yaw
    lost = controllability.report(vehicle, {"m1": EffectorHealth(effectiveness=0.0)})
    assert (lost.nominal_rank, lost.rank, lost.independent_axes) == (4, 3, ())
    assert lost.reference_attainable is False
    (direction,) = lost.uncontrollable_directions
    assert np.argmax(np.abs(direction)) == 2 and abs(direction[2]) > 0.8


def test_step3_the_closed_loop_flies_the_users_vehicle(fleet, tmp_path):
    out = tmp_path / "run.json"
    res = runner.invoke(app, ["sim", "--vehicle", "walk-quad", "--method", "qp", "--failure", "effectiveness:m1@0.5",
                              "--duration", "4", "--failure-time", "2", "--told", "--json", str(out)])
    assert res.exit_code == 0, res.output
    summary = json.loads(out.read_text())
    assert summary["scenario"] == "walk-quad" and summary["failure"] == "effectiveness:m1@0.5"
    assert summary["diverged"] is False
    assert summary["settings"]["design"], "the section 4.3 design choices are recorded"
