"""Vehicle description files: format ``alloc-vehicle/1`` (TOML or JSON).

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

    [model]                       # optional rigid-body linear model x' = A x + B u, y = C x + D u
    states = [...]; outputs = [...]; A = [...]; B = [...]; C = [...]; D = [...]

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
"""

from __future__ import annotations

import json
import math
import re
import tomllib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from .exceptions import AllocError, ProblemError
from .problem import MAX_AXES, MAX_EFFECTORS, MAX_MAGNITUDE, Problem, short_repr

__all__ = [
    "FORMAT", "SCHEMA_PATH", "DATA_DIR", "EFFECTOR_KINDS", "WRENCH_COMPONENTS",
    "Dynamics", "Rotor", "Effector", "Axis", "LinearModel", "Vehicle",
    "load_vehicle", "vehicle_from_dict", "vehicle_from_problem", "vehicle_names", "rotor_wrench", "to_toml",
]

#: the format this module reads and writes (a later, incompatible format gets a new number)
FORMAT = "alloc-vehicle/1"
#: the published JSON Schema of the format
SCHEMA_PATH = Path(__file__).parent / "schemas" / "vehicle-1.schema.json"
#: the bundled vehicle files (the seed's aircraft): ``load_vehicle("ice")`` reads ``ice.toml`` here
DATA_DIR = Path(__file__).parent / "data" / "vehicles"
#: what an effector is; informative (plots, importers), no method branches on it
EFFECTOR_KINDS = ("surface", "rotor", "thrust-vector", "thruster", "other")
#: the body-axis wrench components a rotor's geometry yields, in PX4's order (moments, then forces)
WRENCH_COMPONENTS = ("roll", "pitch", "yaw", "fx", "fy", "fz")

_NAME = re.compile(r"^[^\x00-\x1f\x7f]{1,64}$")


# --------------------------------------------------------------------------- errors and readers
def _fail(path: str, message: str) -> ProblemError:
    return ProblemError(f"{path}: {message}", field=path)


def _table(value: Any, path: str) -> Mapping[str, Any]:
    if not isinstance(value, Mapping):
        raise _fail(path, f"expected a table (object), got {_kind(value)}")
    return value


def _kind(value: Any) -> str:
    if value is None:
        return "null"
    if isinstance(value, bool):
        return f"boolean {value!r}"
    if isinstance(value, str):
        return f"text {short_repr(value)}"
    if isinstance(value, Mapping):
        return "a table"
    if isinstance(value, (list, tuple)):
        return f"a list of {len(value)}"
    return f"{type(value).__name__} {short_repr(value)}"


def _keys(table: Mapping[str, Any], path: str, allowed: Sequence[str], required: Sequence[str] = ()) -> None:
    unknown = [k for k in table if k not in allowed]
    if unknown:
        where = f"{path}." if path else ""
        raise _fail(f"{where}{unknown[0]}", f"unknown field; accepted: {', '.join(allowed)}")
    for k in required:
        if k not in table:
            where = f"{path}." if path else ""
            raise _fail(f"{where}{k}", "required")


def _text(value: Any, path: str, *, name: bool = False) -> str:
    if not isinstance(value, str):
        raise _fail(path, f"expected text, got {_kind(value)}")
    try:
        value.encode("utf-8")
    except UnicodeEncodeError:
        raise _fail(path, "not valid Unicode text (lone surrogate)") from None
    if name and not _NAME.match(value):
        raise _fail(path, f"a name must be 1-64 characters without control characters, got {short_repr(value)}")
    return value


