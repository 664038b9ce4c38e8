"""Telemetry: a stored vehicle's detector fed with batches of samples (no HTTP, no database).

A batch is ``n`` samples of the applied commands ``u`` (m), the measured response ``y``
(k: moments or state derivatives, the vehicle's ``B`` rows) and, when the vehicle's detector
is configured with position sensors, the measured positions (m), each at a time ``t`` in
seconds.  :func:`run_batch` replays it through :class:`alloc.estimation.FailureDetector`
(the library's GLR detection and isolation, thresholds from a design false-alarm rate) on
the detector state stored for the vehicle, and returns the new state and the detections.
It is a pure function of (nominal problem, belief, settings, stored state, samples): the
store (:mod:`service.telemetry_store`) commits its result or nothing.

The detector's *belief* is the health it predicts the response with.  It is the vehicle's
committed health plus the detections proposed and not yet decided (:func:`belief`): when the
vehicle's ``health_version`` moved since the state was last aligned (an event posted, a
proposal accepted or rejected) the detector is realigned to it (:func:`realign`: its belief
replaced, its buffers emptied, since their residuals were computed against the old model;
counters, times and detections kept).

Time.  The detector's thresholds assume samples ``sample_time`` apart, so the times are checked
against it (:func:`samples_from`, :func:`run_batch`):

* inside a batch each step is at least half a ``sample_time`` (a repeat, a step back, a
  subnormal step or a stream faster than configured is refused naming ``t/i``) and at most one
  window (:func:`max_step`, ``N * sample_time``): a batch is one run of consecutive samples, and
  a longer step is refused naming ``t/i`` (unit errors such as milliseconds sent as seconds land
  here);
* a batch whose samples fall in time already received (a kept segment, widened by half a
  ``sample_time`` each side) is refused naming the first such ``t/i`` (repeated or out of order:
  a retried batch is never applied twice);
* otherwise a batch that starts within one window after the last sample continues the segment;
  any other start (a gap longer than a window, or a time before the last sample that was never
  received: a clock restarted, or a far-future time accepted earlier) starts a new *segment*:
  the detector's buffers and pending alarm are emptied and it restarts on the new samples (its
  belief, counters and detections kept), and the answer says so (``segment``).  A window longer
  than the gap would straddle samples that do not follow one another.
* a segment that starts before the last sample (``unseen_time``) forgets the time received
  after its start: the clock went back, so what came later was either a far-future time or a
  clock since restarted, and the real samples must be able to reach those times again.  A
  far-future time therefore holds nothing back: the next real batch starts a segment (its
  samples are never before the last real ones), and the far-future range is forgotten.

The state keeps the last :data:`KEPT_SEGMENTS` segments' first and last times (older ones are
forgotten: a repeat of those is taken as new data) and the count of segments started.

Bounds.  The state holds ``2 N`` samples of ``3 m + k + 1`` numbers (``N`` the window in
samples, at most :data:`MAX_WINDOW_SAMPLES`) and at most
:data:`alloc.estimation.detection.MAX_KEPT` detections: at m = 64, k = 6 at most 12,736
numbers.  A batch holds at most :data:`MAX_SAMPLES` samples and is priced before it runs
(:func:`batch_seconds`).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from enum import StrEnum
from typing import Any

import numpy as np

import alloc
from alloc.effector_health import EffectorHealth
from alloc.estimation import Detection, FailureDetector, SampleError, Withdrawal
from alloc.estimation.robust import RobustSettings
from alloc.health import FailureEvent, FailureKind, Health, apply_event, health_from_dict, health_to_dict

__all__ = ["Policy", "DetectorSettings", "Samples", "BatchOutcome", "run_batch", "belief", "realign",
           "batch_seconds", "samples_from", "detection_out", "event_of", "withdrawal_out", "restoring_events", "MAX_SAMPLES", "MAX_WINDOW_SAMPLES",
           "SAMPLE_SECONDS", "ISOLATION_SECONDS", "ISOLATION_SAMPLE_SECONDS", "MIN_STEP_FRACTION", "KEPT_SEGMENTS",
           "max_step", "segments_of", "new_segment"]

#: samples in one batch (HTTP request or WebSocket message), at most
MAX_SAMPLES = 1000
#: a step between samples is at least this fraction of ``sample_time`` (jitter allowed; a faster
#: stream would break the false-alarm design, which assumes ``sample_time``)
MIN_STEP_FRACTION = 0.5
#: segments whose time ranges are remembered to refuse repeats (module docstring)
KEPT_SEGMENTS = 8
#: the detector's window in samples, at most: it fixes the state's size and the cost of a test
MAX_WINDOW_SAMPLES = 32
# The declared cost of the detector, measured by ``python -m benchmarks.bench_telemetry --worst``
# (CPU seconds on the project's 2-core machine) on the most expensive stream found: two
# effectors no response can tell apart, one of them jammed, so that every test alarms and no
# isolation decides (m = 4, 11, 64; N = 4, 16, 32; hop 1 and N / 4).  Each constant is twice
# the measured figure: per effector and test, an isolation took 1.14 ms + 34 us per buffered
# sample (2 N of them); a sample's update and stage-1 test at most 0.29 ms.
#: seconds of one sample's update and stage-1 test
SAMPLE_SECONDS = 6.0e-4
#: seconds of an isolation per tested effector, fixed part
ISOLATION_SECONDS = 2.5e-3
#: seconds of an isolation per tested effector and buffered sample
ISOLATION_SAMPLE_SECONDS = 7.0e-5
# The learnt model's update (model "learnt", alloc.estimation.robust), measured with
# process_time over 300 samples at k = 6 (2026-12-06): 1.44 ms a sample at m = 11, 21.3 ms at
# m = 64; a fixed part and one in ``k m^3`` (the posterior's Cholesky factors), each twice that.
#: seconds of the learnt model's update per sample, fixed part
LEARNT_SAMPLE_SECONDS = 2.8e-3
#: seconds of the learnt model's update per sample and ``k m^3``
LEARNT_CUBE_SECONDS = 2.7e-8


class Policy(StrEnum):
    """What a vehicle's detections become."""

    #: applied at once as health events, exactly as if a client had posted them
    AUTO = "auto"
    #: recorded as proposals a client accepts (then applied as events) or rejects
    CONFIRM = "confirm"


