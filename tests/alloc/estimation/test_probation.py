"""Withdrawal on the detector's own evidence (alloc.estimation.probation): a detection forced
false on a healthy plant is withdrawn within its probation; real jams, hard-overs, floats and
losses of effectiveness are not; the evidence round-trips through the stored state; the
improvement of every detection is a fraction."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import strategies as st

from alloc.estimation import Detection, FailureDetector, SampleError, StateError
from alloc.estimation.probation import DECISIVE_LOG, REASON
from alloc.health import FailureEvent, FailureKind

from test_detection import DT, commands, failed_run, random_vehicle

REAL_KINDS = ("jam", "hardover", "float", "effectiveness")


def forced_false(robust: bool, seed: int, probation: float = 2.0) -> tuple[FailureDetector, np.ndarray, np.ndarray,
                                                                          str]:
    """A detector that has run 2 s on a healthy plant, then is told (through its internals, as a
    wrong isolation would) that effector 1 is jammed at +8; and 3 s more of healthy data."""
    rng = np.random.default_rng(seed)
    p = random_vehicle(rng)
    det = FailureDetector(p, 0.3, DT, window=0.5, robust=True if robust else None, probation=probation)
    U = commands(rng, p.m, 500)
    Y = U @ np.asarray(p.B).T + rng.normal(size=(500, p.k)) * 0.3
    for i in range(200):
        assert det.update(U[i], Y[i]) == []
    name = p.names[1]
    false = Detection(event=FailureEvent(name, FailureKind.JAM, position=8.0), time=det.last_time,
                      onset=det.last_time - 0.2, statistic=30.0, threshold=20.0, confidence=0.99,
                      effector_confidence=0.99, kind_confidence=1.0, parameter=8.0, parameter_std=0.1, samples=20)
    det._emit(false)
    return det, U[200:], Y[200:], name


@pytest.mark.parametrize("robust", [False, True])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_false_detection_is_withdrawn_within_its_probation(robust: bool, seed: int) -> None:
    det, U, Y, name = forced_false(robust, seed)
    t_det = det.last_time
    assert det.health[name].jam_position == 8.0
    for i in range(len(U)):
        det.update(U[i], Y[i])
    ws = det.pop_withdrawals()
    assert [w.effector for w in ws] == [name]
    w = ws[0]
    assert w.reason == REASON and w.detection_time == t_det
    assert w.statistic >= 2 * DECISIVE_LOG  # -2 ln(Bayes factor) at least 2 ln 100
    assert t_det < w.time <= t_det + 2.0 + 1e-9
    assert name not in det.health  # healthy again, as before the detection


def test_no_probation_no_withdrawal() -> None:
    det, U, Y, name = forced_false(False, 0, probation=0.0)
    for i in range(len(U)):
        det.update(U[i], Y[i])
    assert det.pop_withdrawals() == [] and name in det.health  # refined perhaps, never withdrawn


@pytest.mark.parametrize("robust", [False, True])
@pytest.mark.parametrize("kind", REAL_KINDS)
def test_real_failures_are_not_withdrawn(robust: bool, kind: str) -> None:
    """Seeded worlds (failure on effector 2 at 2 s, 6 s of data): no detection of the failed
    effector's true kind (a jam and a hard-over hold it alike) is ever withdrawn, and the effector
    ends failed.  A wrong kind may be (measured: the learnt model's first report of a loss of
    effectiveness in world 1 was a jam, withdrawn 0.12 s later, the loss found at 3.3 s); so may
    false detections on other effectors (that is the rule's job)."""
    for seed in range(3 if not robust else 2):
        rng = np.random.default_rng(seed)
        p = random_vehicle(rng)
        det = FailureDetector(p, 0.3, DT, window=0.5, robust=True if robust else None)
        U, Y, _ = failed_run(rng, p, kind, 2, 2.0, 600, 0.3)
        found = []
        for i in range(len(U)):
            found += det.update(U[i], Y[i])
        failed = p.names[2]
        assert any(d.event.effector == failed for d in found), (seed, kind)
        same = {"jam", "hardover"} if kind in ("jam", "hardover") else {kind}
        assert [w for w in det.withdrawals if w.effector == failed and w.kind in same] == [], (seed, kind)
        assert failed in det.health, (seed, kind)
        for d in found:
            assert 0.0 <= d.improvement <= 1.0 and 0.0 <= d.confidence <= 1.0
        mine = [d for d in found if d.event.effector == failed]
        assert mine[0].improvement > 0.5  # a real failure explains most of its residual


def test_probation_round_trips_mid_way() -> None:
    det, U, Y, name = forced_false(False, 1)
    for i in range(3):  # a false jam at +8 is withdrawn within a few tenths of a second
        det.update(U[i], Y[i])
    state = json.loads(json.dumps(det.to_dict()))
    assert set(state["probations"]) == {name} and state["probations"][name]["samples"] == 3
    assert -DECISIVE_LOG < state["probations"][name]["llr"] < 0
    back = FailureDetector.from_dict(det.problem, state)
    for i in range(3, len(U)):
        det.update(U[i], Y[i])
        back.update(U[i], Y[i])
    a, b = det.pop_withdrawals(), back.pop_withdrawals()
    assert len(a) == 1 and a == b


@pytest.mark.parametrize("bad, field", [
    ({"nope": {"time": 0.0, "end": 1.0, "llr": 0.0, "samples": 0, "rate": 0.0}}, "probations"),
    ("x", "probations"),
    ("llr", "probations.llr"),
    ("samples", "probations.samples"),
    ("end", "probations.end"),
])
def test_stored_probations_are_checked(bad: object, field: str) -> None:
    det, U, Y, name = forced_false(False, 1)
    det.update(U[0], Y[0])
    state = json.loads(json.dumps(det.to_dict()))
    if bad in ("llr", "samples", "end"):
        state["probations"][name][bad] = {"llr": float("nan"), "samples": -1, "end": -5.0}[bad]
    else:
        state["probations"] = bad
    with pytest.raises(StateError, match=f"^{field}"):
        FailureDetector.from_dict(det.problem, state)


def test_detections_stored_without_improvement_load() -> None:
    det, U, Y, name = forced_false(False, 1)
    state = det.to_dict()
    for d in state["detections"]:
        d.pop("improvement")
    assert FailureDetector.from_dict(det.problem, state).detections[-1].improvement is None


_numbers = st.one_of(st.floats(allow_nan=True, allow_infinity=True, width=64),
                     st.floats(-1e3, 1e3), st.sampled_from([0.0, 1e-300, 1e50, -1e50, 1e51]))


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow],
          phases=[Phase.explicit, Phase.reuse, Phase.generate])  # shrinking a stream takes minutes