def _real(value: Any, path: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise _fail(path, f"expected a number, got {_kind(value)}")
    try:
        x = float(value)
    except OverflowError:
        raise _fail(path, f"{short_repr(value)} is too large (|x| <= {MAX_MAGNITUDE:g})") from None
    if not abs(x) <= MAX_MAGNITUDE:
        what = "must be finite" if not math.isfinite(x) else f"|x| must be <= {MAX_MAGNITUDE:g}"
        raise _fail(path, f"{what}, got {short_repr(value)}")
    return x


def _positive(value: Any, path: str) -> float:
    x = _real(value, path)
    if not x > 0.0:
        raise _fail(path, f"must be > 0, got {x:g}")
    return x


def _weight(value: Any, path: str) -> float:
    """A diagonal weight entry: positive and inside the weight domain (>= 1 / MAX_MAGNITUDE)."""
    w = _positive(value, path)
    if w < 1.0 / MAX_MAGNITUDE:
        raise _fail(path, f"must be >= {1.0 / MAX_MAGNITUDE:g}, got {w:g}")
    return w


def _list(value: Any, path: str, n: int | None = None, *, low: int = 0, high: int | None = None) -> list[Any]:
    if not isinstance(value, (list, tuple)):
        raise _fail(path, f"expected a list, got {_kind(value)}")
    if n is not None and len(value) != n:
        raise _fail(path, f"expected {n} entries, got {len(value)}")
    if len(value) < low:
        raise _fail(path, f"expected at least {low} entries, got {len(value)}")
    if high is not None and len(value) > high:
        raise _fail(path, f"expected at most {high} entries, got {len(value)}")
    return list(value)


def _reals(value: Any, path: str, n: int | None = None) -> tuple[float, ...]:
    return tuple(_real(x, f"{path}[{i}]") for i, x in enumerate(_list(value, path, n)))


def _matrix(value: Any, path: str, rows: int | None, cols: int | None) -> tuple[tuple[float, ...], ...]:
    out = []
    for i, row in enumerate(_list(value, path, rows)):
        out.append(_reals(row, f"{path}[{i}]", cols))
        if cols is None:
            cols = len(out[0])
    return tuple(out)


def _names(value: Any, path: str, n: int | None = None) -> tuple[str, ...]:
    names = tuple(_text(x, f"{path}[{i}]", name=True) for i, x in enumerate(_list(value, path, n)))
    _unique(names, path)
    return names


def _unique(names: Sequence[str], path: str) -> None:
    seen: dict[str, int] = {}
    for i, s in enumerate(names):
        if s in seen:
            raise _fail(f"{path}[{i}]", f"duplicate name {s!r} (also at index {seen[s]})")
        seen[s] = i


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


Matrix = tuple[tuple[float, ...], ...]


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

    FIELDS = ("states", "outputs", "A", "B", "C", "D", "controlled")

    @classmethod
    def from_dict(cls, data: Any, path: str, m: int) -> LinearModel:
        t = _table(data, path)
        _keys(t, path, cls.FIELDS, required=("states", "outputs", "A", "B", "C"))
        states = _names(t["states"], f"{path}.states")
        outputs = _names(t["outputs"], f"{path}.outputs")
        n, p = len(states), len(outputs)
        if n < 1 or p < 1:
            raise _fail(f"{path}.{'states' if n < 1 else 'outputs'}", "at least one name required")
        A = _matrix(t["A"], f"{path}.A", n, n)
        B = _matrix(t["B"], f"{path}.B", n, m)
        C = _matrix(t["C"], f"{path}.C", p, n)
        D = _matrix(t["D"], f"{path}.D", p, m) if "D" in t else tuple((0.0,) * m for _ in range(p))
        controlled = ()
        if "controlled" in t:
            controlled = _names(t["controlled"], f"{path}.controlled")
            for i, name in enumerate(controlled):
                if name not in outputs:
                    raise _fail(f"{path}.controlled[{i}]", f"unknown output {name!r}; outputs: {', '.join(outputs)}")
        return cls(states, outputs, A, B, C, D, controlled)

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"states": list(self.states), "outputs": list(self.outputs)}
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
    def from_statespace(cls, sys: Any, controlled: Sequence[str] = ()) -> LinearModel:
        """The model of a python-control ``StateSpace`` (its state and output names kept)."""
        doc = {
            "states": list(getattr(sys, "state_labels", [f"x{i}" for i in range(sys.nstates)])),
            "outputs": list(getattr(sys, "output_labels", [f"y{i}" for i in range(sys.noutputs)])),
            "A": np.asarray(sys.A, dtype=float).tolist(), "B": np.asarray(sys.B, dtype=float).tolist(),
            "C": np.asarray(sys.C, dtype=float).tolist(), "D": np.asarray(sys.D, dtype=float).tolist(),
        }
        if controlled:
            doc["controlled"] = list(controlled)
        return cls.from_dict(doc, "model", int(np.asarray(sys.B).shape[1]))


