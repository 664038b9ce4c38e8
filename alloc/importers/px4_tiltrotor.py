"""PX4's tiltrotor VTOL (``CA_AIRFRAME`` 3): its effectiveness at any tilt and airspeed, and the same
as a schedule (:mod:`alloc.vehicle_file.schedule`).

By PX4's own code (PX4/PX4-Autopilot ``src/modules/control_allocator/VehicleActuatorEffectiveness/``):

* ``ActuatorEffectivenessTiltrotorVTOL::getEffectivenessMatrix`` (commit 000f5fdbbef9): matrix 0
  holds the rotors and the tilt servos, matrix 1 the control surfaces.  The rotors' yaw row is 0
  when a tilt servo controls yaw (``enableYawByDifferentialThrust(!hasYawControl())``), and their
  thrust rows are ``(0, 0, -CT)`` whatever the tilt (``enableThreeDimensionalThrust(false)``: PX4
  passes the thrust magnitude on z and the collective tilt apart).  The normalisation scales are
  computed with the tilts at their minimum (``collective_tilt_control_applied = -1`` on a
  configuration update) and kept while the tilt moves.
* ``ActuatorEffectivenessRotors::updateAxisFromTilts`` / ``tiltedAxis`` (commit 1da805dc2d25): a
  rotor with ``CA_ROTORn_TILT = t`` (1-based) turns with tilt servo ``t - 1``, its axis
  ``Rz(direction) Ry(-angle) (0, 0, -1) = (sin(angle) cos(direction), sin(angle) sin(direction),
  -cos(angle))`` at ``angle = lerp(CA_SV_TLt_MINA, CA_SV_TLt_MAXA, (c + 1) / 2)`` for the collective
  tilt ``c`` in [-1, 1]; a rotor with no valid tilt keeps its configured axis.
* ``ActuatorEffectivenessTilts::updateTorqueSign`` (commit 21b82c32cb03): a tilt servo used for
  yaw (``CA_SV_TLn_CT`` 1 or 3) has yaw torque +1 when its rotor lies left of the tilt direction
  (the position turned by ``-direction`` has y < -0.01), -1 when right (y > 0.01); its pitch
  torque is disabled for a tiltrotor; no force.

Airspeed, as PX4 scales the surfaces: ``FixedwingRateControl`` (``src/modules/fw_rate_control/
FixedwingRateControl.cpp``, commit 3e1f68e5dc5b) multiplies its torque setpoint by
``(FW_AIRSPD_TRIM / V)^2`` with ``V`` held to ``[FW_AIRSPD_STALL, FW_AIRSPD_MAX]`` (when
``FW_ARSP_SCALE_EN``), i.e. the surfaces' effect per unit of PX4's torque setpoint grows as
``(V / FW_AIRSPD_TRIM)^2``: the surface columns are scaled by that factor (1 at trim airspeed).

The scheduling variables: ``tilt`` in degrees when every tilt servo has the same range (its
nominal is the minimum angle, PX4's hover), else ``collective_tilt`` in [-1, 1] (nominal -1); and
``airspeed`` in m/s (nominal ``FW_AIRSPD_TRIM``).  A tilted rotor's column is linear in its axis,
``sin(angle) h + cos(angle) v``, so the schedule has a sine and a cosine term per tilt range and a
square term for the surfaces.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..exceptions import ProblemError
from ..problem import short_repr
from ..vehicle_file.parts import rotor_wrench

__all__ = ["Tilt", "Tiltrotor", "tilted_axis"]

_FLT_EPSILON = float(np.finfo(np.float32).eps)
_MAX_TILTS = 4  # ActuatorEffectivenessTilts::MAX_COUNT
#: CA_SV_TLn_CT: 0 none, 1 yaw, 2 pitch, 3 yaw and pitch (module.yaml default 1)
_YAW_CONTROLS = (1, 3)
#: the outer bounds PX4 holds the airspeed to before scaling (``constrain(..., 0.1f, 1000.0f)``)
_AIRSPEED_RANGE = (0.0, 1000.0)


def tilted_axis(angle_deg: float, direction_deg: float) -> np.ndarray:
    """PX4's ``tiltedAxis``: ``Dcm(Euler(0, -angle, direction)) (0, 0, -1)``, written as the rotations
    ``Rz(direction) Ry(-angle)`` applied to the upward axis."""
    t, d = math.radians(angle_deg), math.radians(direction_deg)
    ry = np.array([[math.cos(-t), 0.0, math.sin(-t)], [0.0, 1.0, 0.0], [-math.sin(-t), 0.0, math.cos(-t)]])
    rz = np.array([[math.cos(d), -math.sin(d), 0.0], [math.sin(d), math.cos(d), 0.0], [0.0, 0.0, 1.0]])
    return rz @ ry @ np.array([0.0, 0.0, -1.0])


@dataclass(frozen=True)
class Tilt:
    """One tilt servo (``CA_SV_TLn_*``): its control use, angles at minimum and maximum command, direction."""

    control: int
    min_angle: float
    max_angle: float
    direction: float

    def mapping(self, by_angle: bool) -> tuple[float, float]:
        """``(scale, offset)``: the servo's angle in degrees from the scheduling variable."""
        if by_angle:
            return 1.0, 0.0
        return (self.max_angle - self.min_angle) / 2.0, (self.max_angle + self.min_angle) / 2.0


