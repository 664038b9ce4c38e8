"""Request and response bodies (pydantic), separate for input and output.

Sizes are capped in the schema so the caps are visible in the OpenAPI document:
``m <= 64`` effectors, ``k <= 6`` axes, batches of at most 10,000 demands, AMS
requests of at most 256 directions.  Numbers must be finite and at most ``1e9`` in
magnitude (``MAX_MAGNITUDE``), non-zero weights at least ``1e-9``: JSON has no NaN or
infinity, and the literals ``NaN``/``Infinity`` (which Python's parser accepts) are
rejected with 422.  Types are strict: ``true`` is not a number and not an effector
index, ``"1.5"`` is not a number.  An unlimited rate is written ``null``.
"""

from __future__ import annotations

from datetime import datetime
from typing import Annotated, Any, Literal, Union

import numpy as np
from pydantic import (
    AfterValidator, BaseModel, BeforeValidator, ConfigDict, Discriminator, Field, PrivateAttr, StrictInt, WithJsonSchema, model_validator,
)

import alloc
from alloc.health import PARAMETERS, FailureKind, KindSpec, Range
from alloc.registry import DEFAULT_METHOD

from .config import MAX_AXES, MAX_BATCH, MAX_DIRECTIONS, MAX_EFFECTORS, MAX_MAGNITUDE, MIN_WEIGHT

Finite = Annotated[float, Field(strict=True, allow_inf_nan=False, ge=-MAX_MAGNITUDE, le=MAX_MAGNITUDE)]
Rate = Annotated[float | None, Field(strict=True, allow_inf_nan=False, ge=-MAX_MAGNITUDE, le=MAX_MAGNITUDE,
                                     description="units/s; null = unlimited")]


def _weight_entry(w: float) -> float:
    if w != 0.0 and abs(w) < MIN_WEIGHT:
        raise ValueError(f"a non-zero weight must be at least {MIN_WEIGHT:g} in magnitude, got {w:g}")
    return w


# the schema states the rule the validator applies (0, or at least MIN_WEIGHT in magnitude):
# stated as a plain number range, schema-valid weights such as 1e-288 got 422 (issue 39)
WeightEntry = Annotated[Finite, AfterValidator(_weight_entry), WithJsonSchema({"anyOf": [
    {"type": "number", "const": 0},
    {"type": "number", "minimum": MIN_WEIGHT, "maximum": MAX_MAGNITUDE},
    {"type": "number", "minimum": -MAX_MAGNITUDE, "maximum": -MIN_WEIGHT}],
    "description": f"0, or at least {MIN_WEIGHT:g} in magnitude"})]
EffectorVector = Annotated[list[Finite], Field(min_length=1, max_length=MAX_EFFECTORS)]
AxisVector = Annotated[list[Finite], Field(min_length=1, max_length=MAX_AXES)]
WeightVector = Annotated[list[WeightEntry], Field(min_length=1, max_length=MAX_EFFECTORS)]
Weight = WeightVector | Annotated[list[WeightVector], Field(min_length=1, max_length=MAX_EFFECTORS)]
# Printable text only: a NUL byte, accepted by SQLite, is an error in PostgreSQL text columns.
_PRINTABLE = r"^[^\x00-\x1f\x7f]*$"
Label = Annotated[str, Field(strict=True, min_length=1, max_length=64, pattern=_PRINTABLE)]
MethodName = Annotated[str, Field(strict=True, min_length=1, max_length=64, examples=["pinv", "qp"])]
Options = Annotated[dict[str, Any], Field(max_length=16, description="method options, see GET /v1/methods")]


def _integral(value: Any) -> Any:
    """A float with no fractional part as the int it is: JSON Schema's ``integer`` (the type the
    schema states) includes ``22.0`` (issue 39: schemathesis sent it and got 422)."""
    if isinstance(value, float) and value.is_integer():
        return int(value)
    return value


def json_int(**bounds: Any) -> Any:
    """An integer within ``bounds`` (``Field``'s ``ge``, ``le``, ...) as JSON Schema means it:
    ``22`` or ``22.0``; never ``true``, ``"22"`` or ``22.5``.  (The bounds go before the
    validator: after it, pydantic writes them into the schema as unknown keywords.)"""
    return Annotated[StrictInt, Field(**bounds), BeforeValidator(_integral)]


EffectorRef = Label | json_int(ge=0, lt=MAX_EFFECTORS)


