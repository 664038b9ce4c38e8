"""``--detector-model``: the learnt nominal model keeps a detected flight quiet in a world whose
plant is not the model; the exact detector, the control, does not."""

from __future__ import annotations

import pytest

from sim.scenarios import get_scenario
from sim.settings import SettingError


@pytest.mark.parametrize("world", [{"model_error": 0.2}, {"model_error": 0.2, "turbulence": "moderate"}])
def test_no_failure_no_detection_with_the_learnt_model(world):
    fly = get_scenario("ice")
    common = dict(method="qp", seed=1, duration=60.0, health="detected", dt=0.005, frame_period=0.01, **world)
    exact = fly(detector_model="exact", **common).summary()
    learnt = fly(detector_model="learnt", **common).summary()
    assert exact["detections"], "the control: the exact detector must detect something in this world"
    assert learnt["detections"] == [] and not learnt["diverged"]
    assert learnt["detector"]["design"]["model"] == "learnt"


def test_a_bad_model_names_the_setting():
    with pytest.raises(SettingError) as info:
        get_scenario("ice")(method="qp", duration=1.0, health="detected", detector_model="bayes")
    assert info.value.field == "detector_model"