@given(st.data())
def test_hostile_streams_raise_only_sample_errors(data: st.DataObject) -> None:
    """A detector on probation (a false jam standing) fed hostile samples: anything may be
    refused, only ever with SampleError, and the probation's numbers stay finite."""
    robust = data.draw(st.booleans())
    det, U, Y, name = forced_false(robust, 0)
    m, k = det.problem.m, det.problem.k
    t = det.last_time
    for _ in range(data.draw(st.integers(1, 40))):
        t += data.draw(st.sampled_from([DT, DT, -DT, 0.0, 1e-12, 10.0]))
        if data.draw(st.booleans()):
            i = data.draw(st.integers(0, len(U) - 1))
            u, y = U[i] * data.draw(st.sampled_from([1.0, 1e6, -1e30])), Y[i]
        else:
            u = data.draw(st.lists(_numbers, min_size=m, max_size=m))
            y = data.draw(st.lists(_numbers, min_size=k, max_size=k + data.draw(st.integers(0, 1))))
        try:
            det.update(u, y, time=t)
        except SampleError:
            pass
        for rec in det._probations.values():
            assert math.isfinite(rec["llr"])
    if not robust:  # the robust learner's sums may leave the stored domain (|x| <= 1e50): not round-tripped here
        FailureDetector.from_dict(det.problem, json.loads(json.dumps(det.to_dict())))


