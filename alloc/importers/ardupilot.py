"""ArduPilot motor factor tables -> vehicle.

ArduPilot's multicopter mixer (``libraries/AP_Motors/AP_MotorsMatrix.cpp``, ArduPilot/ardupilot)
gives each motor a roll, pitch, yaw and throttle *factor*: the motor's output is
``roll_in * roll_factor + pitch_in * pitch_factor + yaw_in * yaw_factor + throttle * throttle_factor``
before desaturation (``output_armed_stabilizing``).  The factors come from

* ``add_motor(motor, angle, yaw_factor, order)``: ``roll = cos(radians(angle + 90))``,
  ``pitch = cos(radians(angle))``, ``throttle = 1`` (``add_motor_raw``'s default), with
  ``yaw_factor`` ``AP_MOTORS_MATRIX_YAW_FACTOR_CCW = 1`` or ``_CW = -1``; the frames are the
  tables of ``setup_quad_matrix``, ``setup_hexa_matrix``, ``setup_octa_matrix``,
  ``setup_octaquad_matrix`` and ``setup_y6_matrix`` (:data:`FRAMES`, :mod:`alloc.importers.ardupilot_frames`),
  chosen by the parameters ``FRAME_CLASS`` and ``FRAME_TYPE`` (:func:`vehicle_from_ardupilot_params`);
* ``add_motor_raw(motor, roll, pitch, yaw, order[, throttle])`` for raw tables;

and then ``normalise_rpy_factors``: roll, pitch and yaw factors each scaled so the largest
magnitude is 0.5, throttle factors divided by the largest (and floored at 0).

The table is a mixer ``M`` (motors x [roll, pitch, yaw, throttle]), the map from demands to
commands, not an effectiveness.  The vehicle's ``B`` (axes ``roll, pitch, yaw, throttle`` in
ArduPilot's normalised input units, motors commanded in [0, 1]) is, by ``effectiveness``:

* ``"pinv"`` (default): ``B = pinv(M)``, the effectiveness for which ArduPilot's mixer is
  an exact inverse (``B M = I`` when ``M`` has rank 4): a demand ``v`` mixed by ArduPilot and
  applied through ``B`` gives ``v`` back.  For the built-in frames (orthogonal factor
  columns) this is ``M'`` with each row divided by its column's squared norm.
* ``"transpose"``: ``B = M'`` (each motor's factor as its effect; the same directions, other
  row scales).

A user's table: CSV with a header row ``motor,roll,pitch,yaw[,throttle]`` or TOML with
``[[motors]]`` tables of ``name, roll, pitch, yaw[, throttle]``.  An ArduPilot parameter file
(``.param`` as Mission Planner saves it, ``NAME,value``; or ``.parm``, ``NAME value``) names a
built-in frame by ``FRAME_CLASS`` and ``FRAME_TYPE`` (:func:`read_ardupilot_params`).
"""

from __future__ import annotations

import csv
import io
import math
import numbers
import re
from collections.abc import Mapping, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from .._files import MAX_TEXT_BYTES, MAX_TOML_BYTES, params_text, parse_toml, read_user_text
from ..domain import MAX_EFFECTORS, MAX_MAGNITUDE, short_repr
from ..exceptions import ProblemError
from ..vehicle_file.fields import FORMAT, _text, _unique
from ..vehicle_file.vehicle import Vehicle, vehicle_from_dict
from .ardupilot_frames import FRAME_CLASSES, FRAME_TYPES, TABLES, Y6_DEFAULT, Motor, frame_name

__all__ = ["FRAMES", "YAW_CW", "YAW_CCW", "frame_factors", "normalise_rpy_factors", "read_factor_table",
           "factor_table_from_text", "vehicle_from_factors", "vehicle_from_frame", "read_ardupilot_params",
           "ardupilot_params_from_text", "vehicle_from_ardupilot_params", "frame_of_params"]

YAW_CW = -1.0  # AP_MOTORS_MATRIX_YAW_FACTOR_CW
YAW_CCW = 1.0  # AP_MOTORS_MATRIX_YAW_FACTOR_CCW

