"""Request and response bodies of the telemetry endpoints (:mod:`service.routes.telemetry`).

Sizes are capped in the schema: a batch holds at most :data:`service.telemetry.MAX_SAMPLES`
samples, each row at most ``m <= 64`` commands and ``k <= 6`` responses; every number is
finite and at most 1e9 in magnitude; a batch of bad rows is refused at its first bad row.
"""

from __future__ import annotations

from datetime import datetime
from typing import Annotated, Any, Literal

from pydantic import BaseModel, Field, StrictBool

import alloc

from .config import MAX_AXES, MAX_EFFECTORS, MAX_MAGNITUDE
from .errors import InvalidRequest, field_error
from .schemas import AxisVector, EffectorVector, EventOut, Finite, HealthOut, _In, json_int
from .telemetry import MAX_SAMPLES, MAX_WINDOW_SAMPLES, DetectorSettings

__all__ = ["TelemetryConfigIn", "TelemetryBatchIn", "TelemetryOut", "TelemetryResult", "DetectionOut", "WithdrawalOut",
           "ProposalOut", "ProposalList", "ProposalDecided"]

Positive = Annotated[float, Field(strict=True, gt=0, le=MAX_MAGNITUDE, allow_inf_nan=False)]
Seconds = Annotated[float, Field(strict=True, gt=0, le=3600, allow_inf_nan=False)]


class TelemetryConfigIn(_In):
    """``PUT /v1/vehicles/{id}/telemetry``: the vehicle's policy and its detector's settings
    (:class:`alloc.estimation.FailureDetector`'s parameters; defaults the library's)."""

    policy: Literal["auto", "confirm"] = Field(default="confirm", description=(
        "auto: detections become health events at once; confirm: they are proposed "
        "(GET .../proposals) for a client to accept or reject"))
    sample_time: Seconds = Field(description="seconds between samples (the detector's thresholds assume it)")
    noise_std: Positive | Annotated[list[Positive], Field(min_length=1, max_length=MAX_AXES)] = Field(
        description="std of the white noise on each response axis (a number: every axis; a list: k values, the "
                    "vehicle's axes, 422 otherwise)")
    window: Seconds = Field(default=0.25, description=f"seconds per stage-1 test; at most {MAX_WINDOW_SAMPLES} "
                                                      f"samples (and at least 4)")
    hop: json_int(ge=1, le=MAX_WINDOW_SAMPLES) | None = Field(
        default=None, description="samples between tests (default a quarter window)")
    false_alarm_rate: Annotated[float, Field(strict=True, gt=0, le=3.6e9, allow_inf_nan=False)] = Field(
        default=0.1, description="design false alarms per hour")
    position_noise_std: Positive | Annotated[list[Positive], Field(min_length=1, max_length=MAX_EFFECTORS)] | None = \
        Field(default=None, description="position sensor noise (null: no position sensors; a list: m values, the "
                                         "vehicle's effectors, 422 otherwise)")
    min_confidence: Annotated[float, Field(strict=True, gt=0, lt=1, allow_inf_nan=False)] = Field(
        default=0.95, description="posterior needed to report (effector and kind)")
    model: Literal["learnt", "exact"] = Field(default="exact", description=(
        "learnt: residuals against a nominal model learnt in flight from model_uncertainty, with a learnt noise "
        "scale and correlation (alloc.estimation.robust); exact: the vehicle's B and noise_std taken as exact "
        "(the stage-1 statistic exactly chi-square when they are)"))
    model_uncertainty: Annotated[float, Field(strict=True, ge=0, le=10, allow_inf_nan=False)] = Field(
        default=0.2, description="model learnt: the stated relative uncertainty of each effectiveness entry, one "
                                 "standard deviation (0.2: within 20 %); ignored by the exact model")
    probation: Annotated[float, Field(strict=True, ge=0, le=3600, allow_inf_nan=False)] = Field(
        default=2.0, description="seconds each detection is judged on the detector's own evidence after it is "
                                 "applied: withdrawn when the residuals favour the health before it by a Bayes "
                                 "factor of 100 or more (Jeffreys' decisive); 0: never")
    reset: StrictBool = Field(default=False, description=(
        "true: start a new detector even if nothing else changes (buffers, segments and counters "
        "dropped; health and proposals kept). A PUT that changes a setting always does; one that "
        "changes only the policy keeps the detector's state"))

    def to_settings(self, nominal: alloc.Problem) -> DetectorSettings:
        """The validated settings for the vehicle (422 naming the field otherwise)."""
        noise = _vector("noise_std", self.noise_std, nominal.k)
        position = None if self.position_noise_std is None else _vector("position_noise_std",
                                                                        self.position_noise_std, nominal.m)
        settings = DetectorSettings(sample_time=self.sample_time, noise_std=noise, window=self.window, hop=self.hop,
                                    false_alarm_rate=self.false_alarm_rate, position_noise_std=position,
                                    min_confidence=self.min_confidence, model=self.model,
                                    model_uncertainty=self.model_uncertainty, probation=self.probation)
        n = settings.window_samples()
        if n > MAX_WINDOW_SAMPLES:
            reason = (f"{self.window:g} s at {self.sample_time:g} s per sample is {n} samples; at most "
                      f"{MAX_WINDOW_SAMPLES} (the detector's state and cost grow with it)")
            raise InvalidRequest(f"window: {reason}", [field_error("window", reason)])
        if self.hop is not None and self.hop > n:
            reason = f"{self.hop} samples between tests, more than the window's {n}"
            raise InvalidRequest(f"hop: {reason}", [field_error("hop", reason)])
        return settings


