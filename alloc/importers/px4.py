"""PX4 control-allocation parameters -> vehicle.

Reads a QGroundControl parameter file or a PX4 airframe file as PX4 ships it
(``ROMFS/px4fmu_common/init.d/airframes/``: ``#!/bin/sh``, ``. ${R}etc/init.d/rc.vtol_defaults``,
``param set-default ...``; the shell lines are skipped and listed, :func:`read_params_report`), and
from them the parameters PX4's ``control_allocator`` module uses (PX4-Autopilot
``src/modules/control_allocator/module.yaml``; defaults in brackets):

* ``CA_AIRFRAME`` [0]: 0 multirotor, 1 fixed-wing, 2 standard VTOL, 3 tiltrotor VTOL (its tilts,
  ``CA_SV_TL*`` and ``CA_ROTORn_TILT``, and airspeed scaling: :mod:`alloc.importers.px4_tiltrotor`;
  a ``[schedule]`` in tilt and airspeed); others refused.
* ``CA_ROTOR_COUNT`` [0] and per rotor ``CA_ROTORn_PX/PY/PZ`` [0] (m, body axes x forward,
  y right, z down), ``CA_ROTORn_AX/AY/AZ`` [0, 0, -1] (thrust axis), ``CA_ROTORn_CT`` [6.5]
  (thrust at full command), ``CA_ROTORn_KM`` [0.05] (moment per thrust, > 0 counter-clockwise);
  ``CA_R_REV`` (bit n: rotor n reversible, command in [-1, 1] instead of [0, 1]);
  ``CA_Rn_SLEW`` [0] (seconds for the full range: rate limit ``range / slew``; 0 = none).
* ``CA_SV_CS_COUNT`` [0] and per surface ``CA_SV_CSn_TYPE`` [1], ``CA_SV_CSn_TRQ_R/P/Y`` [0]
  (roll/pitch/yaw torque per unit command), ``CA_SV_CSn_TRIM`` [0] (the preferred position);
  ``CA_SVn_SLEW`` [0] (servo ``n``'s full range -1..1 in seconds).  Commands are in [-1, 1].
* ``MPC_THR_HOVER`` (when present): the ``fz`` axis's trim is the force with every rotor at
  that command (the operating point :mod:`alloc.controllability` measures around).

Effectiveness, by PX4's own code (PX4/PX4-Autopilot ``src/modules/control_allocator/
ActuatorEffectiveness/``):

* rotors: ``ActuatorEffectivenessRotors::computeEffectivenessMatrix``
  (``ActuatorEffectivenessRotors.cpp``, commit 25ab311a8229; the same formula at
  ``VehicleActuatorEffectiveness/ActuatorEffectivenessRotors.cpp``, commit 1da805dc2d25): thrust ``ct * a``, moment
  ``ct * (p x a) - ct * km * a`` for the normalised axis ``a`` (:func:`alloc.vehicle_file.rotor_wrench`).
  Fixed-wing: the axis is fixed forward ``(1, 0, 0)`` and propeller torque disabled (``km = 0``;
  ``ActuatorEffectivenessFixedWing.cpp``: ``AxisConfiguration::FixedForward``,
  ``enablePropellerTorque(false)``).  Standard VTOL: ``km = 0`` for a rotor whose axis is not
  upwards (``|ax|, |ay| < 0.1``, ``az < -0.5``; ``ActuatorEffectivenessStandardVTOL.cpp``:
  ``enablePropellerTorqueNonUpwards(false)``), i.e. the pusher.
* surfaces: ``ActuatorEffectivenessControlSurfaces::updateParams`` (``src/modules/control_allocator/
  VehicleActuatorEffectiveness/ActuatorEffectivenessControlSurfaces.cpp``, commit 136b586a3f5a; types
  1..18 in ``src/lib/control_allocation/actuator_effectiveness/ActuatorEffectivenessControlSurfaces.hpp``,
  commit 44bce91dc7c4): the column is ``(TRQ_R, TRQ_P, TRQ_Y)`` in the moment rows, no force; flaps
  (types 9, 10), the airbrake (11), the steering wheel (16) and spoilers (17, 18) get a zero column,
  as ``updateParams`` zeroes their torque (:data:`NO_TORQUE_TYPES`).  A-tails (13, 14) keep theirs.

The axes are PX4's six: ``roll, pitch, yaw`` (moments) and ``fx, fy, fz`` (forces); with
``axes="auto"`` (default) the axes no effector acts on are left out (a multirotor keeps
roll, pitch, yaw, fz).  PX4 allocates a standard VTOL's rotors and surfaces in two matrices
(matrix 0: rotors, matrix 1: surfaces); here they are the columns of one ``B``.

Normalisation (``normalize``):

* ``"none"`` (default): ``B`` in physical units -- moment and force per unit command (N m
  and N when ``CT`` is in newtons).  The surfaces' ``TRQ_*`` are PX4's normalised torques
  (PX4 allocates them against normalised setpoints), so on a fixed-wing or VTOL the moment
  rows mix the rotors' N m with the surfaces' normalised units.
* ``"px4"``: PX4's ``ControlAllocationPseudoInverse::updateControlAllocationMatrixScale`` and
  ``normalizeControlAllocationMatrix`` as PX4 has them now (``src/lib/control_allocation/
  control_allocation/ControlAllocationPseudoInverse.cpp``, commit 1316f1cea719), expressed on ``B``.
  PX4 computes the mix ``M = pinv(B)`` (m x 6) of each matrix and divides its columns by scales ``s``:
  roll and pitch share ``s = max over those two of sqrt(|M_col|^2 / (n / 2))``, ``n`` the
  entries of that column above 1e-3 in magnitude -- only for matrices with "normalize RPY"
  (multirotor: matrix 0; fixed-wing: none; standard VTOL: matrix 0), otherwise 1; yaw
  ``s = max_i M_i,yaw`` (signed maximum) under the same condition; each force axis its own
  ``s = mean over the effectors acting on that axis of |M_i,axis|`` (``> FLT_EPSILON``), z first,
  and an axis no effector acts on takes z's scale (1 when nothing acts on z).  An older PX4
  (``src/modules/control_allocator/ControlAllocation/ControlAllocationPseudoInverse.cpp``, commit
  089afb091546) shared one force scale, the mean norm of each effector's 3-vector; the two agree
  for a multirotor (only fz) and differ for a standard VTOL's pusher (fx and fz now normalised
  apart: the pusher's fx entry is 1 and each lift rotor's fz -1/4, where the shared scale gave
  both 2/5).
  A scale at or below FLT_EPSILON leaves its columns unscaled (the force columns follow x's).
  Since the allocation is ``u = M diag(1/s) c``, the setpoint ``c`` PX4 allocates is
  ``diag(s) B u``: the normalised effectiveness is ``diag(s) B`` (rows scaled), computed
  per matrix (each matrix's columns with its own ``s``).  Not reproduced: PX4 then zeroes
  the entries of the normalised *mix* below 1e-3 (a property of its mixer, not of ``B``),
  and it works in float32.  The scales are computed once for the healthy vehicle (PX4
  recomputes them on a parameter change, not on a failure); a failed rotor is then a
  :mod:`alloc.health` event on the imported vehicle.
"""

