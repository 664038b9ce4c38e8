"""The vehicle document in the service: ``POST /v1/vehicles`` with a vehicle file's content.

The body of ``POST /v1/vehicles`` is either an effector suite (:class:`VehicleCreate`, the
fields of :class:`alloc.Problem`) or a vehicle document (format ``alloc-vehicle/1``, see
:mod:`alloc.vehicle_file`): JSON with a top-level ``format`` member, or the TOML file itself
sent as ``Content-Type: application/toml``.  A document is validated by the library's own
reader (:func:`alloc.vehicle_file.vehicle_from_dict`, what :func:`alloc.load_vehicle` calls),
so the service accepts exactly the files the library does, and an error names the field's
path (``effectors[3].rate_max``) as a 422 problem+json whose ``errors[0].pointer`` is
``/effectors/3/rate_max``.  The stored vehicle's problem is the document's
:meth:`~alloc.vehicle_file.Vehicle.problem`; the document itself
(:meth:`~alloc.vehicle_file.Vehicle.to_dict`: names, units, limits, preferred positions,
dynamics, method defaults, model) is kept beside it and read back by ``GET
/v1/vehicles/{id}/document`` (JSON, or TOML for ``Accept: application/toml``), floats bit for
bit.  Body size and the body budget are the service's (:mod:`service.bodies`), whatever the
content type.
"""

from __future__ import annotations

import re
from typing import Annotated, Any

from fastapi import Request
from pydantic import Discriminator, RootModel, Tag, model_validator

from alloc._files import MAX_TOML_BYTES, parse_toml
from alloc.exceptions import ProblemError
from alloc.vehicle_file import FORMAT, Vehicle, to_toml, vehicle_from_dict, vehicle_from_problem

from .errors import ServiceError, field_error
from .schemas import MAX_MEMBERS, VehicleCreate

__all__ = ["TOML_MEDIA_TYPE", "IMPORT_MEDIA_TYPES",
           "VehicleDocumentIn", "VehicleBody", "vehicle_create", "document_of",
           "require_vehicle_media_type", "document_pointer", "InvalidVehicleDocument", "UnsupportedMediaType"]

#: the media type of a vehicle file in TOML (RFC 9618 registers ``application/toml``)
TOML_MEDIA_TYPE = "application/toml"
#: the media types of a flight stack's file (:mod:`service.vehicle_import`): ``text/csv`` is an
#: ArduPilot factor table (RFC 4180), ``text/plain`` a parameter or airframe file named by ``?import=``
IMPORT_MEDIA_TYPES = ("text/csv", "text/plain")


class InvalidVehicleDocument(ServiceError, status=422, slug="invalid-vehicle-document",
                             title="Invalid vehicle document"):
    """A vehicle document the library's reader refuses; ``errors[0]`` points at the field."""


class UnsupportedMediaType(ServiceError, status=415, slug="unsupported-media-type", title="Unsupported media type"):
    """A body that is neither JSON nor a TOML vehicle file."""


def _parse_toml(raw: bytes) -> dict[str, Any]:
    """The TOML body through the library's bounded reader (:func:`alloc._files.parse_toml`: the
    size, depth and dotted-key caps a vehicle file has; ``tomllib`` alone spends time growing
    with the square of a dotted key's parts, and lets RecursionError and ValueError out)."""
    if len(raw) > MAX_TOML_BYTES:
        reason = f"{len(raw):,} bytes, more than the {MAX_TOML_BYTES:,} a TOML vehicle file may have"
        raise InvalidVehicleDocument(f"the TOML body is {reason}",
                                     [{"loc": ["body"], "pointer": None, "reason": reason}])
    try:
        return parse_toml(raw.decode("utf-8"), field="body", name="the body")
    except UnicodeDecodeError as exc:
        raise InvalidVehicleDocument(f"the TOML body is not UTF-8 text ({exc.reason} at byte {exc.start})",
                                     [{"loc": ["body"], "pointer": None, "reason": "not UTF-8"}]) from None
    except ProblemError as exc:
        reason = str(exc).removeprefix("body: ")
        raise InvalidVehicleDocument(f"the body is refused: {reason}",
                                     [{"loc": ["body"], "pointer": None, "reason": reason}]) from None


