"""The plant contract (sim.plant), LinearPlant, and the Python plant loop against the compiled engine.

The equivalence reference is the compiled engine itself (sim.engine.simulate) on the same LoopSpec:
the plant loop with LinearPlant and the engine's law in numpy (sim.plant_control.EngineController)
must reproduce it.  Measured here: identical to the last bit.  Tolerance 1e-12 relative to each
signal's peak: the two compute the same products in the same order, but numba's compiled dot and
numpy's may reach a BLAS that orders a sum differently on another machine.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from alloc import vehicles
from alloc.exceptions import AllocError
from sim.engine import _inputs, simulate
from sim.plant import LinearPlant, Plant
from sim.plant_control import EngineController
from sim.plant_loop import fly_plant
from sim.settings import LoopSpec, SettingError
from sim.user_vehicle import flight_model

EQUIVALENCE_RTOL = 1e-12
DURATION, DT, FAIL_AT = 3.0, 0.0005, 1.5


@pytest.fixture(scope="module")
def hexa():
    return flight_model("hexa-x")


def _spec(fm, health: str, frame_period: float | None = None) -> LoopSpec:
    n = int(round(DURATION / DT)) + 1
    return LoopSpec(
        scenario="hexa-x", vehicle=fm.vehicle, references=fm.design.references, controller=fm.design.smc,
        commands=fm.commands(np.arange(n) * DT), pilots=(), failure=fm.failure("float:motor1", FAIL_AT),
        method="qp", duration=DURATION, output_bound=fm.output_bound, health=health, record_every=1,
        method_options=vehicles.method_options(fm.source, "qp", None), frame_period=frame_period)


@pytest.mark.parametrize("health, frame_period", [("told", None), ("blind", 0.002), ("detected", None)])
def test_linear_plant_in_the_plant_loop_reproduces_the_engine(hexa, health, frame_period):
    spec = _spec(hexa, health, frame_period)
    engine = simulate(spec)
    n = int(round(DURATION / DT)) + 1
    k, ny = len(hexa.vehicle.controlled), hexa.vehicle.C.shape[0]
    noise = _inputs(spec, np.arange(n) * DT)[:, k:k + ny]  # the engine's own sensor noise, same seed
    loop = fly_plant(
        LinearPlant(hexa.vehicle, DT), EngineController(spec), hexa.vehicle, method="qp",
        method_options=spec.method_options, duration=DURATION, dt=DT, frame_steps=spec.frame_steps(),
        failure=spec.failure, health=health, noise=noise, output_bound=hexa.output_bound,
        alloc_options=dict(rate_aware=spec.rate_aware, preferred=spec.preferred, rate_horizon=spec.rate_horizon,
                           rate_window=spec.rate_window),
        detection=dict(noise_scale=spec.noise_scale, long_window=spec.detector_long_window))
    assert not engine.diverged and not loop.diverged
    assert loop.t.shape == engine.t.shape
    for name in ("output", "reference", "pseudo", "effectors", "unallocated"):
        a, b = getattr(engine, name), getattr(loop, name)
        assert np.max(np.abs(a - b)) <= EQUIVALENCE_RTOL * max(1.0, np.max(np.abs(a))), name
    # the run did something: the failure moved the effectors and the loop tracked the sum of sines
    assert np.max(np.abs(engine.effectors[engine.t >= FAIL_AT, 0] - engine.effectors[engine.t >= FAIL_AT, 0][0])) > 0
    assert np.max(np.abs(engine.output)) > 0.1
    np.testing.assert_array_equal(loop.allocator_status, engine.allocator_status)
    if health == "detected":  # the same detections at the same instants, the same monitor
        assert engine.detections and loop.detections == engine.detections
        assert loop.withdrawals == engine.withdrawals and loop.detector == engine.detector


def test_linear_plant_keeps_the_contract(hexa):
    plant = LinearPlant(hexa.vehicle, DT)
    assert isinstance(plant, Plant)
    y0 = plant.reset(seed=3)
    assert y0.shape == (len(plant.outputs),) and not np.any(y0)
    assert plant.effectors == tuple(hexa.vehicle.effector_names)
    u = np.full(6, 0.1)
    y = plant.step(u, 4 * DT)
    assert np.all(np.isfinite(y)) and y[plant.outputs.index("w")] < 0.0  # more thrust: climbing (w down positive)
    assert np.all(plant.positions() > 0.0)
    plant.fail(0, "float")
    plant.step(u, 0.1)
    assert plant.describe()["failures"] == [{"effector": "motor1", "kind": "float", "params": {}}]
    json.dumps(plant.describe())
    assert set(plant.state()) == set(plant.outputs)
    # a jam without a position holds the position at the instant of failure (the kind's default)
    plant.reset(seed=0)
    plant.step(u, 0.05)
    held = plant.positions()[1]
    plant.fail(1, "jam")
    plant.step(-u, 0.2)
    assert plant.positions()[1] == held
    assert plant.executed()[0].params["position"] == held


def test_linear_plant_refuses_a_step_that_is_not_whole(hexa):
    plant = LinearPlant(hexa.vehicle, 0.002)
    with pytest.raises(AllocError) as info:
        plant.step(np.zeros(6), 0.003)
    assert info.value.field == "dt"
    with pytest.raises(AllocError) as info:
        plant.fail(0, "no-such-kind")
    assert "no-such-kind" in str(info.value)


def test_plant_loop_refuses_an_unknown_health_mode(hexa):
    spec = _spec(hexa, "told")
    with pytest.raises(SettingError) as info:
        fly_plant(LinearPlant(hexa.vehicle, DT), EngineController(spec), hexa.vehicle, method="qp", duration=0.01,
                  dt=DT, health="oracle")
    assert info.value.field == "health"
