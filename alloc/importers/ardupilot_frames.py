"""ArduPilot's built-in multicopter motor tables, by ``FRAME_CLASS`` and ``FRAME_TYPE``.

Transcribed from ``AP_MotorsMatrix::setup_quad_matrix``, ``setup_hexa_matrix``, ``setup_octa_matrix``,
``setup_octaquad_matrix`` and ``setup_y6_matrix`` (ArduPilot/ardupilot
``libraries/AP_Motors/AP_MotorsMatrix.cpp``, the table-driven version with ``MotorDef`` /
``MotorDefRaw`` arrays and ``normalise_rpy_factors`` normalising throttle too; read from a stored
copy whose commit the copy did not record), with the class and type numbers of
``AP_Motors_Class.h`` (``motor_frame_class``, ``motor_frame_type``).  Each motor is the row of one ``add_motor`` call
(position angle in degrees for roll and pitch, yaw factor, test order) or of ``add_motor_raw``
(roll and pitch factors given).  The factors then follow :func:`alloc.importers.ardupilot.frame_factors`:
``roll = cos(radians(roll_angle + 90))``, ``pitch = cos(radians(pitch_angle))``, throttle 1, and
``normalise_rpy_factors``.  Motor ``k`` of a table is ``AP_MOTORS_MOT_k`` (output ``k``).
"""

from __future__ import annotations

from typing import NamedTuple

__all__ = ["Motor", "FRAME_CLASSES", "FRAME_TYPES", "TABLES", "Y6_DEFAULT", "frame_name"]

CW = -1.0  # AP_MOTORS_MATRIX_YAW_FACTOR_CW
CCW = 1.0  # AP_MOTORS_MATRIX_YAW_FACTOR_CCW


class Motor(NamedTuple):
    """One row of a motor table: ``add_motor`` (angles) or ``add_motor_raw`` (``raw=True``: the
    first two fields are the roll and pitch factors themselves)."""

    roll: float  # degrees (add_motor) or the roll factor (raw)
    pitch: float  # degrees (add_motor) or the pitch factor (raw)
    yaw: float
    order: int
    raw: bool = False


def _a(angle: float, yaw: float, order: int) -> Motor:
    """``add_motor(n, angle, yaw, order)``: one angle for roll and pitch."""
    return Motor(angle, angle, yaw, order)


def _r(roll: float, pitch: float, yaw: float, order: int) -> Motor:
    """``add_motor_raw(n, roll, pitch, yaw, order)``."""
    return Motor(roll, pitch, yaw, order, raw=True)


#: motor_frame_class values this importer reads
FRAME_CLASSES = {1: "quad", 2: "hexa", 3: "octa", 4: "octa-quad", 5: "y6"}
#: motor_frame_type values (the ones a table below uses)
FRAME_TYPES = {0: "plus", 1: "x", 2: "v", 3: "h", 4: "vtail", 5: "atail", 6: "plusrev", 10: "y6b", 11: "y6f",
               12: "bf-x", 13: "dji-x", 14: "cw-x", 15: "i", 18: "bf-x-rev", 19: "y4"}