def _vector(name: str, value: float | list[float], n: int) -> list[float]:
    if isinstance(value, list):
        if len(value) != n:
            reason = f"{len(value)} values, expected {n} (or one number)"
            raise InvalidRequest(f"{name}: {reason}", [field_error(name, reason)])
        return [float(x) for x in value]
    return [float(value)] * n


#: said of every vector whose length is the vehicle's (the schema states only the caps)
_PER_VEHICLE = (": n rows as t has, each of the vehicle's length (m effectors, k axes; the schema states only "
                "the caps), 422 naming the field otherwise")


class TelemetryBatchIn(_In):
    """``POST /v1/vehicles/{id}/telemetry`` (and one WebSocket message): ``n`` samples, in time order,
    each after the last one already received."""

    t: Annotated[list[Finite], Field(min_length=1, max_length=MAX_SAMPLES, fail_fast=True, description=(
        "sample times, s: consecutive steps of half a sample_time to one window; a batch reaching into time "
        "already received is 422 naming t/i; a gap longer than the window or time never received starts "
        "a new segment (the answer's segment)"))]
    u: Annotated[list[EffectorVector], Field(min_length=1, max_length=MAX_SAMPLES, fail_fast=True,
                                             description=f"applied commands, n x m{_PER_VEHICLE}")]
    y: Annotated[list[AxisVector], Field(min_length=1, max_length=MAX_SAMPLES, fail_fast=True,
                                         description="measured responses (the rows of B: moments or state "
                                                     f"derivatives), n x k{_PER_VEHICLE}")]
    position: Annotated[list[EffectorVector], Field(min_length=1, max_length=MAX_SAMPLES, fail_fast=True)] | None = \
        Field(default=None, description=f"measured positions, n x m (with position sensors only){_PER_VEHICLE}")


class TelemetryOut(BaseModel):
    vehicle_id: str
    policy: Literal["auto", "confirm"]
    settings: dict[str, Any] = Field(description="the detector's settings, vectors expanded")
    revision: int = Field(description="writes to this vehicle's telemetry state so far")
    samples: int
    last_time: float | None
    alarms: int = Field(description="stage-1 alarms so far (isolated or not)")
    unisolated_alarms: int = Field(description="alarms dropped without a decision (ambiguous)")
    segments: int = Field(description="segments started since the detector started (a gap longer than the window, "
                                      "or time never received before the last sample, starts one)")
    health_version: int
    pending_proposals: int
    withdrawals: list[dict[str, Any]] = Field(default_factory=list, description=(
        "the detector's withdrawals, oldest first (the last 64): effector, kind, time, detection_time, reason, "
        "statistic (twice the log Bayes factor for the health before)"))


