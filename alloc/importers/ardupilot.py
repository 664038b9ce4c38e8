"""ArduPilot motor factor tables -> vehicle.

ArduPilot's multicopter mixer (``libraries/AP_Motors/AP_MotorsMatrix.cpp``, ArduPilot/ardupilot)
gives each motor a roll, pitch, yaw and throttle *factor*: the motor's output is
``roll_in * roll_factor + pitch_in * pitch_factor + yaw_in * yaw_factor + throttle * throttle_factor``
before desaturation (``output_armed_stabilizing``).  The factors come from

* ``add_motor(motor, angle, yaw_factor, order)``: ``roll = cos(radians(angle + 90))``,
  ``pitch = cos(radians(angle))``, ``throttle = 1`` (``add_motor_raw``'s default), with
  ``yaw_factor`` ``AP_MOTORS_MATRIX_YAW_FACTOR_CCW = 1`` or ``_CW = -1``; the frames are the
  tables of ``setup_quad_matrix`` / ``setup_hexa_matrix`` (:data:`FRAMES`);
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
``[[motors]]`` tables of ``name, roll, pitch, yaw[, throttle]``.
"""

from __future__ import annotations

import csv
import io
import math
import tomllib
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..exceptions import ProblemError
from ..vehicle_file.fields import FORMAT
from ..vehicle_file.vehicle import Vehicle, vehicle_from_dict

__all__ = ["FRAMES", "YAW_CW", "YAW_CCW", "frame_factors", "normalise_rpy_factors", "read_factor_table",
           "vehicle_from_factors", "vehicle_from_frame"]

YAW_CW = -1.0  # AP_MOTORS_MATRIX_YAW_FACTOR_CW
YAW_CCW = 1.0  # AP_MOTORS_MATRIX_YAW_FACTOR_CCW

#: (angle in degrees, yaw factor, testing order) per motor, in motor order: AP_MotorsMatrix.cpp
#: setup_quad_matrix / setup_hexa_matrix, MOTOR_FRAME_TYPE_X and MOTOR_FRAME_TYPE_PLUS
FRAMES: dict[str, tuple[tuple[float, float, int], ...]] = {
    "quad-x": ((45, YAW_CCW, 1), (-135, YAW_CCW, 3), (-45, YAW_CW, 4), (135, YAW_CW, 2)),
    "quad-plus": ((90, YAW_CCW, 2), (-90, YAW_CCW, 4), (0, YAW_CW, 1), (180, YAW_CW, 3)),
    "hexa-x": ((90, YAW_CW, 2), (-90, YAW_CCW, 5), (-30, YAW_CW, 6), (150, YAW_CCW, 3), (30, YAW_CCW, 1),
               (-150, YAW_CW, 4)),
    "hexa-plus": ((0, YAW_CW, 1), (180, YAW_CCW, 4), (-120, YAW_CW, 5), (60, YAW_CCW, 2), (-60, YAW_CCW, 6),
                  (120, YAW_CW, 3)),
}
_AXES = ("roll", "pitch", "yaw", "throttle")


def frame_factors(frame: str) -> np.ndarray:
    """The normalised factor table (motors x [roll, pitch, yaw, throttle]) of a built-in frame."""
    try:
        motors = FRAMES[frame]
    except KeyError:
        raise ProblemError(f"frame: unknown {frame!r}; built in: {', '.join(FRAMES)}", field="frame") from None
    raw = np.array([[math.cos(math.radians(angle + 90)), math.cos(math.radians(angle)), yaw, 1.0]
                    for angle, yaw, _ in motors])
    return normalise_rpy_factors(raw)