# --------------------------------------------------------------------------- the vehicle
@dataclass(frozen=True)
class Vehicle:
    """A vehicle read from a file (or built): its effectors, axes, effectiveness and defaults.

    ``B`` is the effectiveness (rows: axes, columns: effectors), given or computed from
    the effectors' columns and rotor geometry; ``B_given`` says whether the file gave the
    matrix itself (``[effectiveness] B``), so :meth:`to_dict` writes it back the same way.
    """

    name: str
    axes: tuple[Axis, ...]
    effectors: tuple[Effector, ...]
    B: Matrix
    B_given: bool = True
    description: str = ""
    source: str = ""
    methods: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)
    model: LinearModel | None = None

    FIELDS = ("format", "name", "description", "source", "axes", "effectors", "effectiveness", "methods", "model")

    @property
    def k(self) -> int:
        return len(self.axes)

    @property
    def m(self) -> int:
        return len(self.effectors)

    @property
    def effector_names(self) -> tuple[str, ...]:
        return tuple(e.name for e in self.effectors)

    @property
    def axis_names(self) -> tuple[str, ...]:
        return tuple(a.name for a in self.axes)

    @property
    def trim(self) -> np.ndarray:
        """The axes' operating point (``Axis.trim``)."""
        return np.array([a.trim for a in self.axes], dtype=float)

    def problem(self) -> Problem:
        """The allocation problem: ``B``, limits, ``up``, rates, weights and names, validated."""
        eff = self.effectors
        rate_max = [math.inf if e.rate_max is None else e.rate_max for e in eff]
        rate_min = [(-math.inf if e.rate_max is None else -e.rate_max) if e.rate_min is None else e.rate_min
                    for e in eff]
        up = None
        if any(e.preferred is not None for e in eff):
            up = [min(max(0.0, e.min), e.max) if e.preferred is None else e.preferred for e in eff]
        Wu = None if all(e.weight is None for e in eff) else [1.0 if e.weight is None else e.weight for e in eff]
        Wv = None if all(a.weight is None for a in self.axes) else [1.0 if a.weight is None else a.weight
                                                                     for a in self.axes]
        return Problem(
            np.array(self.B, dtype=float), [e.min for e in eff], [e.max for e in eff], up=up, Wu=Wu, Wv=Wv,
            rate_min=rate_min, rate_max=rate_max, names=self.effector_names, axes=self.axis_names,
        )

    def method_options(self, method: str) -> dict[str, Any]:
        """This vehicle's defaults for ``method`` (``{}`` when it has none): a fresh copy."""
        return json.loads(json.dumps(self.methods.get(method, {})))

    def to_dict(self) -> dict[str, Any]:
        """The document (JSON-able; ``vehicle_from_dict(v.to_dict()) == v``)."""
        out: dict[str, Any] = {"format": FORMAT, "name": self.name}
        if self.description:
            out["description"] = self.description
        if self.source:
            out["source"] = self.source
        out["axes"] = [a.to_dict() for a in self.axes]
        out["effectors"] = [e.to_dict() for e in self.effectors]
        if self.B_given:
            out["effectiveness"] = {"B": [list(r) for r in self.B]}
        if self.methods:
            out["methods"] = self.method_table()
        if self.model is not None:
            out["model"] = self.model.to_dict()
        return out

    def method_table(self) -> dict[str, dict[str, Any]]:
        return {name: self.method_options(name) for name in self.methods}

    def save(self, path: str | Path) -> Path:
        """Write the vehicle as TOML (``.toml``) or JSON (``.json``), by the file's extension."""
        path = Path(path)
        suffix = path.suffix.lower()
        if suffix == ".toml":
            text = to_toml(self.to_dict())
        elif suffix == ".json":
            text = json.dumps(self.to_dict(), indent=1, allow_nan=False) + "\n"
        else:
            raise ProblemError(f"path: unknown extension {path.suffix!r}; use .toml or .json", field="path")
        path.write_text(text, encoding="utf-8")
        return path


