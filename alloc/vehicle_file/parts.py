"""The parts of a vehicle file: actuator dynamics, rotor geometry, effectors, axes and the
optional rigid-body linear model; each reads itself from its table and writes itself back."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from .fields import (EFFECTOR_KINDS, MAX_MODEL_SIZE, WRENCH_COMPONENTS, Matrix, _fail, _keys, _list, _matrix, _names, _positive, _real,
                     _reals, _table, _text, _weight)


# --------------------------------------------------------------------------- parts
@dataclass(frozen=True)
class Dynamics:
    """An actuator's linear dynamics (unit DC gain) and pure delay.

    At most one of the forms is given; none means a static actuator (with its ``delay``).
    """

    bandwidth: float | None = None
    time_constant: float | None = None
    wn: float | None = None
    zeta: float | None = None
    poles: tuple[float, float] | None = None
    delay: float = 0.0

    FIELDS = ("bandwidth", "time_constant", "wn", "zeta", "poles", "delay")

    @classmethod
    def from_dict(cls, data: Any, path: str) -> Dynamics:
        table = _table(data, path)
        _keys(table, path, cls.FIELDS)
        forms = [f for f in ("bandwidth", "time_constant", "wn", "poles") if f in table]
        if len(forms) > 1:
            raise _fail(f"{path}.{forms[1]}", f"give one of bandwidth, time_constant, wn/zeta, poles (also {forms[0]})")
        if ("wn" in table) != ("zeta" in table):
            raise _fail(f"{path}.{'zeta' if 'wn' in table else 'wn'}", "wn and zeta go together")
        kw: dict[str, Any] = {}
        for f in ("bandwidth", "time_constant", "wn"):
            if f in table:
                kw[f] = _positive(table[f], f"{path}.{f}")
        if "zeta" in table:
            kw["zeta"] = _positive(table["zeta"], f"{path}.zeta")
        if "poles" in table:
            a, b = _reals(table["poles"], f"{path}.poles", 2)
            for i, x in enumerate((a, b)):
                if not x > 0.0:
                    raise _fail(f"{path}.poles[{i}]", f"a stable real pole s = -a needs a > 0, got {x:g}")
            kw["poles"] = (a, b)
        if "delay" in table:
            d = _real(table["delay"], f"{path}.delay")
            if d < 0.0:
                raise _fail(f"{path}.delay", f"must be >= 0, got {d:g}")
            kw["delay"] = d
        return cls(**kw)

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {}
        for f in self.FIELDS:
            v = getattr(self, f)
            if v is not None and not (f == "delay" and v == 0.0):
                out[f] = list(v) if f == "poles" else v
        return out

    def transfer_function(self) -> tuple[tuple[float, ...], tuple[float, ...]]:
        """``(num, den)`` in descending powers of ``s``, without the delay (DC gain 1)."""
        if self.bandwidth is not None:
            return (self.bandwidth,), (1.0, self.bandwidth)
        if self.time_constant is not None:
            return (1.0,), (self.time_constant, 1.0)
        if self.wn is not None and self.zeta is not None:
            return (self.wn * self.wn,), (1.0, 2.0 * self.zeta * self.wn, self.wn * self.wn)
        if self.poles is not None:
            a, b = self.poles
            return (a * b,), (1.0, a + b, a * b)
        return (1.0,), (1.0,)


def rotor_wrench(position: Sequence[float], axis: Sequence[float], ct: float, km: float) -> np.ndarray:
    """A rotor's wrench per unit command: ``[roll, pitch, yaw, fx, fy, fz]`` moments and forces.

    PX4 ``src/modules/control_allocator/ActuatorEffectiveness/ActuatorEffectivenessRotors.cpp``,
    ``ActuatorEffectivenessRotors::computeEffectivenessMatrix`` (PX4/PX4-Autopilot commit
    25ab311a8229): the axis is normalised, then ``thrust = ct * a`` and ``moment = ct * (p x
    a) - ct * km * a``.  PX4 computes in float32 and skips a rotor with ``|a|`` or ``|ct|``
    below ``FLT_EPSILON`` (its column stays zero); here float64, same skips.
    """
    a = np.asarray(axis, dtype=float)
    p = np.asarray(position, dtype=float)
    norm = float(np.linalg.norm(a))
    out = np.zeros(6)
    eps = float(np.finfo(np.float32).eps)
    if not norm > eps or not abs(ct) >= eps:
        return out
    a = a / norm
    out[:3] = ct * np.cross(p, a) - ct * km * a
    out[3:] = ct * a
    return out


@dataclass(frozen=True)
class Rotor:
    """A rotor's geometry (PX4's ``CA_ROTORn_*`` parameters): position [m], thrust axis, CT, KM.

    ``ct``: thrust at full command (PX4: ``thrust = CT u^2`` with ``u`` the command; the
    effectiveness is linear in the command, as PX4's allocation is).  ``km``: moment per
    thrust, positive for a counter-clockwise rotor (PX4 ``CA_ROTORn_KM``).
    """

    position: tuple[float, float, float]
    axis: tuple[float, float, float] = (0.0, 0.0, -1.0)
    ct: float = 1.0
    km: float = 0.0

    FIELDS = ("position", "axis", "ct", "km")

    @classmethod
    def from_dict(cls, data: Any, path: str) -> Rotor:
        table = _table(data, path)
        _keys(table, path, cls.FIELDS, required=("position",))
        kw: dict[str, Any] = {"position": _reals(table["position"], f"{path}.position", 3)}
        if "axis" in table:
            ax = _reals(table["axis"], f"{path}.axis", 3)
            if not math.hypot(*ax) > float(np.finfo(np.float32).eps):
                raise _fail(f"{path}.axis", f"the thrust axis must be a non-zero vector, got {list(ax)}")
            kw["axis"] = ax
        if "ct" in table:
            kw["ct"] = _positive(table["ct"], f"{path}.ct")
        if "km" in table:
            kw["km"] = _real(table["km"], f"{path}.km")
        return cls(**kw)

    def to_dict(self) -> dict[str, Any]:
        return {"position": list(self.position), "axis": list(self.axis), "ct": self.ct, "km": self.km}

    def wrench(self) -> np.ndarray:
        """See :func:`rotor_wrench`."""
        return rotor_wrench(self.position, self.axis, self.ct, self.km)


@dataclass(frozen=True)
class Effector:
    """One effector: limits, rates, preference, weight, dynamics and (optionally) its column."""

    name: str
    min: float
    max: float
    kind: str = "other"
    unit: str = "1"
    rate_max: float | None = None
    rate_min: float | None = None
    preferred: float | None = None
    weight: float | None = None
    dynamics: Dynamics | None = None
    effectiveness: tuple[float, ...] | None = None
    rotor: Rotor | None = None
    description: str = ""

    FIELDS = ("name", "kind", "unit", "description", "min", "max", "rate_max", "rate_min", "preferred", "weight",
              "dynamics", "effectiveness", "rotor")

    @classmethod
    def from_dict(cls, data: Any, path: str, k: int) -> Effector:
        t = _table(data, path)
        _keys(t, path, cls.FIELDS, required=("name", "min", "max"))
        kw: dict[str, Any] = {"name": _text(t["name"], f"{path}.name", name=True)}
        if "kind" in t:
            kind = _text(t["kind"], f"{path}.kind")
            if kind not in EFFECTOR_KINDS:
                raise _fail(f"{path}.kind", f"unknown kind {kind!r}; one of {', '.join(EFFECTOR_KINDS)}")
            kw["kind"] = kind
        for f in ("unit", "description"):
            if f in t:
                kw[f] = _text(t[f], f"{path}.{f}")
        lo, hi = _real(t["min"], f"{path}.min"), _real(t["max"], f"{path}.max")
        if lo > hi:
            raise _fail(f"{path}.max", f"max = {hi:g} is below min = {lo:g}")
        kw["min"], kw["max"] = lo, hi
        if "rate_max" in t:
            kw["rate_max"] = _positive(t["rate_max"], f"{path}.rate_max")
        if "rate_min" in t:
            r = _real(t["rate_min"], f"{path}.rate_min")
            if not r < 0.0:
                raise _fail(f"{path}.rate_min", f"must be < 0, got {r:g}")
            kw["rate_min"] = r
        if "preferred" in t:
            p = _real(t["preferred"], f"{path}.preferred")
            if not lo <= p <= hi:
                raise _fail(f"{path}.preferred", f"{p:g} is outside [min, max] = [{lo:g}, {hi:g}]")
            kw["preferred"] = p
        if "weight" in t:
            kw["weight"] = _weight(t["weight"], f"{path}.weight")
        if "dynamics" in t:
            kw["dynamics"] = Dynamics.from_dict(t["dynamics"], f"{path}.dynamics")
        if "effectiveness" in t and "rotor" in t:
            raise _fail(f"{path}.rotor", "give the column (effectiveness) or the rotor geometry, not both")
        if "effectiveness" in t:
            kw["effectiveness"] = _reals(t["effectiveness"], f"{path}.effectiveness", k)
        if "rotor" in t:
            kw["rotor"] = Rotor.from_dict(t["rotor"], f"{path}.rotor")
        return cls(**kw)

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"name": self.name, "kind": self.kind, "unit": self.unit}
        if self.description:
            out["description"] = self.description
        out["min"], out["max"] = self.min, self.max
        for f in ("rate_max", "rate_min", "preferred", "weight"):
            if getattr(self, f) is not None:
                out[f] = getattr(self, f)
        if self.dynamics is not None:
            out["dynamics"] = self.dynamics.to_dict()
        if self.effectiveness is not None:
            out["effectiveness"] = list(self.effectiveness)
        if self.rotor is not None:
            out["rotor"] = self.rotor.to_dict()
        return out


@dataclass(frozen=True)
class Axis:
    """One virtual-control axis (a row of ``B``): name, unit, weight (``Wv``), wrench component, trim.

    ``trim`` is the axis's operating point (a hovering multicopter's thrust); the
    controllability report measures the attainable range along each axis through it.
    """

    name: str
    unit: str = "1"
    weight: float | None = None
    wrench: str | None = None
    trim: float = 0.0
    description: str = ""

    FIELDS = ("name", "unit", "description", "weight", "wrench", "trim")

    @classmethod
    def from_dict(cls, data: Any, path: str) -> Axis:
        t = _table(data, path)
        _keys(t, path, cls.FIELDS, required=("name",))
        kw: dict[str, Any] = {"name": _text(t["name"], f"{path}.name", name=True)}
        for f in ("unit", "description"):
            if f in t:
                kw[f] = _text(t[f], f"{path}.{f}")
        if "weight" in t:
            kw["weight"] = _weight(t["weight"], f"{path}.weight")
        if "wrench" in t:
            wr = _text(t["wrench"], f"{path}.wrench")
            if wr not in WRENCH_COMPONENTS:
                raise _fail(f"{path}.wrench", f"unknown component {wr!r}; one of {', '.join(WRENCH_COMPONENTS)}")
            kw["wrench"] = wr
        if "trim" in t:
            kw["trim"] = _real(t["trim"], f"{path}.trim")
        return cls(**kw)

    @property
    def component(self) -> str | None:
        """The wrench component this axis is: given, or its name when that is one."""
        if self.wrench is not None:
            return self.wrench
        low = self.name.lower()
        return low if low in WRENCH_COMPONENTS else None

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"name": self.name, "unit": self.unit}
        if self.description:
            out["description"] = self.description
        if self.weight is not None:
            out["weight"] = self.weight
        if self.wrench is not None:
            out["wrench"] = self.wrench
        if self.trim != 0.0:
            out["trim"] = self.trim
        return out


@dataclass(frozen=True)
class LinearModel:
    """The rigid-body linear model ``x' = A x + B u``, ``y = C x + D u`` (``u``: the vehicle's
    effectors, in order).  ``controlled`` names the outputs the axes control (for the simulator).
    """

    states: tuple[str, ...]
    outputs: tuple[str, ...]
    A: Matrix
    B: Matrix
    C: Matrix
    D: Matrix
    controlled: tuple[str, ...] = ()
    #: the outputs' units, in order (plots and tables label them); empty: not given
    units: tuple[str, ...] = ()

    FIELDS = ("states", "outputs", "units", "A", "B", "C", "D", "controlled")

    @classmethod
    def from_dict(cls, data: Any, path: str, m: int) -> LinearModel:
        t = _table(data, path)
        _keys(t, path, cls.FIELDS, required=("states", "outputs", "A", "B", "C"))
        states = _names(t["states"], f"{path}.states", high=MAX_MODEL_SIZE)
        outputs = _names(t["outputs"], f"{path}.outputs", high=MAX_MODEL_SIZE)
        n, p = len(states), len(outputs)
        if n < 1 or p < 1:
            raise _fail(f"{path}.{'states' if n < 1 else 'outputs'}", "at least one name required")
        A = _matrix(t["A"], f"{path}.A", n, n)
        B = _matrix(t["B"], f"{path}.B", n, m)
        C = _matrix(t["C"], f"{path}.C", p, n)
        D = _matrix(t["D"], f"{path}.D", p, m) if "D" in t else tuple((0.0,) * m for _ in range(p))
        controlled: tuple[str, ...] = ()
        if "controlled" in t:
            controlled = _names(t["controlled"], f"{path}.controlled")
            for i, name in enumerate(controlled):
                if name not in outputs:
                    raise _fail(f"{path}.controlled[{i}]", f"unknown output {name!r}; outputs: {', '.join(outputs)}")
        units: tuple[str, ...] = ()
        if "units" in t:
            units = tuple(_text(u, f"{path}.units[{i}]") for i, u in enumerate(_list(t["units"], f"{path}.units", p)))
        return cls(states, outputs, A, B, C, D, controlled, units)

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"states": list(self.states), "outputs": list(self.outputs)}
        if self.units:
            out["units"] = list(self.units)
        for f in ("A", "B", "C", "D"):
            out[f] = [list(r) for r in getattr(self, f)]
        if self.controlled:
            out["controlled"] = list(self.controlled)
        return out

    def arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``(A, B, C, D)`` as float arrays."""
        return tuple(np.array(getattr(self, f), dtype=float) for f in ("A", "B", "C", "D"))  # type: ignore[return-value]

    def to_statespace(self, inputs: Sequence[str] | None = None) -> Any:
        """A python-control ``StateSpace`` with named states, inputs and outputs.

        Needs the optional ``control`` package (``pip install control``).
        """
        try:
            import control
        except ImportError as exc:
            raise ImportError("LinearModel.to_statespace needs python-control: pip install control") from exc
        A, B, C, D = self.arrays()
        kw: dict[str, Any] = {"states": list(self.states), "outputs": list(self.outputs)}
        if inputs is not None:
            kw["inputs"] = list(inputs)
        return control.ss(A, B, C, D, **kw)

    @classmethod
    def from_statespace(cls, sys: Any, controlled: Sequence[str] = (), units: Sequence[str] = ()) -> LinearModel:
        """The model of a python-control ``StateSpace`` (its state and output names kept; a
        ``StateSpace`` has no units, so the outputs' ``units`` are given here if wanted)."""
        doc = {
            "states": list(getattr(sys, "state_labels", [f"x{i}" for i in range(sys.nstates)])),
            "outputs": list(getattr(sys, "output_labels", [f"y{i}" for i in range(sys.noutputs)])),
            "A": np.asarray(sys.A, dtype=float).tolist(), "B": np.asarray(sys.B, dtype=float).tolist(),
            "C": np.asarray(sys.C, dtype=float).tolist(), "D": np.asarray(sys.D, dtype=float).tolist(),
        }
        if controlled:
            doc["controlled"] = list(controlled)
        if units:
            doc["units"] = list(units)
        return cls.from_dict(doc, "model", int(np.asarray(sys.B).shape[1]))