from __future__ import annotations

import math
import numbers
import os
import re
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .._files import params_text
from ..domain import MAX_MAGNITUDE
from ..exceptions import ProblemError
from ..px4_mix import FLT_EPSILON, mix_scales
from ..domain import as_float_array, short_repr
from ..vehicle_file.fields import FORMAT, FORMAT_SCHEDULE, WRENCH_COMPONENTS
from ..vehicle_file.parts import rotor_wrench
from ..vehicle_file.vehicle import Vehicle, vehicle_from_dict
from .px4_tiltrotor import RotorGeometry, Tiltrotor

__all__ = ["read_params", "read_params_report", "params_from_text", "reads_parameter", "READ_PARAMETERS", "looks_like_airframe", "ParamsRead", "vehicle_from_params", "px4_scales", "AIRFRAMES", "SURFACE_TYPES", "NO_TORQUE_TYPES", "DEFAULTS"]

#: CA_AIRFRAME values this importer reads
AIRFRAMES = {0: "multirotor", 1: "fixed-wing", 2: "standard VTOL", 3: "tiltrotor VTOL"}
#: CA_SV_CSn_TYPE: ActuatorEffectivenessControlSurfaces.hpp ``Type`` (PX4-Autopilot, 1..18)
SURFACE_TYPES = {1: "left_aileron", 2: "right_aileron", 3: "elevator", 4: "rudder", 5: "left_elevon",
                 6: "right_elevon", 7: "left_v_tail", 8: "right_v_tail", 9: "left_flap", 10: "right_flap",
                 11: "airbrake", 12: "custom", 13: "left_a_tail", 14: "right_a_tail", 15: "single_channel_aileron",
                 16: "steering_wheel", 17: "left_spoiler", 18: "right_spoiler"}