def vehicle_from_dict(doc: Any) -> Vehicle:
    """Validate a vehicle document (the parsed TOML/JSON); ProblemError naming the field path."""
    t = _table(doc, "vehicle")
    _keys(t, "", Vehicle.FIELDS, required=("format", "name", "axes", "effectors"))
    fmt = t["format"]
    if fmt != FORMAT:
        raise _fail("format", f"unsupported format {short_repr(fmt)}; this library reads {FORMAT!r}")
    name = _text(t["name"], "name", name=True)
    description = _text(t.get("description", ""), "description")
    source = _text(t.get("source", ""), "source")
    axes = tuple(Axis.from_dict(a, f"axes[{i}]") for i, a in
                 enumerate(_list(t["axes"], "axes", low=1, high=MAX_AXES)))
    _unique([a.name for a in axes], "axes")
    k = len(axes)
    effectors = tuple(Effector.from_dict(e, f"effectors[{j}]", k) for j, e in
                      enumerate(_list(t["effectors"], "effectors", low=1, high=MAX_EFFECTORS)))
    _unique([e.name for e in effectors], "effectors")
    m = len(effectors)
    B, given = _effectiveness(t, axes, effectors)
    model = LinearModel.from_dict(t["model"], "model", m) if "model" in t else None
    vehicle = Vehicle(name=name, axes=axes, effectors=effectors, B=B, B_given=given, description=description,
                      source=source, model=model)
    try:
        problem = vehicle.problem()
    except ProblemError as exc:  # the per-field checks above should leave nothing; say where if they do
        raise _fail(exc.field or "vehicle", str(exc)) from exc
    if "methods" in t:
        vehicle = replace(vehicle, methods=_methods(t["methods"], problem))
    return vehicle


def vehicle_from_problem(problem: Problem, name: str, *, methods: Mapping[str, Mapping[str, Any]] | None = None,
                         description: str = "", source: str = "") -> Vehicle:
    """The vehicle of an allocation problem (``vehicle_from_problem(p, n).problem()`` equals ``p``).

    A vehicle file carries diagonal weights only: a problem whose ``Wu`` or ``Wv`` has
    off-diagonal entries raises ProblemError naming it.
    """
    if not isinstance(problem, Problem):
        raise ProblemError(f"problem: expected an alloc.Problem, got {type(problem).__name__}", field="problem")
    for label, W in (("Wu", problem.Wu), ("Wv", problem.Wv)):
        if not np.array_equal(W, np.diag(np.diag(W))):
            raise ProblemError(f"{label}: a vehicle file carries diagonal weights only", field=label)
    weighted_u = not np.array_equal(problem.Wu, np.eye(problem.m))
    weighted_v = not np.array_equal(problem.Wv, np.eye(problem.k))
    default_up = np.minimum(np.maximum(0.0, problem.umin), problem.umax)
    effectors = []
    for j, label in enumerate(problem.names):
        e: dict[str, Any] = {"name": label, "min": float(problem.umin[j]), "max": float(problem.umax[j])}
        rmin, rmax = float(problem.rate_min[j]), float(problem.rate_max[j])
        if math.isfinite(rmax):
            e["rate_max"] = rmax
        if math.isfinite(rmin) and rmin != -rmax:
            e["rate_min"] = rmin
        elif math.isinf(rmin) and math.isfinite(rmax):
            raise ProblemError(f"rate_min: effector {label!r} has rate_max {rmax:g} and no rate_min; a vehicle file "
                               "reads a missing rate_min as -rate_max", field="rate_min")
        if problem.up[j] != default_up[j]:
            e["preferred"] = float(problem.up[j])
        if weighted_u:
            e["weight"] = float(problem.Wu[j, j])
        effectors.append(e)
    axes = [{"name": a, **({"weight": float(problem.Wv[i, i])} if weighted_v else {})}
            for i, a in enumerate(problem.axes)]
    doc: dict[str, Any] = {"format": FORMAT, "name": name, "description": description, "source": source,
                           "axes": axes, "effectors": effectors, "effectiveness": {"B": problem.B.tolist()}}
    if methods:
        doc["methods"] = {k: dict(v) for k, v in methods.items()}
    return vehicle_from_dict(doc)