#: built-in frame name -> its motors (:mod:`alloc.importers.ardupilot_frames`, in motor order):
#: every (FRAME_CLASS, FRAME_TYPE) table of quad, hexa, octa, octa-quad and Y6 ("quad-x", "octa-quad-x", "y6b")
FRAMES: dict[str, tuple[Motor, ...]] = {
    **{frame_name(c, t): motors for (c, t), motors in TABLES.items()}, "y6": Y6_DEFAULT}
_AXES = ("roll", "pitch", "yaw", "throttle")


def frame_factors(frame: str) -> np.ndarray:
    """The normalised factor table (motors x [roll, pitch, yaw, throttle]) of a built-in frame.

    ``add_motor``'s factors ``roll = cos(radians(roll_angle + 90))``, ``pitch = cos(radians(pitch_angle))``,
    or ``add_motor_raw``'s as given; throttle 1; then :func:`normalise_rpy_factors`.
    """
    if not isinstance(frame, str) or frame not in FRAMES:
        raise ProblemError(f"frame: unknown {short_repr(frame)}; built in: {', '.join(FRAMES)}", field="frame")
    raw = np.array([[m.roll, m.pitch, m.yaw, 1.0] if m.raw else
                    [math.cos(math.radians(m.roll + 90)), math.cos(math.radians(m.pitch)), m.yaw, 1.0]
                    for m in FRAMES[frame]])
    return normalise_rpy_factors(raw)


def normalise_rpy_factors(M: np.ndarray) -> np.ndarray:
    """``AP_MotorsMatrix::normalise_rpy_factors``: roll, pitch, yaw to max |factor| 0.5, throttle to max 1."""
    M = _factor_matrix(M)
    for c in range(3):
        peak = float(np.abs(M[:, c]).max())
        if peak != 0.0:
            M[:, c] = 0.5 * M[:, c] / peak
    peak = float(np.maximum(M[:, 3], 0.0).max())
    if peak != 0.0:
        M[:, 3] = np.maximum(0.0, M[:, 3] / peak)
    return M


def read_factor_table(source: str | Path) -> tuple[list[str], np.ndarray]:
    """``(motor names, factors)`` from a CSV or TOML factor table (a path or the text).

    A text is TOML when it contains ``[[motors]]``, CSV otherwise.  A missing throttle
    factor is 1 (ArduPilot's default).  A file is read through :func:`alloc._files.read_user_file`
    and a text held to the same length: at most :data:`~alloc._files.MAX_TOML_BYTES` (128 KiB)
    of TOML or :data:`~alloc._files.MAX_TEXT_BYTES` (1 MiB) of CSV, and at most
    :data:`~alloc.domain.MAX_EFFECTORS` (512) motors, counted before any row is read.  Each
    factor is a finite number within ``1e50``.  Raises ProblemError naming the row and the column.
    """
    if isinstance(source, Path) or (isinstance(source, str) and "\n" not in source
                                    and source.lower().endswith((".csv", ".toml"))):
        path = Path(source)
        toml = path.suffix.lower() == ".toml"
        text = read_user_text(path, field="path", max_bytes=MAX_TOML_BYTES if toml else MAX_TEXT_BYTES)
        label = path.name
    elif isinstance(source, str):
        return factor_table_from_text(source, toml="[[motors]]" in source)
    else:
        raise ProblemError(f"factors: expected a path or the table's text, got {type(source).__name__}",
                           field="factors")
    return _factor_rows(text, toml, label)


def factor_table_from_text(text: str, *, toml: bool = False, label: str = "the table") -> tuple[list[str], np.ndarray]:
    """:func:`read_factor_table` of a text, CSV (or TOML with ``toml``) whatever it contains: never
    read as a path (the service hands it a request body), held to the same length."""
    cap = MAX_TOML_BYTES if toml else MAX_TEXT_BYTES
    if not isinstance(text, str):
        raise ProblemError(f"factors: expected the table's text, got {type(text).__name__}", field="factors")
    if len(text) > cap:
        raise ProblemError(f"factors: the text is {len(text)} characters, more than the {cap} allowed",
                           field="factors")
    return _factor_rows(text, toml, label)


