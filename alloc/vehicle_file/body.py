"""The ``[body]`` table of a vehicle file: the rigid body and its rotors' physics, and the hover
linear model derived from it.

::

    [body]
    mass = 2.0                          # kg
    inertia = [0.08, 0.08, 0.15]        # kg m^2: the diagonal, or the 3 x 3 matrix (body axes, x fwd, y right, z down)
    rotor_speed_max = 1000.0            # optional, rad/s: a rotor's speed at full command (u = 1)
    thrust_coefficient = 6.5e-6         # optional, N / (rad/s)^2 (k_eta: thrust = k_eta w^2)
    torque_coefficient = 3.25e-7        # optional, N m / (rad/s)^2 (k_m: drag torque = k_m w^2)
    motor_time_constant = 0.0333        # optional, s (first-order lag of a rotor's speed)

A rotor's effectiveness stays where the format puts it, in its effector's ``rotor`` table: ``ct`` is
its thrust at full command and ``km`` its torque per thrust (:class:`~alloc.vehicle_file.parts.Rotor`).
The rotor fields of ``[body]`` say what a physics simulator needs beyond that, and are tied to it:
``ct = thrust_coefficient * rotor_speed_max^2`` and ``|km| = torque_coefficient /
thrust_coefficient`` for every rotor.  Any one of ``rotor_speed_max`` and ``thrust_coefficient``
gives the other through ``ct``; both given must agree (to 1e-6 relative); so must a
``torque_coefficient`` with ``km``.  ``motor_time_constant`` not given is the rotors' own first-order
``dynamics`` (``time_constant``, or ``1 / bandwidth``) when they all share one.

The hover model (:meth:`Body.hover_model`): about a level hover, with the axes ``roll``, ``pitch``,
``yaw`` (N m) and ``fz`` (N, body z down) of the vehicle's effectiveness ``B``, the states
``phi, theta, psi`` (rad), ``p, q, r`` (rad/s) and ``w`` (m/s, body z velocity) obey::

    phi' = p,  theta' = q,  psi' = r,  [p q r]' = J^-1 B[roll, pitch, yaw] u,  w' = B[fz] u / m

(small angles and rates: Euler's gyroscopic term and the gravity's tilt are second order at hover).
A file with ``[body]`` and no ``[model]`` flies this model in ``alloc sim``; a file with both keeps
its own ``[model]``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from .fields import _fail, _keys, _list, _matrix, _positive, _real, _reals, _table
from .parts import Axis, Effector, LinearModel

__all__ = ["Body", "HOVER_STATES", "HOVER_CONTROLLED", "COEFFICIENT_RTOL"]

#: the states (= outputs) of the hover model, and their units
HOVER_STATES = ("phi", "theta", "psi", "p", "q", "r", "w")
HOVER_UNITS = ("rad", "rad", "rad", "rad/s", "rad/s", "rad/s", "m/s")
#: the outputs the four axes control (roll, pitch, yaw, fz in that order)
HOVER_CONTROLLED = ("p", "q", "r", "w")
#: wrench components the hover model needs, in the order of the controlled outputs
HOVER_COMPONENTS = ("roll", "pitch", "yaw", "fz")
#: how closely given coefficients must agree with the rotors' ct and km (round-off of a decimal file)
COEFFICIENT_RTOL = 1e-6


@dataclass(frozen=True)
class Body:
    """The rigid body (mass, inertia) and the rotors' physics; see the module docstring."""

    mass: float
    inertia: tuple[tuple[float, float, float], ...]
    rotor_speed_max: float | None = None
    thrust_coefficient: float | None = None
    torque_coefficient: float | None = None
    motor_time_constant: float | None = None
    #: whether the file gave the inertia as its diagonal (written back the same way)
    diagonal: bool = True

    FIELDS = ("mass", "inertia", "rotor_speed_max", "thrust_coefficient", "torque_coefficient", "motor_time_constant")

    @classmethod
    def from_dict(cls, data: Any, path: str, effectors: Sequence[Effector]) -> Body:
        table = _table(data, path)
        _keys(table, path, cls.FIELDS, required=("mass", "inertia"))
        mass = _positive(table["mass"], f"{path}.mass")
        inertia, diagonal = _inertia(table["inertia"], f"{path}.inertia")
        kw: dict[str, Any] = {}
        for f in ("rotor_speed_max", "thrust_coefficient", "motor_time_constant"):
            if f in table:
                kw[f] = _positive(table[f], f"{path}.{f}")
        if "torque_coefficient" in table:
            k_m = _real(table["torque_coefficient"], f"{path}.torque_coefficient")
            if k_m < 0.0:
                raise _fail(f"{path}.torque_coefficient", f"must be >= 0 (the sign is each rotor's km), got {k_m:g}")
            kw["torque_coefficient"] = k_m
        body = cls(mass=mass, inertia=inertia, diagonal=diagonal, **kw)
        body._check_rotors(path, effectors)
        return body

    def _check_rotors(self, path: str, effectors: Sequence[Effector]) -> None:
        """The rotor fields against every rotor's ``ct`` and ``km`` (ProblemError naming the field)."""
        rotors = [(j, e.rotor) for j, e in enumerate(effectors) if e.rotor is not None]
        given = [f for f in ("rotor_speed_max", "thrust_coefficient", "torque_coefficient") if getattr(self, f) is not None]
        if given and not rotors:
            raise _fail(f"{path}.{given[0]}", "the vehicle has no rotors (no effector has a rotor table)")
        w, k_eta, k_m = self.rotor_speed_max, self.thrust_coefficient, self.torque_coefficient
        for j, rotor in rotors:
            if w is not None and k_eta is not None and not _close(rotor.ct, k_eta * w * w):
                raise _fail(f"{path}.thrust_coefficient", f"{k_eta:g} x rotor_speed_max^2 = {k_eta * w * w:g} N, but "
                            f"effectors[{j}].rotor.ct = {rotor.ct:g} N (the thrust at full command)")
            if k_m is not None and k_eta is not None and not _close(abs(rotor.km), k_m / k_eta):
                raise _fail(f"{path}.torque_coefficient", f"{k_m:g} / thrust_coefficient = {k_m / k_eta:g} m, but "
                            f"|effectors[{j}].rotor.km| = {abs(rotor.km):g} m (torque per thrust)")
        if k_m is not None and k_eta is None:
            raise _fail(f"{path}.torque_coefficient", "needs thrust_coefficient (or derive both: give rotor_speed_max)")

    def to_dict(self) -> dict[str, Any]:
        inertia: Any = [self.inertia[i][i] for i in range(3)] if self.diagonal else [list(r) for r in self.inertia]
        out: dict[str, Any] = {"mass": self.mass, "inertia": inertia}
        for f in self.FIELDS[2:]:
            if getattr(self, f) is not None:
                out[f] = getattr(self, f)
        return out

    @property
    def J(self) -> np.ndarray:
        """The inertia matrix (kg m^2)."""
        return np.array(self.inertia, dtype=float)

    def rotor_speed_max_for(self, ct: float) -> float | None:
        """A rotor's speed at full command: given, or ``sqrt(ct / thrust_coefficient)``; None: neither given."""
        if self.rotor_speed_max is not None:
            return self.rotor_speed_max
        if self.thrust_coefficient is not None:
            return float(np.sqrt(ct / self.thrust_coefficient))
        return None

    def hover_model(self, axes: Sequence[Axis], B: Sequence[Sequence[float]], path: str = "body") -> LinearModel:
        """The hover linear model of the module docstring, from the vehicle's axes and effectiveness ``B``.

        Raises ProblemError naming ``axes`` when an axis is not one of roll, pitch, yaw, fz, or one is missing.
        """
        rows = {}
        for i, axis in enumerate(axes):
            comp = axis.component
            if comp not in HOVER_COMPONENTS:
                raise _fail(f"axes[{i}].wrench", f"the hover model of [body] covers the axes roll, pitch, yaw and fz; "
                            f"axis {axis.name!r} is {comp or 'none of them'} (give a [model] instead)")
            rows[comp] = i
        missing = [c for c in HOVER_COMPONENTS if c not in rows]
        if missing:
            raise _fail("axes", f"the hover model of [body] needs an axis for each of roll, pitch, yaw, fz; "
                        f"missing {', '.join(missing)} (give a [model] instead)")
        Bv = np.asarray(B, dtype=float)
        m = Bv.shape[1]
        moments = Bv[[rows["roll"], rows["pitch"], rows["yaw"]]]
        angular = np.linalg.solve(self.J, moments)  # J is checked symmetric positive definite
        n = len(HOVER_STATES)
        A = np.zeros((n, n))
        A[0:3, 3:6] = np.eye(3)  # small-angle kinematics at hover: Euler rates = body rates
        Bm = np.zeros((n, m))
        Bm[3:6] = angular
        Bm[6] = Bv[rows["fz"]] / self.mass
        return LinearModel(
            states=HOVER_STATES, outputs=HOVER_STATES, A=_rows(A), B=_rows(Bm), C=_rows(np.eye(n)),
            D=_rows(np.zeros((n, m))), controlled=HOVER_CONTROLLED, units=HOVER_UNITS)