@dataclass(frozen=True)
class RotorGeometry:
    """What a rotor's column needs: position, configured axis, CT, KM and its tilt (``-1``: none)."""

    position: tuple[float, float, float]
    axis: tuple[float, float, float]
    ct: float
    km: float
    tilt: int


class Tiltrotor:
    """A tiltrotor's tilts and airspeed scaling, read from the parameters (see the module docstring)."""

    def __init__(self, params: Mapping[str, Any], get: Callable[..., float], integer: Callable[..., int],
                 n_rotors: int) -> None:
        n = integer(params, "CA_SV_TL_COUNT", 0, 0, _MAX_TILTS)
        tilts = []
        for t in range(n):
            control = integer(params, f"CA_SV_TL{t}_CT", 1, 0, 3)
            lo, hi = get(params, f"CA_SV_TL{t}_MINA", 0.0), get(params, f"CA_SV_TL{t}_MAXA", 90.0)
            for label, value in ((f"CA_SV_TL{t}_MINA", lo), (f"CA_SV_TL{t}_MAXA", hi)):
                if not -90.0 <= value <= 90.0:  # module.yaml's range
                    raise ProblemError(f"{label}: must be in [-90, 90] degrees, got {value:g}", field=label)
            tilts.append(Tilt(control, lo, hi, float(integer(params, f"CA_SV_TL{t}_TD", 0, 0, 359))))
        self.tilts = tuple(tilts)
        # PX4 keeps CA_ROTORn_TILT - 1; an index past the tilts leaves the rotor untilted
        self.rotor_tilt = tuple(integer(params, f"CA_ROTOR{i}_TILT", 0, 0, _MAX_TILTS) - 1 for i in range(n_rotors))
        self.yaw_by_tilt = any(t.control in _YAW_CONTROLS for t in self.tilts)
        self.by_angle = len({(t.min_angle, t.max_angle) for t in self.tilts}) <= 1
        self.scale_surfaces = integer(params, "FW_ARSP_SCALE_EN", 1, 0, 1) == 1
        self.trim = get(params, "FW_AIRSPD_TRIM", 15.0)
        self.stall, self.vmax = get(params, "FW_AIRSPD_STALL", 7.0), get(params, "FW_AIRSPD_MAX", 20.0)
        if self.scale_surfaces:
            if not self.trim > 0:
                raise ProblemError(f"FW_AIRSPD_TRIM: must be > 0, got {self.trim:g}", field="FW_AIRSPD_TRIM")
            if not 0 < self.stall <= self.vmax:
                raise ProblemError(f"FW_AIRSPD_STALL: must be in (0, FW_AIRSPD_MAX = {self.vmax:g}], got "
                                   f"{self.stall:g}", field="FW_AIRSPD_STALL")

    # ------------------------------------------------------------------ the scheduling variables
    def variables(self) -> list[dict[str, Any]]:
        """The schedule's variables (``tilt`` or ``collective_tilt``, and ``airspeed``)."""
        out = []
        if self.tilts:
            if self.by_angle:
                t = self.tilts[0]
                out.append({"name": "tilt", "unit": "deg", "min": min(t.min_angle, t.max_angle),
                            "max": max(t.min_angle, t.max_angle), "nominal": t.min_angle})
            else:
                out.append({"name": "collective_tilt", "unit": "1", "min": -1.0, "max": 1.0, "nominal": -1.0})
        if self.scale_surfaces:
            out.append({"name": "airspeed", "unit": "m/s", "min": _AIRSPEED_RANGE[0], "max": _AIRSPEED_RANGE[1],
                        "nominal": self.trim})
        return out

    def values(self, at: Mapping[str, Any] | None) -> dict[str, float]:
        """Every variable's value: ``at``'s, else nominal; each checked against its range, naming it."""
        variables = self.variables()
        at = dict(at or {})
        known = {v["name"] for v in variables}
        unknown = [name for name in at if name not in known]
        if unknown:
            raise ProblemError(f"at: unknown scheduling variable {short_repr(unknown[0])}; this vehicle has: "
                               f"{', '.join(sorted(known)) or 'none'}", field="at")
        out = {}
        for v in variables:
            x = at.get(v["name"], v["nominal"])
            if isinstance(x, bool) or not isinstance(x, (int, float)) or not v["min"] <= x <= v["max"]:
                raise ProblemError(f"{v['name']}: must be a number in [{v['min']:g}, {v['max']:g}] {v['unit']}, got "
                                   f"{short_repr(x)}", field=v["name"])
            out[v["name"]] = float(x)
        return out

    def angle(self, t: int, values: Mapping[str, float]) -> float:
        """Tilt servo ``t``'s angle in degrees at ``values``."""
        scale, offset = self.tilts[t].mapping(self.by_angle)
        x = values["tilt"] if self.by_angle else values["collective_tilt"]
        return scale * x + offset

    def surface_factor(self, values: Mapping[str, float]) -> float:
        """``(V / FW_AIRSPD_TRIM)^2`` with ``V`` held to ``[FW_AIRSPD_STALL, FW_AIRSPD_MAX]`` (1 without scaling)."""
        if not self.scale_surfaces:
            return 1.0
        v = min(max(values["airspeed"], self.stall), self.vmax)
        return (v / self.trim) ** 2

    # ------------------------------------------------------------------ columns at given values (a rebuild)
    def _tilt_of(self, rotor: RotorGeometry) -> int:
        return rotor.tilt if 0 <= rotor.tilt < len(self.tilts) else -1

    def rotor_column(self, rotor: RotorGeometry, values: Mapping[str, float]) -> np.ndarray:
        """The rotor's column at ``values``: turned axis, yaw row and 3-D thrust as PX4 sets them."""
        t = self._tilt_of(rotor)
        axis = rotor.axis if t < 0 else tilted_axis(self.angle(t, values), self.tilts[t].direction)
        column = rotor_wrench(rotor.position, axis, rotor.ct, rotor.km)
        if not np.linalg.norm(axis) > _FLT_EPSILON or not abs(rotor.ct) >= _FLT_EPSILON:
            return column  # PX4 skips the rotor: its column stays zero
        if self.yaw_by_tilt:
            column[2] = 0.0
        column[3:] = (0.0, 0.0, -rotor.ct)
        return column

    def tilt_columns(self, rotors: Sequence[RotorGeometry]) -> list[np.ndarray]:
        """Each tilt servo's column: yaw +-1 by the side of its (last) rotor, nothing else."""
        yaw = [0.0] * len(self.tilts)
        for rotor in rotors:
            t = self._tilt_of(rotor)
            if t < 0 or self.tilts[t].control not in _YAW_CONTROLS:
                continue
            d = math.radians(self.tilts[t].direction)
            y = -math.sin(d) * rotor.position[0] + math.cos(d) * rotor.position[1]  # position turned by -d
            if y < -0.01:
                yaw[t] = 1.0
            elif y > 0.01:
                yaw[t] = -1.0
        return [np.array([0.0, 0.0, w, 0.0, 0.0, 0.0]) for w in yaw]

    # ------------------------------------------------------------------ the same as schedule terms
    def terms(self, rotors: Sequence[RotorGeometry], m: int) -> list[dict[str, Any]]:
        """The rotors' schedule terms on PX4's six rows (``B`` a 6 x m array): per tilt range a sine and a
        cosine term, ``sin(angle) M(h) + cos(angle) M(v)`` with ``M(a) = CT (p x a) - CT KM a`` (yaw row
        zeroed as in :meth:`rotor_column`) for ``h = (cos d, sin d, 0)`` and ``v = (0, 0, -1)``; the
        thrust rows do not turn (PX4 passes ``-CT`` on z)."""
        groups: dict[tuple[float, float], dict[str, np.ndarray]] = {}
        for j, rotor in enumerate(rotors):
            t = self._tilt_of(rotor)
            if t < 0 or abs(rotor.ct) < _FLT_EPSILON:
                continue
            d = math.radians(self.tilts[t].direction)
            pair = groups.setdefault(self.tilts[t].mapping(self.by_angle),
                                     {"sin": np.zeros((6, m)), "cos": np.zeros((6, m))})
            for factor, a in (("sin", (math.cos(d), math.sin(d), 0.0)), ("cos", (0.0, 0.0, -1.0))):
                moment = rotor.ct * np.cross(rotor.position, a) - rotor.ct * rotor.km * np.array(a)
                if self.yaw_by_tilt:
                    moment[2] = 0.0
                pair[factor][:3, j] = moment
        variable = "tilt" if self.by_angle else "collective_tilt"
        # a term's angle is in its variable's unit: degrees for tilt, radians for the unitless collective
        to_unit = (lambda a: a) if self.by_angle else math.radians
        return [{"factor": factor, "variable": variable, "scale": to_unit(scale), "offset": to_unit(offset), "B": B}
                for (scale, offset), pair in groups.items() for factor, B in pair.items()]

    def surface_term(self, columns: Mapping[int, np.ndarray], m: int) -> list[dict[str, Any]]:
        """The surfaces' square term: ``((clamp(V, stall, max) / trim)^2) * column``."""
        if not self.scale_surfaces or not columns:
            return []
        B = np.zeros((6, m))
        for j, column in columns.items():
            B[:, j] = column
        return [{"factor": "square", "variable": "airspeed", "scale": 1.0 / self.trim, "offset": 0.0,
                 "clamp": [self.stall, self.vmax], "B": B}]