#: the types whose torque PX4 zeroes (``torque.setZero()`` in ActuatorEffectivenessControlSurfaces::
#: updateParams): flaps and spoilers are driven by their own setpoints, the steering wheel steers on
#: the ground, the airbrake brakes; none is allocated against a torque
NO_TORQUE_TYPES = (9, 10, 11, 16, 17, 18)
#: module.yaml defaults of the per-rotor and per-surface parameters
DEFAULTS = {"PX": 0.0, "PY": 0.0, "PZ": 0.0, "AX": 0.0, "AY": 0.0, "AZ": -1.0, "CT": 6.5, "KM": 0.05,
            "TYPE": 1, "TRQ_R": 0.0, "TRQ_P": 0.0, "TRQ_Y": 0.0, "TRIM": 0.0}
_MAX_ROTORS = 12
_MAX_SURFACES = 8
_INT32 = (-(2**31), 2**31 - 1)
#: MAVLink MAV_PARAM_TYPE codes QGroundControl writes: 1-8 integers, 9 float32, 10 float64
_INT_TYPES = range(1, 9)


@dataclass(frozen=True)
class ParamsRead:
    """What :func:`read_params_report` read: the parameters, and the lines it left out on purpose.

    ``skipped`` holds ``(line number, line)`` for each shell line of an airframe file (``. ${R}etc/
    init.d/rc.vtol_defaults``, ``set MAV_TYPE 22``, ``if``/``fi``): PX4 runs them, they set no
    parameter this importer reads, so they are listed rather than refused.
    """

    params: dict[str, float | int]
    skipped: tuple[tuple[int, str], ...] = ()
    airframe: bool = False
    #: ``(line number, name)`` of each later setting of a parameter this importer does not read (the
    #: last wins, as in PX4's shell); one it reads, set twice the same way, is refused instead
    overridden: tuple[tuple[int, str], ...] = ()

    def skipped_summary(self, limit: int = 6) -> str:
        """One line naming the skipped lines (the first ``limit`` quoted) and the overridden
        parameters, or ``""`` when there are none."""
        parts = []
        if self.skipped:
            shown = ", ".join(f"{n}: {text[:40]!r}" for n, text in self.skipped[:limit])
            more = f", and {len(self.skipped) - limit} more" if len(self.skipped) > limit else ""
            parts.append(f"{len(self.skipped)} shell line(s) skipped (line {shown}{more})")
        if self.overridden:
            shown = ", ".join(f"{name[:20]} at line {n}" for n, name in self.overridden[:limit])
            more = f", and {len(self.overridden) - limit} more" if len(self.overridden) > limit else ""
            parts.append(f"{len(self.overridden)} parameter(s) this importer does not read set again, the last "
                         f"kept ({shown}{more})")
        return "; ".join(parts)


#: the parameters :func:`vehicle_from_params` reads: every ``CA_`` one and these
READ_PARAMETERS = ("MPC_THR_HOVER", "FW_AIRSPD_TRIM", "FW_AIRSPD_STALL", "FW_AIRSPD_MAX", "FW_ARSP_SCALE_EN")


def reads_parameter(name: str) -> bool:
    """Whether :func:`vehicle_from_params` reads the parameter ``name``."""
    return name.startswith("CA_") or name in READ_PARAMETERS


#: a PX4 parameter name: at most 16 characters (param_t names, ``PARAM_ID_LEN``), letters, digits, _
_NAME = re.compile(r"[A-Za-z0-9_]{1,16}")
_PARAM_LINE = re.compile(r"\s*param\s+(set|set-default)(\s|$)")