@pytest.mark.parametrize("robust", [False, True])
def test_overwhelming_evidence_stays_in_the_stored_domain(robust: bool) -> None:
    """Whitened columns of 1e40: one sample's log ratio is about -1e82 (exact).  Every update is
    taken (none refused), the accumulated numbers stay within |x| <= 1e50 and the state loads.
    (At this scale round-off alone leaves the health before unfit: nothing is withdrawn.)"""
    rng = np.random.default_rng(5)
    p = random_vehicle(rng)
    big = type(p)(np.asarray(p.B) * 1e30, p.umin, p.umax, rate_min=p.rate_min, rate_max=p.rate_max, names=p.names)
    det = FailureDetector(big, 1e-10, DT, window=0.5, robust=True if robust else None)
    det._emit(Detection(event=FailureEvent(p.names[1], FailureKind.JAM, position=8.0), time=0.0, onset=0.0,
                        statistic=30.0, threshold=20.0, confidence=0.99, effector_confidence=0.99, kind_confidence=1.0,
                        parameter=8.0, parameter_std=0.1, samples=1))
    U = commands(rng, p.m, 40)
    lowest = 0.0
    for i in range(40):
        det.update(U[i], U[i] @ np.asarray(big.B).T, time=(i + 1) * DT)
        for rec in det._probations.values():
            assert abs(rec["llr"]) <= 1e50 and 0 <= rec["ss_before"] <= 1e50
            lowest = min(lowest, rec["llr"])
        FailureDetector.from_dict(big, json.loads(json.dumps(det.to_dict())))
    assert det.samples == 40
    if not robust:
        assert lowest == -1e50  # held at the domain's edge, not beyond



def imprecise_jam(robust: bool, seed: int) -> tuple[FailureDetector, np.ndarray, np.ndarray, str]:
    """Effector 1 really jammed at 5 from 2 s, noise 0.05; the detector told (as an isolation
    would report it) a jam at an estimate whose error is drawn from its own std 0.02; then 1 s
    in which effector 1 is commanded within 0.005 of the true jam, where 'nothing failed'
    predicts the response about as well as the truth, and better than an estimate off by more."""
    rng = np.random.default_rng(seed)
    p = random_vehicle(rng)
    det = FailureDetector(p, 0.05, DT, window=0.5, robust=True if robust else None)
    U = commands(rng, p.m, 300)
    U[200:, 1] = 5.0 + rng.normal(0.0, 0.005, 100)
    actual = U.copy()
    actual[200:, 1] = 5.0
    Y = actual @ np.asarray(p.B).T + rng.normal(size=(300, p.k)) * 0.05
    for i in range(200):
        det.update(U[i], Y[i])
    name = p.names[1]
    estimate = 5.0 + 0.02 * float(rng.normal())
    told = Detection(event=FailureEvent(name, FailureKind.JAM, position=estimate), time=det.last_time,
                     onset=det.last_time, statistic=30.0, threshold=20.0, confidence=0.99, effector_confidence=0.99,
                     kind_confidence=1.0, parameter=estimate, parameter_std=0.02, samples=4)
    det._emit(told)
    return det, U[200:], Y[200:], name


def _withdrawn(robust: bool, seeds: range) -> int:
    count = 0
    for seed in seeds:
        det, U, Y, name = imprecise_jam(robust, seed)
        for i in range(len(U)):
            det.update(U[i], Y[i])
        count += any(w.effector == name for w in det.pop_withdrawals())
    return count


@pytest.mark.parametrize("robust", [False, True])
def test_an_imprecise_estimate_of_a_real_jam_is_rarely_withdrawn(robust: bool, monkeypatch) -> None:
    """The belief is the mixture over its parameter (the estimate and its std): samples that
    cannot tell the truth from 'nothing failed' do not condemn an estimate that is off by what
    its std says it may be.  Ville's bound for the mixture: at most 1 in 100 real jams withdrawn
    (2 of 30 allowed here; measured 0 of 30).  Judged as an exact position (the point belief,
    forced here), 13 of the same 30 real jams were withdrawn (7 with the learnt model) -- a service stream withdrew a jam one sample after its
    detection so (estimate 3.13, std 0.04, re-detected at 3.03)."""
    import alloc.estimation.probation as probation

    seeds = range(30)
    mixture = _withdrawn(robust, seeds)
    monkeypatch.setattr(probation, "_WRT", {})  # the point belief
    point = _withdrawn(robust, seeds)
    assert mixture <= 2 and point >= 5, (mixture, point)
