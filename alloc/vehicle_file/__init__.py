"""Vehicle description files: format ``alloc-vehicle/1`` (TOML or JSON), and ``alloc-vehicle/1.1``.

A vehicle file names the effectors and the axes of one aircraft and carries everything an
allocation problem, a method's defaults and (optionally) the simulator need::

    format = "alloc-vehicle/1"
    name = "hexa-x"
    description = "6 rotors, X layout"

    [[axes]]                      # the virtual controls v (rows of B), in order
    name = "roll"
    unit = "N m"

    [[effectors]]                 # the effectors u (columns of B), in order
    name = "m1"
    kind = "rotor"                # surface | rotor | thrust-vector | thruster | other
    unit = "1"                    # the unit of the command u (rad, deg, N, 1 = normalised)
    min = 0.0
    max = 1.0
    rate_max = 10.0               # optional, units per second (rate_min defaults to -rate_max)
    preferred = 0.0               # optional: u_pref (default 0 clipped into [min, max])
    weight = 1.0                  # optional: diagonal entry of Wu
    dynamics = { bandwidth = 40.0, delay = 0.01 }   # optional actuator model
    rotor = { position = [0.0, 0.5, 0.0], axis = [0.0, 0.0, -1.0], ct = 6.5, km = -0.05 }

    [effectiveness]               # or B directly (instead of each effector's rotor/effectiveness)
    B = [[...], ...]              # rows = axes, columns = effectors: axis unit per effector unit

    [methods.daisy]               # per-vehicle method defaults (alloc's option names)
    groups = [["m1", "m2"], ["m3"]]

    [body]                        # optional: mass, inertia, rotor physics (alloc.vehicle_file.body);
    mass = 2.0                    # without [model], the hover linear model is derived from it
    inertia = [0.08, 0.08, 0.15]

    [model]                       # optional rigid-body linear model x' = A x + B u, y = C x + D u
    states = [...]; outputs = [...]; A = [...]; B = [...]; C = [...]; D = [...]
    units = [...]                 # optional, one per output (plots and tables label them)

    [simulation]                  # format 1.1 or later: the vehicle's own closed-loop design
    ...                           # (alloc.vehicle_file.simulation; the seed's ICE and HARV carry theirs)

    [schedule]                    # format 1.2 only: B as a function of named variables (tilt, airspeed)
    ...                           # (alloc.vehicle_file.schedule); B above is its value at the nominal point

The effectiveness of an effector is given one of three ways: the whole matrix
(``[effectiveness] B``), its column (``effectiveness = [...]``, one entry per axis: a
surface's derivatives), or its rotor geometry (``rotor = {...}``).  A rotor's column is
PX4's (``ActuatorEffectivenessRotors::computeEffectivenessMatrix``, see
:func:`rotor_wrench`): thrust ``ct * a`` and moment ``ct * (p x a) - ct * km * a`` for the
unit axis ``a`` and the position ``p`` in body axes (x forward, y right, z down; metres);
each axis then names the wrench component it is (``wrench = "roll"``, ``"pitch"``,
``"yaw"``, ``"fx"``, ``"fy"``, ``"fz"``; inferred from an axis named so).

Actuator dynamics (``dynamics``): exactly one of ``bandwidth`` (``a / (s + a)``, rad/s),
``time_constant`` (``1 / (tau s + 1)``, s), ``wn`` with ``zeta`` (``wn^2 / (s^2 + 2 zeta wn
s + wn^2)``) or ``poles = [a, b]`` (``a b / ((s + a)(s + b))``, seed Table 4-5), and an
optional ``delay`` in seconds.  The allocator never sees them (:mod:`alloc.health`); the
simulator does.

Every malformed document raises :class:`~alloc.exceptions.ProblemError` (a ``ValueError``)
whose message starts with the field's path, ``effectors[3].rate_max: must be > 0, got -1``;
:attr:`~alloc.exceptions.AllocError.field` carries the path.  The structure is also
published as a JSON Schema (:data:`SCHEMA_PATH`, ``alloc/schemas/vehicle-1.schema.json``);
the loader's checks are a superset of the schema's (shapes, names, limits).

The package, bottom up: :mod:`~alloc.vehicle_file.fields` (the constants and the field
readers), :mod:`~alloc.vehicle_file.parts` (dynamics, rotors, effectors, axes, the linear
model), :mod:`~alloc.vehicle_file.vehicle` (the vehicle and its documents) and
:mod:`~alloc.vehicle_file.toml_writer`; the importers (:mod:`alloc.importers`) build on
those, and :func:`load_vehicle` here, which reads any of the formats, sits above them.
"""

from __future__ import annotations