def _effectiveness(t: Mapping[str, Any], axes: tuple[Axis, ...], effectors: tuple[Effector, ...]) -> tuple[Matrix, bool]:
    k, m = len(axes), len(effectors)
    per_effector = [j for j, e in enumerate(effectors) if e.effectiveness is not None or e.rotor is not None]
    if "effectiveness" in t:
        table = _table(t["effectiveness"], "effectiveness")
        _keys(table, "effectiveness", ("B",), required=("B",))
        if per_effector:
            j = per_effector[0]
            what = "effectiveness" if effectors[j].effectiveness is not None else "rotor"
            raise _fail(f"effectors[{j}].{what}", "the matrix is given in [effectiveness] B; give one or the other")
        return _matrix(table["B"], "effectiveness.B", k, m), True
    if len(per_effector) < m:
        j = next(j for j in range(m) if j not in per_effector)
        raise _fail(f"effectors[{j}].effectiveness",
                    "required: give [effectiveness] B, or each effector's effectiveness (its column) or rotor")
    rows = {a.component: i for i, a in enumerate(axes) if a.component is not None}
    B = np.zeros((k, m))
    for j, e in enumerate(effectors):
        if e.effectiveness is not None:
            B[:, j] = e.effectiveness
            continue
        assert e.rotor is not None
        missing = [i for i, a in enumerate(axes) if a.component is None]
        if missing:
            raise _fail(f"axes[{missing[0]}].wrench", "required to compute rotor columns: one of "
                        + ", ".join(WRENCH_COMPONENTS))
        w = e.rotor.wrench()
        for comp, i in rows.items():
            B[i, j] = w[WRENCH_COMPONENTS.index(comp)]
        if not np.all(np.abs(B[:, j]) <= MAX_MAGNITUDE):
            raise _fail(f"effectors[{j}].rotor", f"the computed column exceeds |x| <= {MAX_MAGNITUDE:g}")
    return tuple(tuple(float(x) for x in row) for row in B), False


def _methods(value: Any, problem: Problem) -> dict[str, dict[str, Any]]:
    """``[methods.<name>]`` tables: each a registered method, each option declared and admissible.

    Options that depend on the problem are checked against it: effector groups name
    effectors, a priority list has one level per axis, and a method given a group or
    matrix option (``daisy``, ``ganging``: closed-form builds) is built once.
    """
    from . import registry
    from .exceptions import UnknownMethodError
    from .options import validate

    table = _table(value, "methods")
    out: dict[str, dict[str, Any]] = {}
    for method, options in table.items():
        path = f"methods.{method}"
        try:
            cls = registry.get_method(method)
        except UnknownMethodError as exc:
            raise _fail(path, str(exc)) from None
        opts = dict(_table(options, path))
        try:
            validate(method, cls.options, opts)
        except AllocError as exc:
            where = f"{path}.{exc.field}" if exc.field in opts else path
            raise _fail(where, str(exc)) from None
        kinds = {opt: cls.options[opt].type for opt in opts}
        for opt, kind in kinds.items():
            if kind == "groups" and opts[opt] is not None:
                _check_groups(opts[opt], f"{path}.{opt}", list(problem.names))
            elif kind == "real list" and opts[opt] is not None and len(opts[opt]) != problem.k:
                raise _fail(f"{path}.{opt}", f"expected {problem.k} entries (one per axis), got {len(opts[opt])}")
        if any(kind in ("groups", "matrix") for kind in kinds.values()):
            try:
                registry.build(problem, method, opts)
            except AllocError as exc:
                where = f"{path}.{exc.field}" if exc.field in opts else path
                raise _fail(where, str(exc)) from None
        try:
            out[method] = json.loads(json.dumps(opts, allow_nan=False))
        except ValueError:
            raise _fail(path, "option values must be finite (a file must read back from JSON too)") from None
    return out


def _check_groups(groups: Any, path: str, names: list[str]) -> None:
    for g, group in enumerate(_list(groups, path)):
        for i, member in enumerate(_list(group, f"{path}[{g}]")):
            if isinstance(member, str):
                if member not in names:
                    raise _fail(f"{path}[{g}][{i}]", f"unknown effector {member!r}")
            elif (isinstance(member, int) and not isinstance(member, bool)) or (
                    isinstance(member, float) and member.is_integer()):
                if not 0 <= member < len(names):
                    raise _fail(f"{path}[{g}][{i}]", f"effector index {member} out of range 0..{len(names) - 1}")
            else:
                raise _fail(f"{path}[{g}][{i}]", f"expected an effector name or index, got {_kind(member)}")


# --------------------------------------------------------------------------- reading
def vehicle_names() -> list[str]:
    """The bundled vehicle files' names (``load_vehicle(name)`` reads one)."""
    return sorted(p.stem for p in DATA_DIR.glob("*.toml"))