def read_params(source: str | Path) -> dict[str, float | int]:
    """Parameters from a QGroundControl ``.params`` file, a PX4 airframe file, or their text.

    :func:`read_params_report` without the report of skipped lines.
    """
    return read_params_report(source).params


def read_params_report(source: str | Path) -> ParamsRead:
    """Parameters from a QGroundControl ``.params`` file, a PX4 airframe file, or their text.

    QGroundControl lines are tab-separated ``vehicle_id component_id NAME value type``
    (``1\\t1\\tCA_ROTOR0_PX\\t0.15\\t9``; type 9 = float32, 1-8 integers, 10 float64);
    ``#`` starts a comment.  A text with a ``#!`` first line or any ``param set``/``param
    set-default`` line is a PX4 airframe file as PX4 ships it (``ROMFS/px4fmu_common/init.d/
    airframes/``): its ``param set-default NAME value`` and ``param set NAME value`` lines are read,
    every other line is a shell line, skipped and listed in :attr:`ParamsRead.skipped`.  As in PX4,
    a ``param set`` value wins over a ``param set-default`` of the same name, whatever their order.
    A parameter this importer reads (:func:`reads_parameter`) set twice the same way is refused,
    naming both lines: the second would silently undo the first and change ``B``; any other
    parameter set twice keeps its last value, as PX4's shell does, and is listed in
    :attr:`ParamsRead.overridden` (shipped airframes do this: an old ``13014_vtol_babyshark`` sets
    ``MPC_JERK_AUTO`` twice).  Parameters inside shell conditionals
    (``if ... fi``) are read as if the condition held.

    A file is read through :func:`alloc._files.read_user_file` (a regular file of at most
    :data:`~alloc._files.MAX_TEXT_BYTES`, 1 MiB: a full PX4 parameter dump is about 40 KB); a
    text is held to the same length.  A name is at most 16 letters, digits or ``_`` (PX4's
    limit); a value is a finite number within ``1e50`` in magnitude.  A path is a
    :class:`~pathlib.Path`, or a string of one line that ends in ``.params`` or names a file.

    Raises
    ------
    ProblemError
        naming the line (``params: line 7: ...``), or ``path`` for a file that cannot be read.
    """
    text = params_text(source, is_path=isinstance(source, str) and "\n" not in source
                       and (source.endswith(".params") or os.path.isfile(source)))
    return params_from_text(text)


def looks_like_airframe(text: str) -> bool:
    """Whether ``text`` is a PX4 airframe file: a ``#!`` first line or a ``param set[-default]`` line."""
    return text.startswith("#!") or any(_PARAM_LINE.match(line) for line in text.splitlines())


def params_from_text(text: str) -> ParamsRead:
    """:func:`read_params_report` of a text already read (and held to its length)."""
    lines = text.splitlines()
    airframe = looks_like_airframe(text)
    values: dict[str, dict[str, float | int]] = {"set-default": {}, "set": {}, "qgc": {}}
    first_line: dict[tuple[str, str], int] = {}
    skipped: list[tuple[int, str]] = []
    overridden: list[tuple[int, str]] = []
    for n, raw in enumerate(lines, start=1):
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        words = line.split()
        if _PARAM_LINE.match(line):
            if len(words) != 4:
                raise ProblemError(f"params: line {n}: expected 'param {words[1]} NAME value', got "
                                   f"{raw.strip()[:60]!r}", field="params")
            kind, name, value, code = words[1], words[2], words[3], None
        elif airframe:
            skipped.append((n, raw.strip()))
            continue
        elif len(words) == 5:
            kind, name, value, code = "qgc", words[2], words[3], words[4]
        else:
            raise ProblemError(f"params: line {n}: expected 'vehicle component NAME value type' (tab-separated) or "
                               f"'param set-default NAME value', got {raw.strip()[:60]!r}", field="params")
        if not _NAME.fullmatch(name):
            raise ProblemError(f"params: line {n}: {name[:40]!r} is not a PX4 parameter name (at most 16 letters, "
                               "digits or _)", field="params")
        number = _number(value, code, f"params: line {n}: {name}")
        if (kind, name) in first_line:
            if reads_parameter(name):  # a silent override would change B: the file must say which it means
                raise ProblemError(f"params: line {n}: {name} is set again (first at line {first_line[kind, name]}); "
                                   "a parameter is set once", field="params")
            overridden.append((n, name))
        first_line[kind, name] = n
        values[kind][name] = number
    return ParamsRead({**values["qgc"], **values["set-default"], **values["set"]}, tuple(skipped), airframe,
                      tuple(overridden))