def _factor_rows(text: str, toml: bool, label: str) -> tuple[list[str], np.ndarray]:
    rows, where = _toml_rows(text, label) if toml else _csv_rows(text)
    names, table = [], []
    first_row: dict[str, int] = {}
    for i, row in enumerate(rows, start=0 if toml else 2):
        at = where.format(i)
        if not isinstance(row, dict):
            raise ProblemError(f"factors: {at}: expected a table", field="factors")
        name = row.get("name" if toml else "motor")
        if not isinstance(name, str) or not name.strip():
            raise ProblemError(f"factors: {at}: a motor name is required", field="factors")
        values = []
        for axis in _AXES:
            raw = row.get(axis)
            if raw is None or (isinstance(raw, str) and not raw.strip()):
                if axis == "throttle":
                    values.append(1.0)
                    continue
                raise ProblemError(f"factors: {at}: {axis}: required", field="factors")
            values.append(_factor(raw, f"factors: {at}: {axis}"))
        if name.strip() in first_row:
            raise ProblemError(f"factors: {at}: motor {name.strip()[:40]!r} is named twice (first at "
                               f"{where.format(first_row[name.strip()])})", field="factors")
        first_row[name.strip()] = i
        names.append(name.strip())
        table.append(values)
    return names, np.array(table, dtype=float)


def _toml_rows(text: str, label: str) -> tuple[list[Any], str]:
    doc = parse_toml(text, field="factors", name=label)
    rows = doc.get("motors")
    if not isinstance(rows, list) or not rows:
        raise ProblemError("factors: a TOML table needs [[motors]] entries", field="factors")
    if len(rows) > MAX_EFFECTORS:
        raise ProblemError(f"factors: {len(rows)} motors, more than the {MAX_EFFECTORS} allowed", field="factors")
    return rows, "motors[{}]"


def _csv_rows(text: str) -> tuple[list[dict[str, Any]], str]:
    reader = csv.reader(io.StringIO(text))
    try:
        header = [h.strip() for h in next(reader, [])]
        missing = [c for c in ("motor", "roll", "pitch", "yaw") if c not in header]
        if missing:
            raise ProblemError(f"factors: the CSV header needs columns motor, roll, pitch, yaw[, throttle]; "
                               f"missing {', '.join(missing)}", field="factors")
        twice = next((h for i, h in enumerate(header) if h in header[:i]), None)
        if twice is not None:
            raise ProblemError(f"factors: the CSV header names column {twice[:40]!r} twice", field="factors")
        rows = []
        for cells in reader:
            if len(rows) == MAX_EFFECTORS:  # counted before the row is read
                raise ProblemError(f"factors: more than the {MAX_EFFECTORS} motors allowed", field="factors")
            rows.append(dict(zip(header, cells)))
    except csv.Error as exc:  # a field beyond csv.field_size_limit, a stray quote
        raise ProblemError(f"factors: row {reader.line_num}: not valid CSV ({exc})", field="factors") from None
    return rows, "row {}"


def _factor(raw: Any, label: str, *, text: bool = True, field: str = "factors") -> float:
    """One factor: a number (or, with ``text``, its text: a CSV cell), finite and within ``1e50``;
    refused naming ``label``."""
    try:
        if isinstance(raw, bool) or not isinstance(raw, (str, numbers.Real) if text else numbers.Real):
            raise TypeError
        x = float(raw)
    except (TypeError, ValueError):
        raise ProblemError(f"{label}: {short_repr(raw)} is not a number", field=field) from None
    except OverflowError:  # an integer beyond float64
        x = math.inf
    if not math.isfinite(x):
        raise ProblemError(f"{label}: must be finite, got {short_repr(raw)}", field=field)
    if not abs(x) <= MAX_MAGNITUDE:
        raise ProblemError(f"{label}: |x| must be <= {MAX_MAGNITUDE:g}, got {short_repr(raw)}", field=field)
    return x