#: members of one JSON object in a request, at most (the largest model has 17 fields): checked
#: before the fields, so a body of 40,000 unknown members costs one error, not 40,000
MAX_MEMBERS = 64


class _In(BaseModel):
    model_config = ConfigDict(extra="forbid")

    @model_validator(mode="before")
    @classmethod
    def _bounded_members(cls, data: Any) -> Any:
        if isinstance(data, dict) and len(data) > MAX_MEMBERS:
            raise ValueError(f"{len(data):,} members; a request object has at most {MAX_MEMBERS}")
        return data


# ---------------------------------------------------------------- problems
class ProblemIn(_In):
    """The fields of :class:`alloc.Problem` (seed Eq 1.14); shapes are checked by the library."""

    B: Annotated[list[EffectorVector], Field(min_length=1, max_length=MAX_AXES,
                                             description="effectiveness matrix, k rows x m columns")]
    umin: EffectorVector
    umax: EffectorVector
    up: EffectorVector | None = Field(default=None, description="preferred position (default 0 clipped)")
    Wu: Weight | None = Field(default=None, description="preference weight: m-vector (diagonal) or m x m")
    Wv: Weight | None = Field(default=None, description="moment-error weight: k-vector (diagonal) or k x k")
    rate_min: Annotated[list[Rate], Field(min_length=1, max_length=MAX_EFFECTORS)] | None = None
    rate_max: Annotated[list[Rate], Field(min_length=1, max_length=MAX_EFFECTORS)] | None = None
    names: Annotated[list[Label], Field(min_length=1, max_length=MAX_EFFECTORS)] | None = None
    axes: Annotated[list[Label], Field(min_length=1, max_length=MAX_AXES)] | None = None

    def problem_fields(self) -> dict[str, Any]:
        """Keyword arguments of :class:`alloc.Problem` (``null`` rates become infinite)."""
        fields = self.model_dump(include=set(ProblemIn.model_fields), exclude_none=True)
        for name, inf in (("rate_min", -np.inf), ("rate_max", np.inf)):
            if name in fields:
                fields[name] = [inf if r is None else r for r in fields[name]]
        return fields

    def to_problem(self) -> alloc.Problem:
        return alloc.Problem(**self.problem_fields())


class ProblemOut(BaseModel):
    B: list[list[float]]
    umin: list[float]
    umax: list[float]
    up: list[float]
    Wu: list[list[float]]
    Wv: list[list[float]]
    rate_min: list[float | None]
    rate_max: list[float | None]
    names: list[str]
    axes: list[str]

    @classmethod
    def of(cls, problem: alloc.Problem) -> ProblemOut:
        return cls.model_validate(problem.to_dict())


# ------------------------------------------------------------- allocation
class _Demand(_In):
    method: MethodName = DEFAULT_METHOD
    options: Options = Field(default_factory=dict)


class _Single(_Demand):
    v: AxisVector = Field(description="demand (virtual control), k values")
    u_prev: EffectorVector | None = Field(default=None, description="previous command, for rate limits")
    dt: Annotated[float, Field(strict=True, gt=0, le=3600, allow_inf_nan=False)] | None = Field(
        default=None, description="time step in s, for rate limits (with u_prev)")


class _Batch(_Demand):
    # fail_fast: a batch of 10,000 bad rows is refused at its first bad row, not with 60,000 errors
    V: Annotated[list[AxisVector], Field(min_length=1, max_length=MAX_BATCH, fail_fast=True,
                                         description="N demands, N x k")]


_EXAMPLE_PROBLEM = {"B": [[1.0, 1.0, 0.5], [0.5, -0.5, 0.0]], "umin": [-1.0, -1.0, -1.0],
                    "umax": [1.0, 1.0, 1.0], "names": ["left", "right", "centre"], "axes": ["pitch", "roll"]}


def _examples(*examples: dict[str, Any]) -> ConfigDict:
    return ConfigDict(extra="forbid", json_schema_extra={"examples": list(examples)})


class AllocateRequest(ProblemIn, _Single):
    """``POST /v1/allocate``: an inline problem and one demand."""

    model_config = _examples({**_EXAMPLE_PROBLEM, "v": [1.2, 0.3], "method": "qp"})


class BatchAllocateRequest(ProblemIn, _Batch):
    """``POST /v1/allocate/batch``: an inline problem and up to 10,000 demands."""

    model_config = _examples({**_EXAMPLE_PROBLEM, "V": [[1.2, 0.3], [0.5, 0.0]], "method": "pinv"})