class DetectionOut(BaseModel):
    effector: str
    kind: str
    params: dict[str, float]
    time: float = Field(description="s, the sample time the detection was decided at")
    onset: float = Field(description="s, the estimated start of the failure")
    confidence: float = Field(ge=0, le=1, description=(
        "how sure: the posterior of this effector and of a kind with the same consequence, among every kind on "
        "every movable effector (equal priors, BIC-penalised likelihoods), in [0, 1]"))
    improvement: float | None = Field(default=None, ge=0, le=1, description=(
        "how much better: the fraction of the whitened residual sum of squares over the fitted samples, under the "
        "model before the detection, that the detection explains (1 - SS_belief / SS_before, clipped to [0, 1]); "
        "null for detections stored before it was computed"))
    evidence: dict[str, float | int | None] = Field(
        description="statistic and threshold of the stage-1 test (chi-square under no failure), samples fitted, "
                    "effector and kind confidences, the estimated parameter and its std")
    applied: bool = Field(description="true: recorded as a health event (policy auto)")
    event_seq: int | None = Field(description="the event it became (the health_version after it)")
    proposal_id: int | None = Field(description="policy confirm: the proposal to accept or reject")


class WithdrawalOut(BaseModel):
    effector: str
    kind: str = Field(description="the failure kind withdrawn")
    time: float = Field(description="s, the sample time of the withdrawal")
    detection_time: float = Field(description="s, the decision time of the detection withdrawn")
    reason: str
    statistic: float | None = Field(description=(
        "twice the log Bayes factor of the health before against the detection over its probation (at least "
        "2 ln 100 = 9.21 when the detector withdrew it)"))
    applied: bool = Field(description="true: recorded as health events restoring the health before (policy auto)")
    event_seq: int | None = Field(description="policy auto: the last of those events (the health_version after it)")
    proposal_id: int | None = Field(description="policy confirm: the pending proposal marked withdrawn, if any")


class TelemetryResult(BaseModel):
    vehicle_id: str
    accepted: int = Field(description="samples of this batch processed (all of them)")
    samples: int = Field(description="samples processed for this vehicle so far")
    last_time: float | None
    policy: Literal["auto", "confirm"]
    detections: list[DetectionOut]
    withdrawals: list[WithdrawalOut] = Field(description=(
        "detections the detector withdrew during this batch, on its own evidence (probation)"))
    segment: Literal["first", "gap", "unseen_time"] | None = Field(description=(
        "why this batch started a new segment (the detector restarted on it: buffers and pending alarm "
        "emptied): its first batch, a gap longer than the window after the last sample, or a time before "
        "it never received (a clock restarted, or a far-future time earlier); null: it continued the last"))
    segments: int = Field(description="segments started so far")
    health_version: int = Field(description="the vehicle's health version after this batch")


class ProposalOut(BaseModel):
    id: int
    status: Literal["pending", "accepted", "rejected", "withdrawn"] = Field(description=(
        "withdrawn: the detector withdrew the detection (its probation) while the proposal was pending"))
    effector: str
    kind: str
    params: dict[str, float]
    detection: dict[str, Any]
    health_version: int = Field(description="the vehicle's health version when proposed")
    event_seq: int | None
    created_at: datetime
    decided_at: datetime | None


class ProposalList(BaseModel):
    vehicle_id: str
    items: list[ProposalOut]


class ProposalDecided(BaseModel):
    proposal: ProposalOut
    event: EventOut | None = Field(description="the event an accepted proposal became")
    health: HealthOut


def as_arrays(body: TelemetryBatchIn) -> dict[str, Any]:
    """The batch's fields for :func:`service.telemetry.samples_from`."""
    return {"t": body.t, "u": body.u, "y": body.y, "position": body.position}