def _number(value: str, kind: str | None, label: str) -> float | int:
    """A parameter's value: an integer for QGroundControl's integer types (and integer text in an
    airframe), else a float; finite and within ``1e50``, or refused naming ``label``."""
    try:
        code = None if kind is None else int(kind)
        if code is not None and code in _INT_TYPES:
            number: float | int = int(value)
        elif code is None and _looks_int(value):
            number = int(value)
        else:
            number = float(value)
    except ValueError:
        raise ProblemError(f"{label[:80]}: {value[:40]!r} is not a number" +
                           ("" if kind is None else f" of type {kind[:20]}"), field="params") from None
    if not abs(number) <= MAX_MAGNITUDE:
        raise ProblemError(f"{label[:80]}: must be finite with |x| <= {MAX_MAGNITUDE:g}, got {value[:40]!r}",
                           field="params")
    return number


def _looks_int(text: str) -> bool:
    return text.lstrip("+-").isdigit()


def _get(params: Mapping[str, Any], name: str, default: float) -> float:
    """Parameter ``name`` (``default`` when absent): a finite real number, ``|x| <= 1e50``."""
    value = params.get(name, default)
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise ProblemError(f"{name}: expected a finite number, got {short_repr(value)}", field=name)
    try:
        x = float(value)
    except (OverflowError, TypeError, ValueError):
        x = math.inf
    if not abs(x) <= MAX_MAGNITUDE:
        raise ProblemError(f"{name}: expected a finite number with |x| <= {MAX_MAGNITUDE:g}, got "
                           f"{short_repr(value)}", field=name)
    return x


def _integer(params: Mapping[str, Any], name: str, default: int, low: int, high: int) -> int:
    """Parameter ``name``: a whole number in ``[low, high]`` (PX4's integer parameters are int32)."""
    x = _get(params, name, default)
    if not x.is_integer() or not low <= x <= high:
        raise ProblemError(f"{name}: expected an integer {low}..{high}, got {short_repr(params.get(name))}", field=name)
    return int(x)


def _count(params: Mapping[str, Any], name: str, high: int) -> int:
    return _integer(params, name, 0, 0, high)


