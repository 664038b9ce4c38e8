"""A flight stack's file as the body of ``POST /v1/vehicles``: the library's importers on the text.

The body is the file as the flight stack writes it, and the request says how to read it:

========================  ======================================  =====================================
``Content-Type``          ``?import=``                            read as
========================  ======================================  =====================================
``text/csv``              (absent) or ``ardupilot-csv``           an ArduPilot motor factor table
``text/plain``            ``ardupilot-params``                    an ArduPilot ``.param``/``.parm`` file
``text/plain``            ``px4-params``                          a QGroundControl ``.params`` file
``text/plain``            ``px4-airframe``                        a PX4 airframe file (ROMFS)
========================  ======================================  =====================================

The format is named, not guessed: the CLI tells them apart by the file's extension, which an
HTTP body has not.  ``?name=`` names the vehicle (default: the importer's, as ``alloc
allocate --vehicle`` names it after the file's stem).  The text goes to
:func:`alloc.vehicle_file.import_vehicle_text`, what :func:`alloc.load_vehicle` does with the
same file's content, never read as a path, so the stored vehicle has the ``B`` and limits the
CLI finds in that file; the vehicle's document (:meth:`~alloc.vehicle_file.Vehicle.to_dict`:
names, limits, a tiltrotor's ``[schedule]``, and in ``source`` the shell lines an airframe
file had that were skipped) is kept and read back by ``GET /v1/vehicles/{id}/document``.

Refusals: 422 ``invalid-vehicle-import`` naming the line or parameter as the library does
(``params: line 4: ...``, ``FRAME_CLASS: ...``, ``factors: row 3: pitch: ...``), for a body
that is not UTF-8 or is over :data:`~alloc._files.MAX_TEXT_BYTES` (1 MiB, the library's cap on
such a file); 422 ``validation-error`` naming ``query.import`` or ``query.name`` when the query
does not fit the body's type; 415 for a ``charset`` other than UTF-8.
"""

from __future__ import annotations

import email.message
from enum import Enum
from typing import Any

from pydantic import BaseModel

from alloc._files import MAX_TEXT_BYTES
from alloc.exceptions import ProblemError
from alloc.vehicle_file import IMPORT_FORMATS, Vehicle, import_vehicle_text

from .errors import InvalidRequest, ServiceError
from .schemas import VehicleCreate
from .vehicle_document import IMPORT_MEDIA_TYPES, UnsupportedMediaType, vehicle_create

__all__ = ["ImportFormat", "ImportedFile", "InvalidImport", "check_import_query",
           "imported_vehicle", "media_type"]

_CSV_FORM = "ardupilot-csv"
_CHARSETS = ("utf-8", "utf8", "us-ascii")

#: ``?import=``: how to read a flight stack's file (one definition: the library's)
ImportFormat = Enum("ImportFormat", {f.replace("-", "_"): f for f in IMPORT_FORMATS}, type=str)  # type: ignore[misc]


class InvalidImport(ServiceError, status=422, slug="invalid-vehicle-import", title="Invalid flight-stack file"):
    """A flight stack's file the library's importer refuses; the detail names the line or parameter."""


class ImportedFile(BaseModel):
    """What an ``Idempotency-Key`` fingerprints for an imported file: the format, the name and the text."""

    format: str
    name: str | None
    text: str


def _query_error(name: str, reason: str) -> InvalidRequest:
    return InvalidRequest(f"query/{name}: {reason}", [{"loc": ["query", name], "pointer": None, "reason": reason}])


def media_type(content_type: str | None) -> tuple[str, str | None]:
    """``(media type, charset)`` of a ``Content-Type`` header, lower case (``("", None)``: none)."""
    if not content_type:
        return "", None
    message = email.message.Message()
    message["content-type"] = content_type
    charset = message.get_param("charset")
    return message.get_content_type(), (charset.lower() if isinstance(charset, str) else None)


def check_import_query(media: str, form: str | None, name: str | None) -> str | None:
    """The format a body of type ``media`` is read as, or ``None`` (a vehicle document or suite);
    422 naming ``query.import`` or ``query.name`` when the query does not fit the type."""
    if media not in IMPORT_MEDIA_TYPES:
        if form is not None:
            types = " or ".join(IMPORT_MEDIA_TYPES)
            raise _query_error("import", f"applies to a flight stack's file sent as {types}; this body is "
                                         f"{media or 'untyped'} (a vehicle document or an effector suite)")
        if name is not None:
            raise _query_error("name", "applies to an imported file; a document or suite carries its own name")
        return None
    if media == "text/csv":
        if form not in (None, _CSV_FORM):
            raise _query_error("import", f"a text/csv body is an ArduPilot factor table ({_CSV_FORM}); send {form} "
                                         "as text/plain")
        return _CSV_FORM
    if form is None:
        raise _query_error("import", f"required for a text/plain body: one of {', '.join(IMPORT_FORMATS)}")
    return form


def imported_vehicle(raw: bytes, form: str, name: str | None,
                     charset: str | None) -> tuple[VehicleCreate, Vehicle, ImportedFile]:
    """The stored vehicle's body of a flight stack's file (its problem, its name, its document
    kept), the vehicle, and what a retry's fingerprint is taken over.

    Raises
    ------
    InvalidImport
        the importer's refusal (naming the line or parameter), a body that is not UTF-8 or
        over :data:`~alloc._files.MAX_TEXT_BYTES`.
    """
    if charset is not None and charset not in _CHARSETS:
        raise UnsupportedMediaType(f"charset {charset[:40]!r}: a flight stack's file is read as UTF-8",
                                   [{"loc": ["header", "content-type"], "pointer": None, "reason": "charset"}])
    if len(raw) > MAX_TEXT_BYTES:
        reason = f"{len(raw):,} bytes, more than the {MAX_TEXT_BYTES:,} a flight stack's file may have"
        raise InvalidImport(f"the body is {reason}", [_body_error(reason)])
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        reason = f"not UTF-8 text ({exc.reason} at byte {exc.start})"
        raise InvalidImport(f"the body is {reason}", [_body_error(reason)]) from None
    try:
        vehicle = import_vehicle_text(text, form, name=name, label="the body")
    except ProblemError as exc:
        raise InvalidImport(f"{form}: {exc}", [_body_error(str(exc), exc.field)]) from None
    suite, vehicle = vehicle_create(vehicle.to_dict())
    return suite, vehicle, ImportedFile(format=form, name=name, text=text)


def _body_error(reason: str, field: str | None = None) -> dict[str, Any]:
    """An ``errors`` entry of the body (not JSON, so no pointer); ``field`` the library's name for
    the part at fault (``params``, ``factors``, ``FRAME_CLASS``) when it gave one."""
    return {"loc": ["body"] if not field else ["body", field], "pointer": None, "reason": reason}