def _close(a: float, b: float) -> bool:
    return abs(a - b) <= COEFFICIENT_RTOL * max(abs(a), abs(b))


def _rows(M: np.ndarray) -> tuple[tuple[float, ...], ...]:
    return tuple(tuple(float(x) for x in row) for row in M)


def _inertia(value: Any, path: str) -> tuple[tuple[tuple[float, float, float], ...], bool]:
    """The inertia as a 3 x 3 matrix, and whether it was given as a diagonal; symmetric positive definite."""
    entries = _list(value, path)
    if len(entries) == 3 and not any(isinstance(x, (list, tuple)) for x in entries):
        d = _reals(entries, path, 3)
        for i, x in enumerate(d):
            if not x > 0.0:
                raise _fail(f"{path}[{i}]", f"a principal moment of inertia must be > 0, got {x:g}")
        J = np.diag(d)
        diagonal = True
    else:
        J = np.array(_matrix(entries, path, 3, 3), dtype=float)
        diagonal = False
        if not np.allclose(J, J.T, rtol=0.0, atol=COEFFICIENT_RTOL * float(np.abs(J).max(initial=0.0))):
            raise _fail(path, "the inertia matrix must be symmetric")
        if not np.all(np.linalg.eigvalsh(0.5 * (J + J.T)) > 0.0):
            raise _fail(path, "the inertia matrix must be positive definite")
    # the triangle inequalities of a rigid body's principal moments (a physical inertia)
    ev = np.linalg.eigvalsh(0.5 * (J + J.T))
    if ev[0] + ev[1] < ev[2] * (1.0 - COEFFICIENT_RTOL):
        raise _fail(path, f"principal moments {ev.tolist()} break the triangle inequality (no rigid body has them)")
    return tuple(tuple(float(x) for x in row) for row in J), diagonal