import os
import warnings
from collections.abc import Mapping
from dataclasses import replace
from pathlib import Path
from typing import Any

from .._files import MAX_TEXT_BYTES, MAX_TOML_BYTES, parse_json, parse_toml, read_user_text
from ..exceptions import ProblemError, SkippedLinesWarning
from .fields import DATA_DIR, EFFECTOR_KINDS, FORMAT, FORMAT_SCHEDULE, FORMAT_SIMULATION, FORMATS, SCHEMA_PATH, WRENCH_COMPONENTS
from .body import Body
from .parts import Axis, Dynamics, Effector, LinearModel, Rotor, rotor_wrench
from .schedule import Schedule, ScheduledEffectiveness
from .simulation import Simulation
from .toml_writer import to_toml
from .vehicle import Vehicle, vehicle_from_dict, vehicle_from_problem

__all__ = [
    "FORMAT", "FORMAT_SIMULATION", "FORMAT_SCHEDULE", "FORMATS", "Schedule", "ScheduledEffectiveness", "SCHEMA_PATH", "Simulation", "DATA_DIR", "EFFECTOR_KINDS", "WRENCH_COMPONENTS",
    "Body", "Dynamics", "Rotor", "Effector", "Axis", "LinearModel", "Vehicle",
    "load_vehicle", "import_vehicle_text", "IMPORT_FORMATS",
    "vehicle_from_dict", "vehicle_from_problem", "vehicle_names", "rotor_wrench", "to_toml",
]


# --------------------------------------------------------------------------- reading
def vehicle_names() -> list[str]:
    """The bundled vehicle files' names (``load_vehicle(name)`` reads one)."""
    return sorted(p.stem for p in DATA_DIR.glob("*.toml"))


def load_vehicle(source: str | Path | Mapping[str, Any]) -> Vehicle:
    """Read a vehicle: a file, a document, or a bundled name.

    A file is a vehicle file (``.toml``, ``.json``), or a flight stack's file read by an importer
    with its defaults: a PX4 ``.params`` file or airframe file as PX4 ships it (any other name whose
    text starts with ``#!`` or has ``param set-default`` lines: ``13000_my_quadplane``,
    ``1103_standard_vtol_sih.hil``; :func:`alloc.importers.px4.vehicle_from_params`, shell lines
    skipped and listed in a :class:`~alloc.exceptions.SkippedLinesWarning`), an ArduPilot motor
    factor table ``.csv`` (:func:`alloc.importers.ardupilot.vehicle_from_factors`) or parameter file
    ``.param``/``.parm`` (``FRAME_CLASS``, ``FRAME_TYPE``:
    :func:`alloc.importers.ardupilot.vehicle_from_ardupilot_params`).  A bare name without an
    extension that is not a file (``"ice"``) is a bundled vehicle file (:func:`vehicle_names`).

    A file is read through :func:`alloc._files.read_user_file` and parsed with its bounds:
    regular files only (not a directory, FIFO or device, nor a symlink to one), at most
    :data:`~alloc._files.MAX_TOML_BYTES` (128 KiB) of TOML or :data:`~alloc._files.MAX_TEXT_BYTES`
    (1 MiB) of JSON or PX4 parameters, nested at most :data:`~alloc._files.MAX_DEPTH` (16) levels,
    JSON without duplicate keys; the counts (axes, effectors, model states and outputs) are
    checked on the parsed document before any per-entry work.  The slowest file found at a cap is
    read and refused in 0.3 s (TOML) and 0.2 s (JSON) on a 2-core machine (:mod:`alloc._files`).

    Raises
    ------
    ProblemError
        naming the field path of the first problem (``effectors[3].rate_max: ...``), or
        ``path`` for an unreadable, oversized, unparsable or unknown file.
    """
    if isinstance(source, Mapping):
        return vehicle_from_dict(source)
    if not isinstance(source, (str, Path)):
        raise ProblemError(f"source: expected a path, a bundled name or a document, got {type(source).__name__}",
                           field="source")
    path = Path(source)
    if not os.path.exists(path) and isinstance(source, str) and path.suffix == "" and "/" not in source:
        bundled = DATA_DIR / f"{source}.toml"
        if not os.path.exists(bundled):
            raise ProblemError(f"path: no file {source!r} and no bundled vehicle of that name; bundled: "
                               f"{', '.join(vehicle_names())}", field="path")
        path = bundled
    suffix = path.suffix.lower()
    if suffix in (".toml", ".json"):
        cap = MAX_TOML_BYTES if suffix == ".toml" else MAX_TEXT_BYTES
        text = read_user_text(path, field="path", max_bytes=cap)
        parse = parse_toml if suffix == ".toml" else parse_json
        return vehicle_from_dict(parse(text, field="path", name=path.name))
    return _import_vehicle(path, suffix)