def normalise_rpy_factors(M: np.ndarray) -> np.ndarray:
    """``AP_MotorsMatrix::normalise_rpy_factors``: roll, pitch, yaw to max |factor| 0.5, throttle to max 1."""
    M = np.array(M, dtype=float)
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
    factor is 1 (ArduPilot's default).  Raises ProblemError naming the row and the column.
    """
    if isinstance(source, Path) or (isinstance(source, str) and "\n" not in source
                                    and source.lower().endswith((".csv", ".toml"))):
        path = Path(source)
        try:
            text = path.read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as exc:
            raise ProblemError(f"path: cannot read {str(path)!r} ({exc})", field="path") from exc
        toml = path.suffix.lower() == ".toml"
    elif isinstance(source, str):
        text = source
        toml = "[[motors]]" in text
    else:
        raise ProblemError(f"factors: expected a path or the table's text, got {type(source).__name__}",
                           field="factors")
    rows: list[dict[str, Any]]
    if toml:
        try:
            doc = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            raise ProblemError(f"factors: not valid TOML ({exc})", field="factors") from None
        rows = doc.get("motors") if isinstance(doc.get("motors"), list) else None  # type: ignore[assignment]
        if not rows:
            raise ProblemError("factors: a TOML table needs [[motors]] entries", field="factors")
        where = "motors[{}]"
    else:
        reader = csv.DictReader(io.StringIO(text))
        rows = list(reader)
        header = [h.strip() for h in (reader.fieldnames or [])]
        missing = [c for c in ("motor", "roll", "pitch", "yaw") if c not in header]
        if missing:
            raise ProblemError(f"factors: the CSV header needs columns motor, roll, pitch, yaw[, throttle]; "
                               f"missing {', '.join(missing)}", field="factors")
        rows = [{k.strip(): v for k, v in r.items() if k is not None} for r in rows]
        where = "row {}"
    names, table = [], []
    for i, row in enumerate(rows, start=0 if toml else 2):
        label = where.format(i)
        if not isinstance(row, dict):
            raise ProblemError(f"factors: {label}: expected a table", field="factors")
        name = row.get("name" if toml else "motor")
        if not isinstance(name, str) or not name.strip():
            raise ProblemError(f"factors: {label}: a motor name is required", field="factors")
        values = []
        for axis in _AXES:
            raw = row.get(axis)
            if raw is None or (isinstance(raw, str) and not raw.strip()):
                if axis == "throttle":
                    values.append(1.0)
                    continue
                raise ProblemError(f"factors: {label}: {axis}: required", field="factors")
            try:
                if isinstance(raw, bool):
                    raise ValueError
                x = float(raw)
            except (TypeError, ValueError):
                raise ProblemError(f"factors: {label}: {axis}: {raw!r} is not a number", field="factors") from None
            if not math.isfinite(x):
                raise ProblemError(f"factors: {label}: {axis}: must be finite, got {raw!r}", field="factors")
            values.append(x)
        names.append(name.strip())
        table.append(values)
    return names, np.array(table, dtype=float)


def vehicle_from_factors(factors: Any, names: Sequence[str] | None = None, *, name: str = "ardupilot",
                         normalise: bool = True, effectiveness: str = "pinv", slew_up_time: float | None = None,
                         slew_down_time: float | None = None) -> Vehicle:
    """The vehicle of a factor table (motors x [roll, pitch, yaw, throttle]).

    ``normalise`` applies :func:`normalise_rpy_factors` first (ArduPilot always does).
    ``slew_up_time`` / ``slew_down_time``: ArduPilot's ``MOT_SLEW_UP_TIME`` / ``MOT_SLEW_DN_TIME``
    (seconds for the full 0..1 range): the rate limits ``1 / time``.
    """
    M = np.array(factors, dtype=float)
    if M.ndim != 2 or M.shape[1] != 4 or M.shape[0] < 1:
        raise ProblemError(f"factors: expected a table of motors x 4 (roll, pitch, yaw, throttle), got shape "
                           f"{M.shape}", field="factors")
    if not np.isfinite(M).all():
        raise ProblemError("factors: every factor must be finite", field="factors")
    if effectiveness not in ("pinv", "transpose"):
        raise ProblemError(f"effectiveness: expected 'pinv' or 'transpose', got {effectiveness!r}",
                           field="effectiveness")
    m = M.shape[0]
    names = [f"motor{i + 1}" for i in range(m)] if names is None else list(names)
    if len(names) != m:
        raise ProblemError(f"names: expected {m} motor names, got {len(names)}", field="names")
    if normalise:
        M = normalise_rpy_factors(M)
    B = np.linalg.pinv(M) if effectiveness == "pinv" else M.T
    effectors = []
    for j, motor in enumerate(names):
        e: dict[str, Any] = {"name": motor, "kind": "rotor", "unit": "1", "min": 0.0, "max": 1.0,
                             "effectiveness": [float(x) for x in B[:, j]]}
        for key, t in (("rate_max", slew_up_time), ("rate_min", slew_down_time)):
            if t is not None:
                if isinstance(t, bool) or not isinstance(t, (int, float)) or not t > 0 or not math.isfinite(t):
                    field = "slew_up_time" if key == "rate_max" else "slew_down_time"
                    raise ProblemError(f"{field}: must be a positive number of seconds, got {t!r}", field=field)
                e[key] = (1.0 if key == "rate_max" else -1.0) / float(t)
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


def vehicle_from_frame(frame: str, **options: Any) -> Vehicle:
    """The vehicle of a built-in ArduPilot frame (``"quad-x"``, ``"hexa-x"``, ...; :data:`FRAMES`)."""
    options.setdefault("name", f"ardupilot-{frame}")
    return vehicle_from_factors(frame_factors(frame), **options)