def _factor_matrix(factors: Any) -> np.ndarray:
    """The factor table as a float array (motors x 4), its size checked before its entries."""
    shape_error = "factors: expected a table of motors x 4 (roll, pitch, yaw, throttle)"
    if isinstance(factors, np.ndarray):
        if factors.ndim != 2 or factors.shape[1] != 4 or factors.shape[0] < 1:
            raise ProblemError(f"{shape_error}, got shape {factors.shape}", field="factors")
        rows: Any = factors
    elif isinstance(factors, (list, tuple)):
        rows = factors
    else:
        raise ProblemError(f"{shape_error}, got {type(factors).__name__}", field="factors")
    if not 1 <= len(rows) <= MAX_EFFECTORS:
        raise ProblemError(f"factors: expected 1 to {MAX_EFFECTORS} motors, got {len(rows)}", field="factors")
    out = np.empty((len(rows), 4))
    for i, row in enumerate(rows):
        if not isinstance(row, (list, tuple, np.ndarray)) or len(row) != 4:
            got = f"{len(row)} entries" if isinstance(row, (list, tuple, np.ndarray)) else type(row).__name__
            raise ProblemError(f"factors[{i}]: expected 4 factors (roll, pitch, yaw, throttle), got {got}",
                               field="factors")
        for j, x in enumerate(row):
            if isinstance(x, np.generic):
                x = x.item()  # a numpy scalar: its Python number (complex stays complex and is refused)
            out[i, j] = _factor(x, f"factors[{i}][{j}] ({_AXES[j]})", text=False)
    return out


def vehicle_from_factors(factors: Any, names: Sequence[str] | None = None, *, name: str = "ardupilot",
                         normalise: bool = True, effectiveness: str = "pinv", slew_up_time: float | None = None,
                         slew_down_time: float | None = None) -> Vehicle:
    """The vehicle of a factor table (motors x [roll, pitch, yaw, throttle]).

    ``normalise`` applies :func:`normalise_rpy_factors` first (ArduPilot always does).
    ``slew_up_time`` / ``slew_down_time``: ArduPilot's ``MOT_SLEW_UP_TIME`` / ``MOT_SLEW_DN_TIME``
    (seconds for the full 0..1 range): the rate limits ``1 / time``.  Every argument is checked
    before any work and refused naming it (``factors[2][1] (pitch): ...``, ``names[3]``): at most
    512 motors, each factor a finite real number within ``1e50``.
    """
    M = _factor_matrix(factors)
    if effectiveness not in ("pinv", "transpose"):
        raise ProblemError(f"effectiveness: expected 'pinv' or 'transpose', got {short_repr(effectiveness)}",
                           field="effectiveness")
    m = M.shape[0]
    if names is None:
        names = [f"motor{i + 1}" for i in range(m)]
    else:
        if isinstance(names, str) or not isinstance(names, (list, tuple)):
            raise ProblemError(f"names: expected a list of {m} motor names, got {type(names).__name__}", field="names")
        if len(names) != m:
            raise ProblemError(f"names: expected {m} motor names, got {len(names)}", field="names")
        names = [_text(label, f"names[{j}]", name=True) for j, label in enumerate(names)]
        _unique(names, "names")
    rates = {key: _rate(t, label) for key, t, label in (("rate_max", slew_up_time, "slew_up_time"),
                                                        ("rate_min", slew_down_time, "slew_down_time"))
             if t is not None}
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):  # checked just below
        if normalise:
            M = normalise_rpy_factors(M)
        try:
            B = np.linalg.pinv(M) if effectiveness == "pinv" else M.T
        except np.linalg.LinAlgError as exc:
            raise ProblemError(f"factors: the table has no pseudo-inverse ({exc})", field="factors") from None
    if not (np.abs(B) <= MAX_MAGNITUDE).all():
        raise ProblemError(f"factors: pinv of the table has entries beyond {MAX_MAGNITUDE:g} (the table is nearly "
                           "rank-deficient at this scale); effectiveness='transpose' reads it as is", field="factors")
    effectors = []
    for j, motor in enumerate(names):
        e: dict[str, Any] = {"name": motor, "kind": "rotor", "unit": "1", "min": 0.0, "max": 1.0,
                             "effectiveness": [float(x) for x in B[:, j]]}
        if "rate_max" in rates:
            e["rate_max"] = rates["rate_max"]
        if "rate_min" in rates:
            e["rate_min"] = -rates["rate_min"]
        effectors.append(e)
    doc = {
        "format": FORMAT, "name": name,
        "description": f"ArduPilot motor factor table, {m} motors",
        "source": f"ArduPilot AP_MotorsMatrix factors (normalise_rpy_factors: {normalise}); B = "
                  f"{'pinv(M)' if effectiveness == 'pinv' else 'M transpose'}",
        "axes": [{"name": a, "unit": "1"} for a in _AXES],
        "effectors": effectors,
    }
    return vehicle_from_dict(doc)