#: what each importer's file looks like, for the messages: one list for every refusal of a path
_KNOWN_FILES = (".toml or .json vehicle files, PX4 .params or airframe files (ROMFS airframes, with or without "
                "an extension), ArduPilot .csv factor tables or .param/.parm parameter files")


#: the flight-stack files :func:`import_vehicle_text` reads, by name: an ArduPilot motor factor table
#: (CSV), an ArduPilot parameter file (``.param``/``.parm``), a QGroundControl ``.params`` file, a
#: PX4 airframe file as PX4 ships it
IMPORT_FORMATS = ("ardupilot-csv", "ardupilot-params", "px4-params", "px4-airframe")


def import_vehicle_text(text: str, form: str, *, name: str | None = None, label: str = "the text") -> Vehicle:
    """A vehicle from the text of a flight stack's file, read as ``form`` (one of
    :data:`IMPORT_FORMATS`), never as a path: what :func:`load_vehicle` does with such a file's
    content (the service hands it a request body).  ``name`` is the vehicle's name (default the
    importer's); ``label`` names the text in :attr:`Vehicle.source`.

    The text is held to :data:`~alloc._files.MAX_TEXT_BYTES`, as a file is.  Shell lines a PX4
    airframe file has (``. ${R}etc/init.d/rc.vtol_defaults``) are skipped and listed in the
    vehicle's ``source``; no warning is issued (:func:`load_vehicle` issues one for a file).

    Raises
    ------
    ProblemError
        naming the line or the parameter (``params: line 4: ...``, ``FRAME_CLASS: ...``,
        ``factors: row 3: ...``), ``format`` for an unknown ``form``.
    """
    return _imported(text, form, name, label)[0]


def _imported(text: str, form: str, name: str | None, label: str) -> tuple[Vehicle, str]:
    """:func:`import_vehicle_text` and the summary of the lines it skipped (``""``: none)."""
    named: dict[str, Any] = {} if name is None else {"name": name}
    if form == "ardupilot-csv":
        from ..importers.ardupilot import factor_table_from_text, vehicle_from_factors

        names, factors = factor_table_from_text(text, label=label)
        return vehicle_from_factors(factors, names, **named), ""
    if form == "ardupilot-params":
        from ..importers.ardupilot import ardupilot_params_from_text, vehicle_from_ardupilot_params

        return vehicle_from_ardupilot_params(ardupilot_params_from_text(text), name=name), ""
    if form not in ("px4-params", "px4-airframe"):
        raise ProblemError(f"format: unknown {form[:40]!r}; flight-stack files are read as one of "
                           f"{', '.join(IMPORT_FORMATS)}", field="format")
    from .._files import params_text
    from ..importers.px4 import looks_like_airframe, params_from_text, vehicle_from_params

    text = params_text(text, is_path=False)
    if form == "px4-airframe" and not looks_like_airframe(text):
        raise ProblemError(f"params: {label} is not a PX4 airframe file (no '#!' first line, no 'param set-default' "
                           "lines)", field="params")
    read = params_from_text(text)
    vehicle = vehicle_from_params(read.params, **named)
    summary = read.skipped_summary()
    if summary:
        vehicle = replace(vehicle, source=f"{vehicle.source}; PX4 airframe file {label}: {summary}")
    return vehicle, summary


def _import_vehicle(path: Path, suffix: str) -> Vehicle:
    """A vehicle from a flight stack's file: by extension, else (an airframe's name, ``13000_my_quadplane``,
    ``1103_standard_vtol_sih.hil``) by its text (:func:`import_vehicle_text`).  Skipped shell lines are
    listed in a :class:`~alloc.exceptions.SkippedLinesWarning` and in the vehicle's ``source``."""
    text = read_user_text(path, field="path", max_bytes=MAX_TEXT_BYTES)
    if suffix == ".csv":
        form = "ardupilot-csv"
    elif suffix in (".param", ".parm"):
        form = "ardupilot-params"
    elif suffix == ".params":
        form = "px4-params"
    else:
        from ..importers.px4 import looks_like_airframe

        if not looks_like_airframe(text):
            what = f"unknown extension {path.suffix!r}" if suffix else f"{path.name} has no extension"
            raise ProblemError(f"path: {what} and is not a PX4 airframe file (no '#!' first line, no 'param "
                               f"set-default' lines); vehicles are read from {_KNOWN_FILES}", field="path")
        form = "px4-airframe"
    vehicle, summary = _imported(text, form, path.stem, path.name)
    if summary:
        warnings.warn(f"{path.name}: {summary}", SkippedLinesWarning, stacklevel=3)
    return vehicle