@dataclass(frozen=True)
class DetectorSettings:
    """A vehicle's :class:`~alloc.estimation.FailureDetector` settings (its free parameters,
    each the library's, validated against the vehicle by :meth:`detector`)."""

    sample_time: float
    noise_std: list[float]
    window: float = 0.25
    hop: int | None = None
    false_alarm_rate: float = 0.1
    position_noise_std: list[float] | None = None
    min_confidence: float = 0.95
    #: "learnt": residuals against a nominal model learnt in flight from ``model_uncertainty``
    #: (the library's ``robust``); "exact": the stated model and noise are taken as exact.  The
    #: default is exact: on the ICE silent-jam flight (tests/service/test_telemetry.py)
    #: the learnt model, 1.5 s into its learning, isolated a hard-over of lef_r instead of the
    #: jam of elevon_l that the exact model finds on the first sample after it
    model: str = "exact"
    model_uncertainty: float = 0.2
    #: seconds each applied detection is judged on the detector's own evidence (0: never)
    probation: float = 2.0

    def record(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_record(cls, data: dict[str, Any]) -> DetectorSettings:
        # settings stored before the model option ran the exact model, the default
        return cls(**data)

    def window_samples(self) -> int:
        """``N``, the detector's window in samples (the library's rule: at least 4)."""
        ratio = self.window / self.sample_time  # inf for a sample time near zero: capped, never an int of it
        return max(4, int(round(min(ratio, 1e12))))

    def detector(self, nominal: alloc.Problem) -> FailureDetector:
        """A fresh detector for the vehicle's nominal problem."""
        robust = RobustSettings(model_uncertainty=self.model_uncertainty) if self.model == "learnt" else None
        return FailureDetector(nominal, self.noise_std, self.sample_time, false_alarm_rate=self.false_alarm_rate,
                               window=self.window, hop=self.hop, position_noise_std=self.position_noise_std,
                               min_confidence=self.min_confidence, robust=robust, probation=self.probation)


@dataclass(frozen=True)
class Samples:
    """One batch, validated: ``t`` (n,), ``u`` (n, m), ``y`` (n, k), ``position`` (n, m) or None."""

    t: np.ndarray
    u: np.ndarray
    y: np.ndarray
    position: np.ndarray | None

    def __len__(self) -> int:
        return int(self.t.size)


@dataclass(frozen=True)
class BatchOutcome:
    """What a batch did: the detector's new state, the detections it completed and the
    withdrawals it made (each with the effector's health it restored), and both in time order."""

    state: dict[str, Any]
    detections: list[Detection]
    belief: Health
    samples: int
    last_time: float | None
    #: why this batch started a new segment ("first", "gap", "unseen_time"), or None
    segment: str | None
    segments: int
    withdrawals: list[tuple[Withdrawal, EffectorHealth | None]] = field(default_factory=list)
    #: ("detection", index) and ("withdrawal", index) in the order the detector made them
    order: list[tuple[str, int]] = field(default_factory=list)


def max_step(settings: DetectorSettings) -> float:
    """Seconds between two consecutive samples of one segment, at most: the detector's window
    (``N * sample_time``).  Across a longer gap a test window would hold samples that do not
    follow one another, so the detector restarts (a new segment)."""
    return settings.window_samples() * settings.sample_time


def batch_seconds(settings: DetectorSettings, m: int, n: int) -> float:
    """Declared worst-case seconds of ``n`` samples for a vehicle of ``m`` effectors: each
    sample's update and test, plus an isolation of every effector over the ``2 N`` buffered
    samples at every test (every ``hop`` samples), as when an alarm never resolves."""
    N = settings.window_samples()
    hop = settings.hop or max(1, N // 4)
    k = len(settings.noise_std)
    learnt = LEARNT_SAMPLE_SECONDS + LEARNT_CUBE_SECONDS * k * m ** 3 if settings.model == "learnt" else 0.0
    return n * (SAMPLE_SECONDS + learnt + m * (ISOLATION_SECONDS + ISOLATION_SAMPLE_SECONDS * 2 * N) / hop)


def samples_from(nominal: alloc.Problem, settings: DetectorSettings, t: Any, u: Any, y: Any,
                 position: Any) -> Samples:
    """The batch's arrays, shapes and times checked; :class:`~alloc.estimation.SampleError`
    naming the field (``t``, ``u``, ``y``, ``position``) and the first bad sample."""
    t_arr = np.asarray(t, dtype=float)
    n = t_arr.size
    if t_arr.shape != (n,) or n == 0:
        raise SampleError(f"t: expected a non-empty list of times, got shape {t_arr.shape}", field="t")
    if n > MAX_SAMPLES:
        raise SampleError(f"t: {n} samples; a batch holds at most {MAX_SAMPLES}", field="t")
    arrays = {"u": (u, nominal.m), "y": (y, nominal.k)}
    if position is not None or settings.position_noise_std is not None:
        if position is None:
            raise SampleError("position: this vehicle's detector has position sensors; every sample needs "
                              "their readings", field="position")
        if settings.position_noise_std is None:
            raise SampleError("position: this vehicle's detector has no position sensors "
                              "(position_noise_std = null)", field="position")
        arrays["position"] = (position, nominal.m)
    out: dict[str, np.ndarray] = {}
    for name, (value, width) in arrays.items():
        rows = value if isinstance(value, list) else []
        if len(rows) != n:
            raise SampleError(f"{name}: {len(rows)} rows for {n} times", field=name)
        for i, row in enumerate(rows):
            if len(row) != width:
                raise SampleError(f"{name}/{i}: {len(row)} values, expected {width}", field=f"{name}/{i}")
        out[name] = np.asarray(rows, dtype=float).reshape(n, width)
    steps = np.diff(t_arr)
    shortest, longest = MIN_STEP_FRACTION * settings.sample_time, max_step(settings)
    bad = (steps < shortest) | (steps > longest)
    if bad.any():
        i = int(np.argmax(bad)) + 1
        step = float(t_arr[i] - t_arr[i - 1])
        if step < shortest:
            reason = (f"{float(t_arr[i])!r} s is {step:.6g} s after the previous sample ({float(t_arr[i - 1])!r} s); samples are "
                      f"sample_time = {settings.sample_time:g} s apart (at least half of it): repeated, out of "
                      f"order or faster than configured")
        else:
            reason = (f"{float(t_arr[i])!r} s is {step:.6g} s after the previous sample ({float(t_arr[i - 1])!r} s), more than "
                      f"one window ({longest:g} s): a batch is one run of consecutive samples (send the samples "
                      f"after a gap as a batch of their own: it starts a new segment)")
        raise SampleError(f"t/{i}: {reason}", field=f"t/{i}")
    return Samples(t_arr, out["u"], out["y"], out.get("position"))


def belief(nominal: alloc.Problem, health: Health, proposed: list[FailureEvent]) -> Health:
    """The vehicle's committed ``health`` with the ``proposed`` events (oldest first) applied as
    the detector applies its own findings: each replaces what was known of its effector."""
    for event in proposed:
        _, health = apply_event(nominal, health, FailureEvent(event.effector, FailureKind.REPAIR))
        _, health = apply_event(nominal, health, event)
    return health


def realign(state: dict[str, Any], health: Health) -> dict[str, Any]:
    """The stored detector ``state`` with its belief replaced by ``health`` and its buffers
    emptied (their residuals were against the old belief); counters and times kept.  A
    standing detection (and its probation) on an effector whose health changed is forgotten:
    a client decided that effector (an event, a rejection), the detector must not undo it."""
    out = dict(state)
    old = health_from_dict(state.get("health") or {})
    changed = {name for name in set(old) | set(health) if old.get(name) != health.get(name)}
    for key in ("active", "probations"):
        if isinstance(out.get(key), dict):
            out[key] = {name: v for name, v in out[key].items() if name not in changed}
    out["health"] = health_to_dict(health)
    out["buffer"] = {"U": [], "K": [], "R": [], "Q": [], "T": []}
    out["pending"] = None
    out["since_test"] = 0
    return out


def segments_of(state: dict[str, Any] | None) -> dict[str, Any]:
    """The stored segments of a detector state: ``{"count": started, "kept": [[first, last], ...]}``
    (the last :data:`KEPT_SEGMENTS`, newest last)."""
    state = state or {}
    found = state.get("segments")
    if found is None and state.get("last_time") is not None:  # a state stored before segments: one, open
        return {"count": 1, "kept": [[state["last_time"], state["last_time"]]]}
    return {"count": 0, "kept": []} if found is None else found


def new_segment(state: dict[str, Any]) -> dict[str, Any]:
    """``state`` restarted for a new segment: buffers, pending alarm and last time emptied;
    belief, counters and detections kept."""
    out = dict(state)
    out["buffer"] = {"U": [], "K": [], "R": [], "Q": [], "T": []}
    out["pending"] = None
    out["since_test"] = 0
    out["last_time"] = None
    return out


def _segment_start(settings: DetectorSettings, segments: dict[str, Any], t: np.ndarray) -> str | None:
    """Why a batch of times ``t`` starts a new segment (``None``: it continues the last one);
    SampleError naming the first ``t/i`` that falls in time already received."""
    half = MIN_STEP_FRACTION * settings.sample_time
    kept = segments["kept"]
    for first, last in kept:  # a kept range covers (first - half, last + half): a repeat or too close
        lo, hi = first - half, last + half
        inside = (t > lo) & (t < hi)
        if inside.any():
            i = int(np.argmax(inside))
            step = "" if not i else f" (the batch started at {float(t[0])!r} s)"
            raise SampleError(f"t/{i}: {float(t[i])!r} s falls within samples already received ({first!r} s to "
                              f"{last!r} s, each +- half a sample_time){step}: repeated or out of order",
                              field=f"t/{i}")
        if t[0] <= lo and t[-1] >= hi:  # spans a received range: its first sample after it is the one named
            i = int(np.argmax(t >= hi))
            raise SampleError(f"t/{i}: the batch runs from {float(t[0])!r} s over samples already received "
                              f"({first!r} s to {last!r} s): repeated or out of order", field=f"t/{i}")
    if not kept:
        return "first"
    step = float(t[0]) - kept[-1][1]
    if 0 < step <= max_step(settings):
        return None
    return "gap" if step > 0 else "unseen_time"


def run_batch(nominal: alloc.Problem, settings: DetectorSettings, state: dict[str, Any] | None,
              align_to: Health | None, samples: Samples) -> BatchOutcome:
    """Replay ``samples`` through the vehicle's detector (``state``, or a fresh one), first
    realigned to ``align_to`` when given; the stored state is never modified.

    The batch's times against those already received (module docstring): SampleError naming
    ``t/i`` for a repeat, or a new segment.
    """
    if state is None:
        state = settings.detector(nominal).to_dict()
    segments = segments_of(state)
    state = {key: value for key, value in state.items() if key != "segments"}
    if align_to is not None:
        state = realign(state, align_to)
    reason = _segment_start(settings, segments, samples.t)
    kept = [list(r) for r in segments["kept"]]
    first, last = float(samples.t[0]), float(samples.t[-1])
    if reason is None:
        kept[-1][1] = last
    else:
        state = new_segment(state)
        if reason == "unseen_time":  # the clock went back: what was received after it is forgotten
            kept = [r for r in kept if r[0] < first]
        kept = [*kept, [first, last]][-KEPT_SEGMENTS:]
    detector = FailureDetector.from_dict(nominal, state)
    found: list[Detection] = []
    withdrawn: list[tuple[Withdrawal, EffectorHealth | None]] = []
    order: list[tuple[str, int]] = []
    position = samples.position
    for i in range(len(samples)):
        for d in detector.update(samples.u[i], samples.y[i], None if position is None else position[i],
                                 time=float(samples.t[i])):
            order.append(("detection", len(found)))
            found.append(d)
        for w in detector.pop_withdrawals():  # made at the end of an update: the health it restored is current
            order.append(("withdrawal", len(withdrawn)))
            withdrawn.append((w, detector.health.get(w.effector)))
    count = segments["count"] + (reason is not None)
    out = {**detector.to_dict(), "segments": {"count": count, "kept": kept}}
    last_time = detector.last_time
    return BatchOutcome(out, found, dict(detector.health), detector.samples,
                        None if math.isinf(last_time) else last_time, reason, count, withdrawn, order)


def detection_out(d: Detection) -> dict[str, Any]:
    """A detection as the service answers it: the effector, kind and parameters of its event,
    the decision time, the confidence and the evidence of both stages."""
    record = d.to_dict()
    event = record.pop("event")
    return {
        "effector": event.pop("effector"), "kind": event.pop("kind"), "params": event,
        "time": d.time, "onset": d.onset, "confidence": d.confidence, "improvement": d.improvement,
        "evidence": {"statistic": d.statistic, "threshold": d.threshold, "samples": d.samples,
                     "effector_confidence": d.effector_confidence, "kind_confidence": d.kind_confidence,
                     "parameter": d.parameter, "parameter_std": d.parameter_std},
    }


def withdrawal_out(w: Withdrawal) -> dict[str, Any]:
    """A withdrawal as the service answers it (the library's record)."""
    return w.to_dict()


def restoring_events(name: str, before: EffectorHealth | None) -> list[FailureEvent]:
    """The events that give effector ``name`` the health ``before`` whatever it has now: a
    repair, then each failure of ``before`` (:mod:`alloc.health`'s told rules compose them)."""
    events = [FailureEvent(name, FailureKind.REPAIR)]
    if before is None:
        return events
    if before.effectiveness != 1.0:
        events.append(FailureEvent(name, FailureKind.EFFECTIVENESS, fraction=before.effectiveness))
    if before.floating:
        events.append(FailureEvent(name, FailureKind.FLOAT))
    if before.limits is not None:
        events.append(FailureEvent(name, FailureKind.LIMITS, lo=before.limits[0], hi=before.limits[1]))
    if before.rate_limits is not None:
        events.append(FailureEvent(name, FailureKind.RATE_LIMITS, rate_min=before.rate_limits[0],
                                   rate_max=before.rate_limits[1]))
    if before.jam_position is not None:
        events.append(FailureEvent(name, FailureKind.JAM, position=before.jam_position))
    return events


def event_of(detection: dict[str, Any]) -> FailureEvent:
    """The :class:`~alloc.health.FailureEvent` of a detection as :func:`detection_out` gives it."""
    return FailureEvent(detection["effector"], FailureKind(detection["kind"]), **detection["params"])