def vehicle_from_params(params: Mapping[str, Any], *, name: str = "px4", normalize: str = "none",
                        axes: str = "auto", at: Mapping[str, float] | None = None) -> Vehicle:
    """The vehicle PX4 would allocate for with these parameters (see the module docstring).

    Parameters
    ----------
    params : mapping
        Parameter name -> value (:func:`read_params`); absent parameters take PX4's defaults.
    normalize : {"none", "px4"}
        ``"none"``: physical effectiveness; ``"px4"``: PX4's normalised effectiveness.
    axes : {"auto", "all"}
        ``"auto"`` leaves out the axes no effector acts on (at any scheduling point); ``"all"``
        keeps PX4's six.
    at : mapping, optional
        Tiltrotor only (``CA_AIRFRAME`` 3, :mod:`alloc.importers.px4_tiltrotor`): the scheduling
        variables' values (``tilt`` or ``collective_tilt``, ``airspeed``).  Without it the vehicle
        carries a ``[schedule]`` and its ``B`` is at the nominal point (tilts at their minimum, trim
        airspeed); with it, ``B`` is rebuilt at those values and the vehicle has no schedule.
    """
    if not isinstance(params, Mapping):
        raise ProblemError(f"params: expected a mapping of parameter names to numbers (read_params), got "
                           f"{type(params).__name__}", field="params")
    if normalize not in ("none", "px4"):
        raise ProblemError(f"normalize: expected 'none' or 'px4', got {normalize!r}", field="normalize")
    if axes not in ("auto", "all"):
        raise ProblemError(f"axes: expected 'auto' or 'all', got {axes!r}", field="axes")
    airframe = _get(params, "CA_AIRFRAME", 0)
    if airframe not in AIRFRAMES:
        known = ", ".join(f"{k} ({v})" for k, v in AIRFRAMES.items())
        raise ProblemError(f"CA_AIRFRAME: {short_repr(params.get('CA_AIRFRAME'))} is not supported; supported: {known}",
                           field="CA_AIRFRAME")
    airframe = int(airframe)
    n_rotors = _count(params, "CA_ROTOR_COUNT", _MAX_ROTORS)
    n_surfaces = _count(params, "CA_SV_CS_COUNT", _MAX_SURFACES) if airframe != 0 else 0
    reversible = _integer(params, "CA_R_REV", 0, _INT32[0], _INT32[1])  # a bitmask
    tiltrotor = Tiltrotor(params, _get, _integer, n_rotors) if airframe == 3 else None
    if at is not None and tiltrotor is None:
        raise ProblemError(f"at: only a tiltrotor (CA_AIRFRAME 3) has scheduling variables; this is a "
                           f"{AIRFRAMES[airframe]}", field="at")
    values = tiltrotor.values(at) if tiltrotor is not None else {}
    geometry: list[RotorGeometry] = []
    surface_columns: dict[int, np.ndarray] = {}

    columns: list[np.ndarray] = []  # 6-vectors, PX4's axis order
    matrix: list[int] = []  # which PX4 matrix each effector is in
    effectors: list[dict[str, Any]] = []
    for i in range(n_rotors):
        def p(suffix: str) -> float:
            return _get(params, f"CA_ROTOR{i}_{suffix}", DEFAULTS[suffix])

        position = [p("PX"), p("PY"), p("PZ")]
        axis = [1.0, 0.0, 0.0] if airframe == 1 else [p("AX"), p("AY"), p("AZ")]
        ct, km = p("CT"), p("KM")
        if airframe == 1 or (airframe == 2 and not _upwards(axis)):
            km = 0.0
        lo = -1.0 if reversible >> i & 1 else 0.0
        e: dict[str, Any] = {"name": f"motor{i + 1}", "kind": "rotor", "unit": "1", "min": lo, "max": 1.0}
        slew = _get(params, f"CA_R{i}_SLEW", 0.0)
        if slew < 0:
            raise ProblemError(f"CA_R{i}_SLEW: must be >= 0, got {slew:g}", field=f"CA_R{i}_SLEW")
        if slew > 0:
            e["rate_max"] = _rate(1.0 - lo, slew, f"CA_R{i}_SLEW")
        geometry.append(RotorGeometry((position[0], position[1], position[2]), (axis[0], axis[1], axis[2]), ct, km,
                                      -1 if tiltrotor is None else tiltrotor.rotor_tilt[i]))
        if tiltrotor is not None:  # the tilt turns the column and PX4 rewrites its yaw and thrust rows
            columns.append(tiltrotor.rotor_column(geometry[-1], values))
        else:
            columns.append(rotor_wrench(position, axis, ct, km))
        if normalize == "none" and tiltrotor is None and ct >= FLT_EPSILON and math.hypot(*axis) > FLT_EPSILON \
                and ct > 0:
            e["rotor"] = {"position": position, "axis": axis, "ct": ct, "km": km}
        matrix.append(0)
        effectors.append(e)
    names = {e["name"] for e in effectors}
    for i in range(n_surfaces):
        kind = _integer(params, f"CA_SV_CS{i}_TYPE", DEFAULTS["TYPE"], 0, _INT32[1])
        torque = [_get(params, f"CA_SV_CS{i}_TRQ_{a}", 0.0) for a in "RPY"]
        if kind in NO_TORQUE_TYPES:
            torque = [0.0, 0.0, 0.0]
        base = SURFACE_TYPES.get(kind, f"surface_type{kind}")
        label = base if base not in names else f"{base}_{i}"
        names.add(label)
        e = {"name": label, "kind": "surface", "unit": "1", "min": -1.0, "max": 1.0}
        trim = _get(params, f"CA_SV_CS{i}_TRIM", 0.0)
        if not -1.0 <= trim <= 1.0:
            raise ProblemError(f"CA_SV_CS{i}_TRIM: must be in [-1, 1], got {trim:g}", field=f"CA_SV_CS{i}_TRIM")
        if trim != 0.0:
            e["preferred"] = trim
        slew = _get(params, f"CA_SV{i}_SLEW", 0.0)
        if slew < 0:
            raise ProblemError(f"CA_SV{i}_SLEW: must be >= 0, got {slew:g}", field=f"CA_SV{i}_SLEW")
        if slew > 0:
            e["rate_max"] = _rate(2.0, slew, f"CA_SV{i}_SLEW")
        surface_columns[len(columns)] = np.array([*torque, 0.0, 0.0, 0.0])
        factor = 1.0 if tiltrotor is None else tiltrotor.surface_factor(values)
        columns.append(factor * surface_columns[len(columns)])
        matrix.append(0 if airframe == 1 else 1)
        effectors.append(e)
    if tiltrotor is not None:
        for t, column in enumerate(tiltrotor.tilt_columns(geometry)):
            columns.append(column)
            matrix.append(0)
            effectors.append({"name": f"tilt{t + 1}", "kind": "thrust-vector", "unit": "1", "min": -1.0, "max": 1.0})
    if not effectors:
        raise ProblemError("CA_ROTOR_COUNT: the parameters define no rotor and no control surface",
                           field="CA_ROTOR_COUNT")

    B6 = np.array(columns, dtype=float).T  # (6, m)
    m = B6.shape[1]
    terms: list[dict[str, Any]] = []
    if tiltrotor is not None and at is None:
        terms = tiltrotor.terms(geometry, m) + tiltrotor.surface_term(surface_columns, m)
    if normalize == "px4":
        # a tiltrotor's scales are those of the tilts at their minimum, kept as they turn (as PX4)
        hover = B6 if tiltrotor is None else _tiltrotor_B6(tiltrotor, geometry, surface_columns, m)
        rpy = {0: (True,), 1: (False,), 2: (True, False), 3: (True, False)}[airframe]
        with np.errstate(over="ignore", invalid="ignore"):  # extreme geometry: checked just below
            for mat in sorted(set(matrix)):
                cols = [j for j, mj in enumerate(matrix) if mj == mat]
                try:
                    s = px4_scales(hover[:, cols], normalize_rpy=rpy[mat])[:, None]
                except np.linalg.LinAlgError as exc:
                    raise ProblemError(f"normalize: PX4's normalisation has no answer for these parameters ({exc})",
                                       field="normalize") from None
                for target in (B6, *(term["B"] for term in terms)):
                    target[:, cols] = s * target[:, cols]
    # the parameters are each within 1e50; their products may not be, nor a term at its largest factor
    # (sin, cos: 1; the surfaces' square: at the top of the airspeed clamp)
    peaks = [1.0 if t["factor"] in ("sin", "cos") else (t["scale"] * t["clamp"][1] + t["offset"]) ** 2 for t in terms]
    with np.errstate(over="ignore", invalid="ignore"):
        largest = np.max([np.abs(B6), *(peak * np.abs(t["B"]) for peak, t in zip(peaks, terms))], axis=(0, 1))
    for j in range(m):
        if not largest[j] <= MAX_MAGNITUDE:
            where = (f"CA_ROTOR{j}" if j < n_rotors else f"CA_SV_CS{j - n_rotors}" if j < n_rotors + n_surfaces
                     else f"CA_SV_TL{j - n_rotors - n_surfaces}")
            raise ProblemError(f"{where}: the effectiveness column of these parameters is not finite within "
                               f"{MAX_MAGNITUDE:g}: {short_repr(B6[:, j].tolist())}", field=where)
    acting = np.any(B6 != 0.0, axis=1) | np.any([np.any(t["B"] != 0.0, axis=1) for t in terms] or [False], axis=0)
    keep = list(range(6)) if axes == "all" else [r for r in range(6) if acting[r]]
    if not keep:
        raise ProblemError("CA_ROTOR_COUNT: no effector acts on any axis (all columns zero)", field="CA_ROTOR_COUNT")
    moment_unit, force_unit = ("1", "1") if normalize == "px4" else ("N m", "N")
    doc_axes = [{"name": WRENCH_COMPONENTS[r], "unit": moment_unit if r < 3 else force_unit} for r in keep]
    if "MPC_THR_HOVER" in params and 5 in keep:
        hover = _get(params, "MPC_THR_HOVER", 0.5)
        if not 0.0 <= hover <= 1.0:
            raise ProblemError(f"MPC_THR_HOVER: must be in [0, 1], got {hover:g}", field="MPC_THR_HOVER")
        # every rotor at the hover command: the thrust the controllability report measures around
        trim = float(hover * B6[5, :n_rotors].sum())
        if not abs(trim) <= MAX_MAGNITUDE:
            raise ProblemError(f"MPC_THR_HOVER: the hover thrust {trim:g} is beyond {MAX_MAGNITUDE:g}",
                               field="MPC_THR_HOVER")
        doc_axes[keep.index(5)]["trim"] = trim
    for j, e in enumerate(effectors):
        if "rotor" not in e:
            e["effectiveness"] = [float(B6[r, j]) for r in keep]
    doc = {
        "format": FORMAT, "name": name,
        "description": f"PX4 {AIRFRAMES[airframe]}: {n_rotors} rotor(s), {n_surfaces} control surface(s)",
        "source": (f"PX4 parameters (CA_AIRFRAME {airframe}); effectiveness by ActuatorEffectivenessRotors::"
                   f"computeEffectivenessMatrix and ActuatorEffectivenessControlSurfaces; normalize={normalize}"),
        "axes": doc_axes, "effectors": effectors,
    }
    if tiltrotor is not None and at is not None:
        doc["description"] += " at " + ", ".join(f"{k} {v:g}" for k, v in values.items())
    if terms:
        doc["format"] = FORMAT_SCHEDULE
        doc["schedule"] = {"variables": tiltrotor.variables() if tiltrotor is not None else [],
                           "terms": [{**t, "B": [[float(t["B"][r, j]) for j in range(m)] for r in keep]}
                                     for t in terms]}
    return vehicle_from_dict(doc)


