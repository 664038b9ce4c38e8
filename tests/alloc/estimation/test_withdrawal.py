"""Withdrawal of a detection (alloc.estimation.detection.FailureDetector.withdraw): the health
before the detection is restored, a Withdrawal is recorded and handed out once, the state
round-trips, bad calls name the field."""

from __future__ import annotations

import json

import numpy as np
import pytest

from alloc.estimation import FailureDetector, SampleError, Withdrawal

from test_detection import DT, failed_run, random_vehicle


def detected_jam() -> tuple[FailureDetector, str]:
    rng = np.random.default_rng(7)
    p = random_vehicle(rng)
    det = FailureDetector(p, 0.3, DT, window=0.5)
    U, Y, _ = failed_run(rng, p, "jam", 2, 2.0, 600, 0.3)
    found = []
    for i in range(len(U)):
        found += det.update(U[i], Y[i])
    assert found and found[0].event.effector == p.names[2]
    return det, p.names[2]


def test_withdraw_restores_the_health_before_and_records_it() -> None:
    det, name = detected_jam()
    assert name in det.health
    w = det.withdraw(name, det.last_time + 0.1, "tracking worse with it")
    assert isinstance(w, Withdrawal)
    assert name not in det.health  # healthy before the jam
    assert (w.effector, w.kind, w.reason, w.statistic) == (name, det.detections[-1].event.kind.value,
                                                            "tracking worse with it", None)
    assert w.detection_time == det.detections[-1].time
    assert det.withdrawals == [w]
    assert det.pop_withdrawals() == [w]
    assert det.pop_withdrawals() == []
    assert det.withdrawals == [w]  # kept
    with pytest.raises(SampleError, match="^effector: no detection"):
        det.withdraw(name, det.last_time, "again")


def test_withdrawal_state_round_trips() -> None:
    det, name = detected_jam()
    state = json.loads(json.dumps(det.to_dict()))
    back = FailureDetector.from_dict(det.problem, state)
    w = back.withdraw(name, 9.0, "r")
    again = FailureDetector.from_dict(det.problem, json.loads(json.dumps(back.to_dict())))
    assert again.withdrawals == [w] and again.pop_withdrawals() == [w]
    assert name not in again.health
    old = {k: v for k, v in det.to_dict().items() if k not in ("withdrawals", "unpopped", "active")}
    assert FailureDetector.from_dict(det.problem, old).withdrawals == []  # states stored before withdrawals


def test_withdraw_names_the_field() -> None:
    det, name = detected_jam()
    with pytest.raises(SampleError, match="^effector:"):
        det.withdraw("nope", 1.0, "r")
    with pytest.raises(SampleError, match="^effector:"):
        det.withdraw(3, 1.0, "r")  # type: ignore[arg-type]
    with pytest.raises(SampleError, match="^time:"):
        det.withdraw(name, float("nan"), "r")
    with pytest.raises(SampleError, match="^reason:"):
        det.withdraw(name, 1.0, None)  # type: ignore[arg-type]
    assert name in det.health and det.withdrawals == []
