"""``--health detected`` on every catalogue vehicle, errors named by their setting, and do no harm.

Every vehicle of ``alloc/data/vehicles`` (and the built-in scenarios ``ice`` and ``harv_latdir``
they fly) flies every health mode for two seconds through the CLI; a vehicle file's outputs
with no stated noise are left out of the detector's response set (sim.detection.response_outputs);
the detector's refusals name the run setting they come from, never ``--method``.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

import sim.detection as detection
from alloc.cli import app as alloc_app
from sim.settings import HEALTH_MODES

runner = CliRunner()

CATALOGUE = sorted(p.stem for p in (Path(__file__).parents[2] / "alloc" / "data" / "vehicles").glob("*.toml"))
#: the built-in scenarios flown by name (``--vehicle`` takes a scenario's name too)
SCENARIOS = ("ice", "harv_latdir")


def _sim(*args: str):
    return runner.invoke(alloc_app, ["sim", *args])


def test_the_catalogue_is_the_one_named_in_the_brief():
    assert CATALOGUE == ["harv", "hexa-x", "ice", "ice-design", "ice-mid", "tailless"]


@pytest.mark.parametrize("health", HEALTH_MODES)
@pytest.mark.parametrize("vehicle", [*CATALOGUE, *SCENARIOS])
def test_every_vehicle_flies_every_health_mode(vehicle, health):
    out = _sim("--vehicle", vehicle, "--health", health, "--duration", "2", "--failure", "none", "--seed", "1")
    assert out.exit_code == 0, out.output
    summary = json.loads(out.output[out.output.index("{"):])
    assert summary["settings"]["health"] == health and not summary["diverged"]
    assert ("detections" in summary) == (health == "detected")
    if health == "detected":
        assert summary["detector"]["response_outputs"], summary["detector"]


def test_outputs_without_stated_noise_are_not_tested():
    from sim.user_vehicle import flight_model

    v = flight_model("tailless").vehicle
    rows = detection.response_outputs(v)
    gains = np.zeros(v.C.shape[0])
    gains[list(v.measured)] = v.noise_gains
    # the auto-design states noise on the controlled outputs only (sim.user_vehicle)
    assert rows and all(gains[i] > 0 for i in rows) and set(rows) <= set(v.controlled)
    assert (detection.response_noise_std(v, 0.0005, 0.1) > 0).all()


@pytest.mark.parametrize("args, flag", [
    (["--detector-long-window", "0.3"], "--detector-long-window"),  # shorter than the 0.4 s window
])
def test_a_detector_refusal_names_its_run_setting(args, flag):
    out = _sim("--vehicle", "tailless", "--health", "detected", "--duration", "1", "--failure", "none", *args)
    assert out.exit_code == 2
    assert f"Invalid value for {flag}" in out.output and "--method" not in out.output, out.output


def test_a_vehicle_with_no_noisy_response_output_is_refused_naming_health():
    from sim.user_vehicle import flight_model

    v = flight_model("tailless").vehicle
    from dataclasses import replace

    quiet = replace(v, noise_gains=np.zeros_like(v.noise_gains))
    with pytest.raises(detection.SettingError) as err:
        detection.InLoopDetector(quiet, 0.0005, np.zeros((10, v.C.shape[0])), noise_scale=1.0, actuators=True,
                                 preferred=np.zeros(len(v.actuators)))
    assert err.value.field == "health"