#: scheduling variables of one request, at most (the library's bound on a [schedule])
MAX_SCHEDULE_VARIABLES = 8
ScheduleName = Annotated[str, Field(min_length=1, max_length=64)]


class _Scheduled(_In):
    at: Annotated[dict[ScheduleName, Finite], Field(max_length=MAX_SCHEDULE_VARIABLES)] | None = Field(
        default=None, examples=[{"tilt": 45.0, "airspeed": 12.0}],
        description="a scheduled vehicle's variables by name (its document's [schedule]: tilt, airspeed), "
                    "each within its declared range; those not given take their nominal values; absent or {}: "
                    "the vehicle's nominal effectiveness")


class VehicleAllocateRequest(_Single, _Scheduled):
    """``POST /v1/vehicles/{id}/allocate``: one demand against the vehicle's current health."""

    model_config = _examples({"v": [1.2, 0.3], "method": "qp"},
                             {"v": [1.2, 0.3], "method": "qp", "u_prev": [0.0, 0.0, 0.0], "dt": 0.01},
                             {"v": [0.1, 0.0, 0.0, -20.0], "method": "qp", "at": {"tilt": 45.0, "airspeed": 12.0}})


class VehicleBatchRequest(_Batch, _Scheduled):
    """``POST /v1/vehicles/{id}/allocate/batch``: every row at the same ``at``."""


Status = Literal["exact", "unattainable", "fallback"]


def _answer(r: alloc.Result | alloc.BatchResult) -> dict[str, Any]:
    """The fields a single and a batch answer share (one row or one row per demand)."""
    return {"u": r.u.tolist(), "v_achieved": r.v_achieved.tolist(), "unallocated": r.unallocated.tolist(),
            "method": r.method, "solve_time": float(r.solve_time)}


class AllocationOut(BaseModel):
    u: list[float] = Field(description="effector commands")
    v: list[float]
    v_achieved: list[float] = Field(description="B u")
    unallocated: list[float] = Field(description="v - B u")
    status: Status
    fallback: bool = Field(description="true when the solver failed and the safe answer was returned")
    method: str
    iterations: int
    solve_time: float = Field(description="seconds spent in the method")
    message: str
    vehicle_id: str | None = None
    health_version: int | None = None

    @classmethod
    def of(cls, r: alloc.Result, **extra: Any) -> AllocationOut:
        return cls(**_answer(r), v=r.v.tolist(), status=r.status.value, fallback=r.fallback,
                   iterations=int(r.iterations), message=r.message, **extra)


class BatchOut(BaseModel):
    u: list[list[float]]
    v_achieved: list[list[float]]
    unallocated: list[list[float]]
    status: list[Status]
    counts: dict[str, int]
    method: str
    solve_time: float
    vehicle_id: str | None = None
    health_version: int | None = None

    @classmethod
    def of(cls, b: alloc.BatchResult, **extra: Any) -> BatchOut:
        return cls(**_answer(b), status=b.status.tolist(), counts=b.counts(), **extra)


class MethodOut(BaseModel):
    name: str
    equation: str
    summary: str
    options: dict[str, str]
    capabilities: dict[str, bool] = Field(default_factory=dict,
                                          description="declared by the method: affine, needs_ams, ...")


# -------------------------------------------------------------------- AMS
class _AmsQuery(_In):
    directions: Annotated[list[AxisVector], Field(max_length=MAX_DIRECTIONS, fail_fast=True)] | None = Field(
        default=None, description="directions d (k values each); default: +/- each axis")


class AmsRequest(ProblemIn, _AmsQuery):
    """``POST /v1/ams``: summary of the attainable moment set of an inline problem."""

    model_config = _examples({**_EXAMPLE_PROBLEM, "directions": [[1.0, 0.0], [1.0, 1.0]]})


class AmsVehicleRequest(_AmsQuery):
    """``POST /v1/vehicles/{id}/ams``: the same for a vehicle at its current health."""


class DirectionOut(BaseModel):
    direction: list[float]
    scale: float | None = Field(description="largest a with B u0 + a d attainable (u0: preferred position)")
    moment: list[float] | None = Field(description="B u0 + a d, the farthest attainable moment along d")
    u: list[float] | None = Field(description="an admissible command achieving it")