def _tiltrotor_B6(tiltrotor: Tiltrotor, geometry: list[RotorGeometry], surfaces: Mapping[int, np.ndarray],
                  m: int) -> np.ndarray:
    """A tiltrotor's six-row ``B`` at the nominal point (tilts at their minimum, trim airspeed): where PX4
    computes its normalisation scales."""
    values = tiltrotor.values(None)
    B6 = np.zeros((6, m))
    for j, rotor in enumerate(geometry):
        B6[:, j] = tiltrotor.rotor_column(rotor, values)
    factor = tiltrotor.surface_factor(values)
    for j, column in surfaces.items():
        B6[:, j] = factor * column
    for t, column in enumerate(tiltrotor.tilt_columns(geometry)):
        B6[:, m - len(tiltrotor.tilts) + t] = column
    return B6


def _rate(full_range: float, slew: float, name: str) -> float:
    """The rate limit of a slew time (``range / slew``), refused naming ``name`` beyond 1e50."""
    rate = full_range / slew
    if not rate <= MAX_MAGNITUDE:
        raise ProblemError(f"{name}: {slew:g} s gives a rate limit {rate:g} beyond {MAX_MAGNITUDE:g}", field=name)
    return rate


def _upwards(axis: list[float]) -> bool:
    """PX4's test in computeEffectivenessMatrix (on the normalised axis)."""
    a = np.asarray(axis, dtype=float)
    n = float(np.linalg.norm(a))
    if not n > FLT_EPSILON:
        return True  # a zero axis gives a zero column anyway
    a = a / n
    return abs(a[0]) < 0.1 and abs(a[1]) < 0.1 and a[2] < -0.5


def px4_scales(B6: np.ndarray, *, normalize_rpy: bool) -> np.ndarray:
    """PX4's six axis scales ``s`` for one effectiveness matrix ``B6`` (6 x m); see the module docstring.

    ``ControlAllocationPseudoInverse::updateControlAllocationMatrixScale`` on ``M = pinv(B6)``,
    with the FLT_EPSILON guards of ``normalizeControlAllocationMatrix`` folded in (an unused
    scale is 1).  The normalised effectiveness is ``s[:, None] * B6``.
    """
    B6 = as_float_array("B6", B6, ProblemError)
    if B6.ndim != 2 or B6.shape[0] != 6 or not np.isfinite(B6).all():
        raise ProblemError(f"B6: expected a finite 6 x m matrix, got shape {B6.shape}", field="B6")
    return mix_scales(np.linalg.pinv(B6), normalize_rpy=normalize_rpy)