def _rate(seconds: Any, label: str) -> float:
    """The rate limit ``1 / seconds`` of a slew time, refused naming ``label`` unless positive and finite."""
    bad = ProblemError(f"{label}: must be a positive number of seconds, got {short_repr(seconds)}", field=label)
    if isinstance(seconds, bool) or not isinstance(seconds, numbers.Real):
        raise bad
    try:
        t = float(seconds)
    except (OverflowError, TypeError, ValueError):
        raise bad from None
    if not (t > 0 and math.isfinite(t)):
        raise bad
    if not 1.0 / t <= MAX_MAGNITUDE:
        raise ProblemError(f"{label}: {t:g} s gives a rate limit beyond {MAX_MAGNITUDE:g}", field=label)
    return 1.0 / t


def vehicle_from_frame(frame: str, **options: Any) -> Vehicle:
    """The vehicle of a built-in ArduPilot frame (``"quad-x"``, ``"hexa-x"``, ...; :data:`FRAMES`)."""
    options.setdefault("name", f"ardupilot-{frame}")
    return vehicle_from_factors(frame_factors(frame), **options)


#: an ArduPilot parameter name: at most 16 characters (AP_MAX_NAME_SIZE), capitals, digits, _
_AP_NAME = re.compile(r"[A-Z0-9_]{1,16}")
_AP_SEPARATOR = re.compile(r"\s*,\s*|\s+")


def read_ardupilot_params(source: str | Path) -> dict[str, float | int]:
    """Parameters from an ArduPilot parameter file (a path, or its text).

    One parameter a line, ``NAME,value`` (Mission Planner's ``.param``) or ``NAME value`` (MAVProxy's
    ``.parm``, tab or spaces); ``#`` starts a comment.  A file is read through
    :func:`alloc._files.read_user_file` (at most :data:`~alloc._files.MAX_TEXT_BYTES`, 1 MiB; a full
    ArduCopter dump is about 30 KB) and a text held to the same length.  Refused naming the line
    (``params: line 4: ...``): another shape, a name that is not ArduPilot's (16 capitals, digits or
    ``_`` at most), a value that is not a finite number within ``1e50``, a name given twice.
    """
    text = params_text(source, is_path=isinstance(source, str) and "\n" not in source
                       and source.lower().endswith((".param", ".parm")))
    return ardupilot_params_from_text(text)


def ardupilot_params_from_text(text: str) -> dict[str, float | int]:
    """:func:`read_ardupilot_params` of a text, never read as a path (the service hands it a request
    body), held to :data:`~alloc._files.MAX_TEXT_BYTES`."""
    text = params_text(text, is_path=False)
    out: dict[str, float | int] = {}
    first: dict[str, int] = {}
    for n, raw in enumerate(text.splitlines(), start=1):
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        words = _AP_SEPARATOR.split(line)
        if len(words) != 2:
            raise ProblemError(f"params: line {n}: expected 'NAME,value' or 'NAME value', got {raw.strip()[:60]!r}",
                               field="params")
        name, value = words
        if not _AP_NAME.fullmatch(name):
            raise ProblemError(f"params: line {n}: {name[:40]!r} is not an ArduPilot parameter name (at most 16 "
                               "capitals, digits or _)", field="params")
        if name in first:
            raise ProblemError(f"params: line {n}: {name} is set again (first at line {first[name]})",
                               field="params")
        first[name] = n
        number = _factor(value, f"params: line {n}: {name}", field="params")
        out[name] = int(number) if value.lstrip("+-").isdigit() else number
    return out