class AmsOut(BaseModel):
    volume: float | None = Field(description="k-volume of the AMS, null when not computed")
    volume_note: str
    directions: list[DirectionOut]
    vehicle_id: str | None = None
    health_version: int | None = None


# --------------------------------------------------------------- vehicles
class VehicleCreate(ProblemIn):
    """``POST /v1/vehicles``: an effector suite (its nominal, healthy problem)."""

    model_config = _examples({**_EXAMPLE_PROBLEM, "name": "demo", "rate_min": [-100.0, -100.0, None],
                              "rate_max": [100.0, 100.0, None]})

    name: Label | None = None
    #: the vehicle document this suite was read from (service.vehicle_document), kept with it
    _document: dict[str, Any] | None = PrivateAttr(default=None)

    def keep_document(self, document: dict[str, Any]) -> None:
        self._document = document

    def stored_problem(self, nominal: alloc.Problem) -> dict[str, Any]:
        """What the store keeps: ``nominal.to_dict()``, and the vehicle document as ``"document"`` if any."""
        stored = nominal.to_dict()
        if self._document is not None:
            stored["document"] = self._document
        return stored


class EffectorHealthOut(BaseModel):
    effector: str
    status: Literal["healthy", "jammed", "floating", "degraded"]
    jam_position: float | None = None
    effectiveness: float = 1.0
    limits: tuple[float, float] | None = Field(default=None, description="reduced position limits")
    rate_limits: tuple[float, float] | None = Field(default=None, description="reduced rate limits")


class HealthOut(BaseModel):
    vehicle_id: str
    health_version: int = Field(description="number of events recorded; changes with every event")
    effectors: list[EffectorHealthOut]
    effective: ProblemOut = Field(description="the problem allocations use now")


class VehicleOut(BaseModel):
    id: str
    name: str | None
    created_at: datetime
    health_version: int
    problem: ProblemOut = Field(description="the nominal (healthy) problem")
    health: list[EffectorHealthOut]


class VehicleSummary(BaseModel):
    id: str
    name: str | None
    created_at: datetime
    health_version: int
    m: int
    k: int


class VehicleList(BaseModel):
    items: list[VehicleSummary]
    total: int


# ----------------------------------------------------------------- events
class _Event(_In):
    effector: EffectorRef = Field(description="effector name or index")
    note: Annotated[str, Field(max_length=500, pattern=r"^[^\x00]*$")] | None = None


#: the JSON type of a parameter of each range (the ranges against the nominal problem are the library's)
_RANGE_TYPES: dict[Range, Any] = {
    Range.POSITION: Finite,
    Range.FRACTION: Annotated[float, Field(strict=True, ge=0.0, le=1.0)],
    Range.RATE_MIN: Annotated[float, Field(strict=True, le=0.0, ge=-MAX_MAGNITUDE, allow_inf_nan=False)],
    Range.RATE_MAX: Annotated[float, Field(strict=True, ge=0.0, le=MAX_MAGNITUDE, allow_inf_nan=False)],
}


def _event_model(spec: KindSpec) -> type[_Event]:
    """The JSON body of one failure kind, from its row of :data:`alloc.health.FAILURE_KINDS`.

    Every parameter the library requires is required here (a position at the instant of
    failure is a simulator's default: the service has no actuator to read it from); one with
    a default is optional and the recorded event carries the value it resolved to.
    """
    kind = spec.name.value
    annotations: dict[str, Any] = {"kind": Literal[kind]}
    namespace: dict[str, Any] = {"__module__": __name__, "__annotations__": annotations,
                                 "__doc__": f"{spec.meaning[0].upper()}{spec.meaning[1:]} (see alloc.health).",
                                 "model_config": _examples({"effector": "left", "kind": kind, **spec.example})}
    for name, default in spec.params.items():
        p = PARAMETERS[name]
        about = f"{p.description} ({p.unit}; {p.range.value})"
        if name in spec.required:
            annotations[name] = Annotated[_RANGE_TYPES[p.range], Field(description=about)]
        else:
            annotations[name] = Annotated[_RANGE_TYPES[p.range] | None,
                                          Field(description=f"{about}; default: {default.value}")]
            namespace[name] = None
    title = "".join(part.capitalize() for part in kind.split("_"))
    return type(f"{title}Event", (_Event,), namespace)


#: one JSON body per failure kind, derived from the library's table (registered kinds included)
EVENT_MODELS: dict[str, type[_Event]] = {kind.value: _event_model(kind.spec) for kind in FailureKind}