def load_vehicle(source: str | Path | Mapping[str, Any]) -> Vehicle:
    """Read a vehicle: a file (``.toml``, ``.json``, PX4 ``.params``), a document, or a bundled name.

    A bare name without an extension that is not a file (``"ice"``) is a bundled vehicle
    file (:func:`vehicle_names`).  PX4 parameter files go through
    :func:`alloc.importers.px4.vehicle_from_params` with its defaults.

    Raises
    ------
    ProblemError
        naming the field path of the first problem (``effectors[3].rate_max: ...``), or
        ``path`` for an unreadable or unknown file.
    """
    if isinstance(source, Mapping):
        return vehicle_from_dict(source)
    if not isinstance(source, (str, Path)):
        raise ProblemError(f"source: expected a path, a bundled name or a document, got {type(source).__name__}",
                           field="source")
    path = Path(source)
    if not path.exists() and isinstance(source, str) and path.suffix == "" and "/" not in source:
        bundled = DATA_DIR / f"{source}.toml"
        if not bundled.exists():
            raise ProblemError(f"path: no file {source!r} and no bundled vehicle of that name; bundled: "
                               f"{', '.join(vehicle_names())}", field="path")
        path = bundled
    suffix = path.suffix.lower()
    if suffix == ".params":
        from .importers.px4 import read_params, vehicle_from_params

        return vehicle_from_params(read_params(path), name=path.stem)
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise ProblemError(f"path: cannot read {str(path)!r} ({exc.strerror})", field="path") from exc
    try:
        text = raw.decode("utf-8")
        if suffix == ".toml":
            doc = tomllib.loads(text)
        elif suffix == ".json":
            doc = json.loads(text)
        else:
            raise ProblemError(f"path: unknown extension {path.suffix!r}; use .toml, .json or .params", field="path")
    except UnicodeDecodeError as exc:
        raise ProblemError(f"path: {path.name} is not UTF-8 text ({exc.reason} at byte {exc.start})",
                           field="path") from None
    except tomllib.TOMLDecodeError as exc:
        raise ProblemError(f"path: {path.name} is not valid TOML ({exc})", field="path") from None
    except json.JSONDecodeError as exc:
        raise ProblemError(f"path: {path.name} is not valid JSON ({exc})", field="path") from None
    return vehicle_from_dict(doc)


# --------------------------------------------------------------------------- writing TOML
_BARE_KEY = re.compile(r"^[A-Za-z0-9_-]+$")


def _key(k: str) -> str:
    return k if _BARE_KEY.match(k) else _string(k)


def _string(s: str) -> str:
    return json.dumps(s, ensure_ascii=False).replace("\x7f", "\\u007f")


def _value(v: Any, indent: str = "") -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, str):
        return _string(v)
    if isinstance(v, Mapping):
        return "{ " + ", ".join(f"{_key(k)} = {_value(x)}" for k, x in v.items()) + " }" if v else "{}"
    if isinstance(v, (list, tuple)):
        if v and all(isinstance(x, (list, tuple)) for x in v):  # a matrix: one row a line
            inner = indent + "  "
            return "[\n" + "".join(f"{inner}{_value(x, inner)},\n" for x in v) + indent + "]"
        return "[" + ", ".join(_value(x, indent) for x in v) + "]"
    raise TypeError(f"cannot write {type(v).__name__} as TOML")


def _is_table(v: Any) -> bool:
    return isinstance(v, Mapping)


def _is_table_array(v: Any) -> bool:
    return isinstance(v, (list, tuple)) and bool(v) and all(isinstance(x, Mapping) for x in v)


def to_toml(doc: Mapping[str, Any]) -> str:
    """A document of tables, arrays of tables, strings, numbers, booleans and lists as TOML.

    Floats are written with ``repr`` so they read back bit for bit; ``None`` values are left
    out (TOML has no null).
    """
    lines: list[str] = []
    _emit(lines, [], doc)
    return "\n".join(lines).strip("\n") + "\n"


def _emit(lines: list[str], path: list[str], table: Mapping[str, Any]) -> None:
    for k, v in table.items():
        if v is None or _is_table(v) or _is_table_array(v):
            continue
        lines.append(f"{_key(k)} = {_value(v)}")
    for k, v in table.items():
        if _is_table_array(v):
            for item in v:
                lines.append("")
                lines.append(f"[[{'.'.join(_key(p) for p in (*path, k))}]]")
                for ik, iv in item.items():
                    if iv is not None:
                        lines.append(f"{_key(ik)} = {_value(iv)}")
    for k, v in table.items():
        if _is_table(v):
            only_tables = bool(v) and all(_is_table(x) for x in v.values())
            if not only_tables:  # a header with nothing under it but sub-tables is implied by theirs
                lines.append("")
                lines.append(f"[{'.'.join(_key(p) for p in (*path, k))}]")
            _emit(lines, [*path, k], v)