def frame_of_params(params: Mapping[str, Any]) -> str:
    """The built-in frame (:data:`FRAMES`) that ``FRAME_CLASS`` and ``FRAME_TYPE`` select.

    ``FRAME_CLASS`` is required (ArduPilot's 0 means "not set up"); ``FRAME_TYPE`` defaults to
    1 (X), ArduPilot's default.  A Y6 takes its default table for any type but Y6B (10) and Y6F (11),
    as ``setup_y6_matrix`` does.  Refused naming the parameter: a missing or unsupported class, a type
    the class has no table for (listing the ones it has).
    """
    if "FRAME_CLASS" not in params:
        raise ProblemError("FRAME_CLASS: missing; the parameters must name the frame class (1 quad, 2 hexa, "
                           "3 octa, 4 octa-quad, 5 Y6)", field="FRAME_CLASS")
    frame_class = _whole(params["FRAME_CLASS"], "FRAME_CLASS")
    if frame_class not in FRAME_CLASSES:
        known = ", ".join(f"{k} ({v})" for k, v in FRAME_CLASSES.items())
        raise ProblemError(f"FRAME_CLASS: {short_repr(params['FRAME_CLASS'])} is not supported; supported: {known}",
                           field="FRAME_CLASS")
    frame_type = _whole(params.get("FRAME_TYPE", 1), "FRAME_TYPE")
    if frame_class == 5 and (5, frame_type) not in TABLES:
        return "y6"
    if (frame_class, frame_type) not in TABLES:
        have = ", ".join(f"{t} ({FRAME_TYPES[t]})" for c, t in TABLES if c == frame_class)
        raise ProblemError(f"FRAME_TYPE: {short_repr(params.get('FRAME_TYPE', 1))} has no table for FRAME_CLASS "
                           f"{frame_class} ({FRAME_CLASSES[frame_class]}); it has: {have}", field="FRAME_TYPE")
    return frame_name(frame_class, frame_type)


def _whole(value: Any, name: str) -> int:
    """A whole number (a class or type code), refused naming ``name``."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or not math.isfinite(float(value)) \
            or not float(value).is_integer():
        raise ProblemError(f"{name}: expected a whole number, got {short_repr(value)}", field=name)
    return int(value)


def vehicle_from_ardupilot_params(params: Mapping[str, Any], *, name: str | None = None, **options: Any) -> Vehicle:
    """The vehicle of an ArduPilot parameter set: the built-in frame of ``FRAME_CLASS`` and
    ``FRAME_TYPE`` (:func:`frame_of_params`), with ``MOT_SLEW_UP_TIME`` / ``MOT_SLEW_DN_TIME``
    as rate limits when positive (ArduPilot: 0 = no limit).  A vehicle's rate limits come as a
    pair: with only ``MOT_SLEW_UP_TIME`` positive, the decrease is held to the same rate (the vehicle
    file's ``rate_min = -rate_max``), more cautious than ArduPilot.  ``options`` go to
    :func:`vehicle_from_factors`."""
    if not isinstance(params, Mapping):
        raise ProblemError(f"params: expected a mapping of parameter names to numbers, got {type(params).__name__}",
                           field="params")
    frame = frame_of_params(params)
    for key, param in (("slew_up_time", "MOT_SLEW_UP_TIME"), ("slew_down_time", "MOT_SLEW_DN_TIME")):
        if param in params:
            seconds = params[param]
            if isinstance(seconds, bool) or not isinstance(seconds, numbers.Real) or not seconds >= 0:
                raise ProblemError(f"{param}: must be a number of seconds >= 0, got {short_repr(seconds)}",
                                   field=param)
            if seconds > 0:
                options.setdefault(key, seconds)
    options.setdefault("name", name or f"ardupilot-{frame}")
    vehicle = vehicle_from_factors(frame_factors(frame), **options)
    return replace(vehicle, description=f"ArduPilot {frame} (FRAME_CLASS {int(params['FRAME_CLASS'])}, FRAME_TYPE "
                                        f"{int(params.get('FRAME_TYPE', 1))}), {vehicle.m} motors")