def event_of_text(data: Any) -> Any:
    """A body written in the library's failure grammar, ``{"failure": "jam:elevon_l@5", "note": ...}``,
    as the same event with its kind's fields (``effector``, ``kind``, ``position``); any other body unchanged.

    One event is one effector's failure: text joining several (``+``) is refused, and so are a
    simulator-only kind (never told) and ``failure`` beside the fields it stands for.
    """
    if not (isinstance(data, dict) and "failure" in data):
        return data
    from alloc.failure_grammar import parse_failure

    others = sorted(set(data) - {"failure", "note"})
    if others:
        raise ValueError(f"failure: give the failure as text or as effector, kind and parameters, not both "
                         f"(also given: {', '.join(others)})")
    try:
        parts = parse_failure(data["failure"])
    except alloc.AllocError as exc:
        raise ValueError(str(exc)) from None
    if len(parts) != 1:
        raise ValueError(f"failure: {len(parts)} effector failures joined; an event is one (post one event each)")
    part = parts[0]
    if part.kind not in FailureKind:
        raise ValueError(f"failure: {part.kind!r} changes actuator dynamics (simulator only, never told); "
                         f"event kinds: {', '.join(k.value for k in FailureKind)}")
    return {"effector": part.effector, "kind": part.kind, **part.params,
            **({"note": data["note"]} if "note" in data else {})}


#: an event body: its kind's fields, or the same failure as text (:func:`event_of_text`)
EventIn = Annotated[Union[tuple(EVENT_MODELS.values())], Discriminator("kind"),
                    BeforeValidator(event_of_text)]

#: the event kinds: exactly the library's failure kinds (alloc.health.FailureKind)
EVENT_KINDS = frozenset(EVENT_MODELS)


class EventOut(BaseModel):
    seq: int = Field(description="1, 2, ... per vehicle; the health_version after this event")
    effector: str
    kind: str
    params: dict[str, Any]
    failure: str | None = Field(default=None, description=(
        "the event in the failure grammar, kind:effector@values (alloc.failure_grammar; what a request's "
        "'failure' takes); null for a kind no longer registered"))
    note: str | None
    recorded_at: datetime


class EventList(BaseModel):
    vehicle_id: str
    items: list[EventOut]


class EventRecorded(BaseModel):
    event: EventOut
    health: HealthOut


class ServiceHealth(BaseModel):
    status: Literal["ok"]
    version: str
    database: str
    methods: int


class ServiceReady(BaseModel):
    status: Literal["ready"]
    startup_seconds: float = Field(description="seconds this worker took to start (imports excluded)")
    warmed: bool = Field(description="every method's numba kernels loaded in this worker (they load on a thread "
                                     "after start)")


class ProblemError(BaseModel):
    loc: list[str | int] = Field(description="FastAPI-style location, e.g. [\"body\", \"umin\"]")
    pointer: str | None = Field(description="JSON Pointer (RFC 6901) into the request body")
    reason: str


class ProblemDetails(BaseModel):
    """RFC 9457 problem document (media type ``application/problem+json``)."""

    type: str = Field(examples=["urn:alloc:problem:invalid-problem"])
    title: str
    status: int
    detail: str
    errors: list[ProblemError] = Field(description="the first ALLOC_MAX_VALIDATION_ERRORS (20) errors")
    error_count: int | None = Field(default=None, description="validation errors: how many there were in all")


def _problem(description: str) -> dict[str, Any]:
    return {"description": description, "model": ProblemDetails,
            "content": {"application/problem+json": {"schema": {"$ref": "#/components/schemas/ProblemDetails"}}}}


#: error responses shared by every route, for the OpenAPI document
PROBLEM_RESPONSES: dict[int | str, dict[str, Any]] = {
    413: _problem("request body larger than ALLOC_MAX_BODY_BYTES"),
    422: _problem("invalid request: shape, non-finite value, limits out of order, unknown method, ..."),
}
#: additionally, on routes with a vehicle id / on write routes
NOT_FOUND = {404: _problem("unknown vehicle")}
NOT_READY = {503: _problem("not ready: this worker is starting or shutting down")}
UNAUTHORIZED = {401: _problem("missing or wrong X-API-Key (when ALLOC_API_KEY is set)"),
                409: _problem("Idempotency-Key reused with a different body, or too many concurrent writes")}