class VehicleDocumentIn(RootModel[dict[str, Any] | bytes]):
    """A vehicle document (format ``alloc-vehicle/1``): a JSON object, or the TOML file's bytes
    (FastAPI hands over the raw body of a type that is not JSON; :func:`require_vehicle_media_type`
    lets only TOML through).  Its content is checked by the library's reader, not here (one
    definition of the format)."""

    model_config = {"json_schema_extra": {"description": f"a vehicle document, format {FORMAT!r} "
                                          "(alloc/schemas/vehicle-1.schema.json); or the TOML file as "
                                          f"{TOML_MEDIA_TYPE}"}}

    @model_validator(mode="before")
    @classmethod
    def _bounded(cls, data: Any) -> Any:
        if isinstance(data, dict) and len(data) > MAX_MEMBERS:
            raise ValueError(f"{len(data):,} members; a vehicle document has at most {MAX_MEMBERS}")
        return data

    def document(self) -> dict[str, Any]:
        """The document: the JSON object, or the TOML parsed (InvalidVehicleDocument if it is not TOML)."""
        return _parse_toml(self.root) if isinstance(self.root, bytes) else self.root


def _form(data: Any) -> str:
    """Which body this is: a document has a top-level ``format`` (or is TOML bytes)."""
    if isinstance(data, (bytes, bytearray)) or (isinstance(data, dict) and "format" in data):
        return "document"
    if isinstance(data, VehicleDocumentIn):
        return "document"
    return "problem"


#: the body of ``POST /v1/vehicles``: an effector suite or a vehicle document
VehicleBody = Annotated[Annotated[VehicleCreate, Tag("problem")] | Annotated[VehicleDocumentIn, Tag("document")],
                        Discriminator(_form)]


def require_vehicle_media_type(request: Request) -> None:
    """JSON (``application/json``, ``+json``), ``application/toml``, or a flight stack's file
    (``text/csv``, ``text/plain``: :mod:`service.vehicle_import`); anything else is a 415 naming them."""
    value = request.headers.get("content-type")
    if value is None:
        return  # FastAPI's own answer (a body without a type is not read as JSON)
    media = value.split(";", 1)[0].strip().lower()
    if media == "application/json" or media.endswith("+json") or media in (TOML_MEDIA_TYPE, *IMPORT_MEDIA_TYPES):
        return
    raise UnsupportedMediaType(f"content-type {media[:60]!r}: send the vehicle as application/json (an effector "
                               f"suite or a vehicle document), as {TOML_MEDIA_TYPE} (a vehicle file), as text/csv "
                               "(an ArduPilot factor table) or as text/plain with ?import=ardupilot-params, "
                               "px4-params or px4-airframe (a flight stack's parameter or airframe file)",
                               [{"loc": ["header", "content-type"], "pointer": None, "reason": "unsupported"}])


_STEP = re.compile(r"\[(\d+)\]")


def document_pointer(path: str) -> str:
    """The library's field path as the service's ``field_error`` path: ``effectors[3].rate_max``
    -> ``effectors/3/rate_max`` (a JSON pointer into the document)."""
    return _STEP.sub(r"/\1", path).replace(".", "/").strip("/")


def vehicle_create(document: VehicleDocumentIn | dict[str, Any]) -> tuple[VehicleCreate, Vehicle]:
    """The stored vehicle's body of a document: its problem, its name, the document kept.

    Raises
    ------
    InvalidVehicleDocument
        what :func:`alloc.vehicle_file.vehicle_from_dict` refuses, pointing at the field.
    """
    if isinstance(document, VehicleDocumentIn):
        document = document.document()
    try:
        vehicle = vehicle_from_dict(document)
    except ProblemError as exc:
        path = exc.field or ""
        where = document_pointer(path) if path and path != "vehicle" else ""
        errors = [field_error(where, str(exc))] if where else [{"loc": ["body"], "pointer": None, "reason": str(exc)}]
        raise InvalidVehicleDocument(str(exc), errors) from None
    body = VehicleCreate.model_validate({**vehicle.problem().to_dict(), "name": vehicle.name})
    body.keep_document(vehicle.to_dict())
    return body, vehicle


def document_of(stored: dict[str, Any] | None, nominal: Any, name: str | None) -> dict[str, Any]:
    """The vehicle document of a stored vehicle: the one it was created from, or (created from
    an effector suite) the document of its problem (:func:`alloc.vehicle_file.vehicle_from_problem`).

    Raises
    ------
    ProblemError
        a suite a document cannot carry (off-diagonal weights; a one-sided rate limit).
    """
    if stored is not None:
        return stored
    return vehicle_from_problem(nominal, name or "vehicle").to_dict()


def toml_text(document: dict[str, Any]) -> str:
    """The document as a TOML vehicle file (floats written with ``repr``: read back bit for bit)."""
    return to_toml(document)