#: (FRAME_CLASS, FRAME_TYPE) -> the motors, in motor-number order
TABLES: dict[tuple[int, int], tuple[Motor, ...]] = {
    # ---- quad (setup_quad_matrix)
    (1, 0): (_a(90, CCW, 2), _a(-90, CCW, 4), _a(0, CW, 1), _a(180, CW, 3)),
    (1, 1): (_a(45, CCW, 1), _a(-135, CCW, 3), _a(-45, CW, 4), _a(135, CW, 2)),
    (1, 2): (_a(45, 0.7981, 1), _a(-135, 1.0, 3), _a(-45, -0.7981, 4), _a(135, -1.0, 2)),
    (1, 3): (_a(45, CW, 1), _a(-135, CW, 3), _a(-45, CCW, 4), _a(135, CCW, 2)),
    # V- and A-tail: roll and pitch from different angles (add_motor with two angles)
    (1, 4): (Motor(60, 60, 0.0, 1), Motor(0, -160, CW, 3), Motor(-60, -60, 0.0, 4), Motor(0, 160, CCW, 2)),
    (1, 5): (Motor(60, 60, 0.0, 1), Motor(0, -160, CCW, 3), Motor(-60, -60, 0.0, 4), Motor(0, 160, CW, 2)),
    (1, 6): (_a(90, CW, 2), _a(-90, CW, 4), _a(0, CCW, 1), _a(180, CCW, 3)),
    (1, 12): (_a(135, CW, 2), _a(45, CCW, 1), _a(-135, CCW, 3), _a(-45, CW, 4)),
    (1, 13): (_a(45, CCW, 1), _a(-45, CW, 4), _a(-135, CCW, 3), _a(135, CW, 2)),
    (1, 14): (_a(45, CCW, 1), _a(135, CW, 2), _a(-135, CCW, 3), _a(-45, CW, 4)),
    (1, 18): (_a(135, CCW, 2), _a(45, CW, 1), _a(-135, CW, 3), _a(-45, CCW, 4)),
    (1, 19): (_r(-1.0, 1.0, CCW, 1), _r(0.0, -1.0, CW, 2), _r(0.0, -1.0, CCW, 3), _r(1.0, 1.0, CW, 4)),
    # ---- hexa (setup_hexa_matrix)
    (2, 0): (_a(0, CW, 1), _a(180, CCW, 4), _a(-120, CW, 5), _a(60, CCW, 2), _a(-60, CCW, 6), _a(120, CW, 3)),
    (2, 1): (_a(90, CW, 2), _a(-90, CCW, 5), _a(-30, CW, 6), _a(150, CCW, 3), _a(30, CCW, 1), _a(-150, CW, 4)),
    (2, 3): (_r(-1.0, 0.0, CW, 2), _r(1.0, 0.0, CCW, 5), _r(1.0, 1.0, CW, 6), _r(-1.0, -1.0, CCW, 3),
             _r(-1.0, 1.0, CCW, 1), _r(1.0, -1.0, CW, 4)),
    (2, 13): (_a(30, CCW, 1), _a(-30, CW, 6), _a(-90, CCW, 5), _a(-150, CW, 4), _a(150, CCW, 3), _a(90, CW, 2)),
    (2, 14): (_a(30, CCW, 1), _a(90, CW, 2), _a(150, CCW, 3), _a(-150, CW, 4), _a(-90, CCW, 5), _a(-30, CW, 6)),
    # ---- octa (setup_octa_matrix)
    (3, 0): (_a(0, CW, 1), _a(180, CW, 5), _a(45, CCW, 2), _a(135, CCW, 4), _a(-45, CCW, 8), _a(-135, CCW, 6),
             _a(-90, CW, 7), _a(90, CW, 3)),
    (3, 1): (_a(22.5, CW, 1), _a(-157.5, CW, 5), _a(67.5, CCW, 2), _a(157.5, CCW, 4), _a(-22.5, CCW, 8),
             _a(-112.5, CCW, 6), _a(-67.5, CW, 7), _a(112.5, CW, 3)),
    (3, 2): (_r(0.83, 0.34, CW, 7), _r(-0.67, -0.32, CW, 3), _r(0.67, -0.32, CCW, 6), _r(-0.50, -1.00, CCW, 4),
             _r(1.00, 1.00, CCW, 8), _r(-0.83, 0.34, CCW, 2), _r(-1.00, 1.00, CW, 1), _r(0.50, -1.00, CW, 5)),
    (3, 3): (_r(-1.0, 1.0, CW, 1), _r(1.0, -1.0, CW, 5), _r(-1.0, 0.333, CCW, 2), _r(-1.0, -1.0, CCW, 4),
             _r(1.0, 1.0, CCW, 8), _r(1.0, -0.333, CCW, 6), _r(1.0, 0.333, CW, 7), _r(-1.0, -0.333, CW, 3)),
    (3, 13): (_a(22.5, CCW, 1), _a(-22.5, CW, 8), _a(-67.5, CCW, 7), _a(-112.5, CW, 6), _a(-157.5, CCW, 5),
              _a(157.5, CW, 4), _a(112.5, CCW, 3), _a(67.5, CW, 2)),
    (3, 14): (_a(22.5, CCW, 1), _a(67.5, CW, 2), _a(112.5, CCW, 3), _a(157.5, CW, 4), _a(-157.5, CCW, 5),
              _a(-112.5, CW, 6), _a(-67.5, CCW, 7), _a(-22.5, CW, 8)),
    (3, 15): (_r(0.333, -1.0, CW, 5), _r(-0.333, 1.0, CW, 1), _r(1.0, -1.0, CCW, 6), _r(0.333, 1.0, CCW, 8),
              _r(-0.333, -1.0, CCW, 4), _r(-1.0, 1.0, CCW, 2), _r(-1.0, -1.0, CW, 3), _r(1.0, 1.0, CW, 7)),
    # ---- octa-quad (setup_octaquad_matrix): coaxial pairs, top and bottom spinning opposite ways
    (4, 0): (_a(0, CCW, 1), _a(-90, CW, 7), _a(180, CCW, 5), _a(90, CW, 3), _a(-90, CCW, 8), _a(0, CW, 2),
             _a(90, CCW, 4), _a(180, CW, 6)),
    (4, 1): (_a(45, CCW, 1), _a(-45, CW, 7), _a(-135, CCW, 5), _a(135, CW, 3), _a(-45, CCW, 8), _a(45, CW, 2),
             _a(135, CCW, 4), _a(-135, CW, 6)),
    (4, 2): (_a(45, 0.7981, 1), _a(-45, -0.7981, 7), _a(-135, 1.0, 5), _a(135, -1.0, 3), _a(-45, 0.7981, 8),
             _a(45, -0.7981, 2), _a(135, 1.0, 4), _a(-135, -1.0, 6)),
    (4, 3): (_a(45, CW, 1), _a(-45, CCW, 7), _a(-135, CW, 5), _a(135, CCW, 3), _a(-45, CW, 8), _a(45, CCW, 2),
             _a(135, CW, 4), _a(-135, CCW, 6)),
    (4, 12): (_a(135, CW, 3), _a(45, CCW, 1), _a(-135, CCW, 5), _a(-45, CW, 7), _a(135, CCW, 4), _a(45, CW, 2),
              _a(-135, CW, 6), _a(-45, CCW, 8)),
    (4, 14): (_a(45, CCW, 1), _a(45, CW, 2), _a(135, CW, 3), _a(135, CCW, 4), _a(-135, CCW, 5), _a(-135, CW, 6),
              _a(-45, CW, 7), _a(-45, CCW, 8)),
    (4, 18): (_a(135, CCW, 3), _a(45, CW, 1), _a(-135, CW, 5), _a(-45, CCW, 7), _a(135, CW, 4), _a(45, CCW, 2),
              _a(-135, CCW, 6), _a(-45, CW, 8)),
    # ---- Y6 (setup_y6_matrix): Y6B, Y6F; every other FRAME_TYPE takes the default table
    (5, 10): (_r(-1.0, 0.5, CW, 1), _r(-1.0, 0.5, CCW, 2), _r(0.0, -1.0, CW, 3), _r(0.0, -1.0, CCW, 4),
              _r(1.0, 0.5, CW, 5), _r(1.0, 0.5, CCW, 6)),
    (5, 11): (_r(0.0, -1.0, CCW, 3), _r(-1.0, 0.5, CCW, 1), _r(1.0, 0.5, CCW, 5), _r(0.0, -1.0, CW, 4),
              _r(-1.0, 0.5, CW, 2), _r(1.0, 0.5, CW, 6)),
}
#: the Y6 table for any FRAME_TYPE other than Y6B (10) and Y6F (11): setup_y6_matrix's ``default:``
Y6_DEFAULT: tuple[Motor, ...] = (
    _r(-1.0, 0.666, CCW, 2), _r(1.0, 0.666, CW, 5), _r(1.0, 0.666, CCW, 6), _r(0.0, -1.333, CW, 4),
    _r(-1.0, 0.666, CW, 1), _r(0.0, -1.333, CCW, 3),
)


def frame_name(frame_class: int, frame_type: int) -> str:
    """The built-in frame name of a table (``"quad-x"``, ``"octa-quad-cw-x"``, ``"y6b"``, ``"y6"``)."""
    if frame_class == 5:
        return FRAME_TYPES[frame_type] if (5, frame_type) in TABLES else "y6"
    return f"{FRAME_CLASSES[frame_class]}-{FRAME_TYPES[frame_type]}"
