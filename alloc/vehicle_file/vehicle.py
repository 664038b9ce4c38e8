"""The vehicle: its parts assembled and checked against each other, its allocation problem,
its per-method defaults, and the document it reads from and writes to."""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from .._files import MAX_TEXT_BYTES, MAX_TOML_BYTES
from ..exceptions import AllocError, ProblemError
from ..problem import MAX_AXES, MAX_EFFECTORS, MAX_MAGNITUDE, Problem, short_repr
from .fields import FORMAT, FORMAT_SCHEDULE, FORMAT_SIMULATION, FORMATS, WRENCH_COMPONENTS, Matrix, _child, _fail, _keys, _kind, _list, _matrix, _table, _text, _unique
from .parts import Axis, Effector, LinearModel
from .schedule import Schedule, ScheduledEffectiveness
from .simulation import Simulation
from .toml_writer import to_toml


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
    #: the vehicle's own closed-loop design (format 1.1), flown instead of the section 4.3 auto-design
    simulation: Simulation | None = None
    #: ``B`` as a function of scheduling variables (format 1.2); ``B`` above is its value at the nominal point
    schedule: Schedule | None = None

    FIELDS = ("format", "name", "description", "source", "axes", "effectors", "effectiveness", "methods", "model",
              "simulation", "schedule")

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
        """The allocation problem: ``B``, limits, ``up``, rates, weights and names, validated.

        ``up`` is the effectors' ``preferred`` positions where any is declared; otherwise, when
        the axes declare a trim (a hovering multirotor's thrust), the trim command
        (:attr:`trim_command`), so that every method works about the operating point: the
        direction-keeping methods (``da``, ``da_facet``, ``da_bisect``, ``pinv_scale``) keep
        the demand's direction from it and never scale a multirotor's thrust toward the
        rotors-off corner of the attainable set, where ``up = 0`` lies.
        """
        problem = self._declared_problem()
        if any(e.preferred is not None for e in self.effectors) or not np.any(self.trim):
            return problem
        return problem.replace(up=self.trim_command)

    @property
    def trim_command(self) -> np.ndarray:
        """The effector command that meets the axes' trim, closest to the declared preferred
        positions (the default method, ``qp``: ``min |u - up|_Wu`` subject to ``B u = trim``);
        the closest attainable moment's command when the trim is beyond reach.  Zero trims give
        the declared ``up``.  Computed once per vehicle."""
        cached = self.__dict__.get("_trim_command")
        if cached is None:
            problem = self._declared_problem()
            if np.any(self.trim):
                from ..api import make_allocator
                from ..registry import DEFAULT_METHOD

                cached = np.array(make_allocator(problem, DEFAULT_METHOD)(self.trim).u, dtype=float)
            else:
                cached = np.array(problem.up, dtype=float)
            cached.setflags(write=False)
            object.__setattr__(self, "_trim_command", cached)  # frozen: a cache, not a field
        return cached

    def _declared_problem(self) -> Problem:
        """The problem exactly as the file declares it (``up`` from ``preferred`` or the default)."""
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

    def scheduled(self) -> ScheduledEffectiveness:
        """The evaluator of ``B(x)`` (:class:`~alloc.vehicle_file.schedule.ScheduledEffectiveness`); a vehicle
        without a ``[schedule]`` is refused naming ``schedule``."""
        if self.schedule is None:
            raise ProblemError(f"schedule: vehicle {self.name!r} declares no [schedule]; its B is constant",
                               field="schedule")
        return ScheduledEffectiveness(self.B, self.schedule)

    def problem_at(self, values: Mapping[str, float]) -> Problem:
        """The allocation problem with ``B`` at the scheduling variables' ``values`` (by name; an
        absent variable takes its nominal value); limits, rates, weights and ``up`` as :meth:`problem`.

        The evaluator and the nominal problem are made once per vehicle (a cache, as
        :attr:`trim_command`); each call evaluates ``B`` and validates one new Problem."""
        cached = self.__dict__.get("_schedule_cache")
        if cached is None:
            cached = (self.scheduled(), self.problem())
            object.__setattr__(self, "_schedule_cache", cached)  # frozen: a cache, not a field
        evaluator, nominal = cached
        return nominal.replace(B=evaluator.evaluate(values, out=np.empty((self.k, self.m))))

    def method_options(self, method: str) -> dict[str, Any]:
        """This vehicle's defaults for ``method`` (``{}`` when it has none): a fresh copy."""
        return json.loads(json.dumps(self.methods.get(method, {})))

    def to_dict(self) -> dict[str, Any]:
        """The document (JSON-able; ``vehicle_from_dict(v.to_dict()) == v``)."""
        fmt = FORMAT_SCHEDULE if self.schedule is not None else FORMAT if self.simulation is None else FORMAT_SIMULATION
        out: dict[str, Any] = {"format": fmt, "name": self.name}
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
        if self.simulation is not None:
            out["simulation"] = self.simulation.to_dict()
        if self.schedule is not None:
            out["schedule"] = self.schedule.to_dict()
        return out

    def method_table(self) -> dict[str, dict[str, Any]]:
        return {name: self.method_options(name) for name in self.methods}

    def save(self, path: str | Path) -> Path:
        """Write the vehicle as TOML (``.toml``) or JSON (``.json``), by the file's extension.

        A text longer than :func:`~alloc.vehicle_file.load_vehicle` reads is refused before
        writing: TOML over :data:`~alloc._files.MAX_TOML_BYTES` (128 KiB; save it as JSON), JSON
        over :data:`~alloc._files.MAX_TEXT_BYTES` (1 MiB).
        """
        path = Path(path)
        suffix = path.suffix.lower()
        if suffix == ".toml":
            text = to_toml(self.to_dict())
            size = len(text.encode("utf-8"))
            if size > MAX_TOML_BYTES:
                raise ProblemError(f"path: the vehicle is {size} bytes of TOML, more than the {MAX_TOML_BYTES} a "
                                   "vehicle file may hold; save it as .json", field="path")
        elif suffix == ".json":
            text = json.dumps(self.to_dict(), indent=1, allow_nan=False) + "\n"
            size = len(text.encode("utf-8"))
            if size > MAX_TEXT_BYTES:
                raise ProblemError(f"path: the vehicle is {size} bytes of JSON, more than the {MAX_TEXT_BYTES} a "
                                   "vehicle file may hold", field="path")
        else:
            raise ProblemError(f"path: unknown extension {path.suffix!r}; use .toml or .json", field="path")
        path.write_text(text, encoding="utf-8")
        return path


def vehicle_from_dict(doc: Any) -> Vehicle:
    """Validate a vehicle document (the parsed TOML/JSON); ProblemError naming the field path.

    Each list's length (axes, effectors, model states and outputs) is checked before its entries
    are read, and each field is read only as deep as the format goes, so a deep or cyclic value
    is refused at its field; a file's nesting is bounded when it is parsed (:mod:`alloc._files`).
    """
    t = _table(doc, "vehicle")
    _keys(t, "", Vehicle.FIELDS, required=("format", "name", "axes", "effectors"))
    fmt = t["format"]
    if fmt not in FORMATS:
        raise _fail("format", f"unsupported format {short_repr(fmt)}; this library reads {', '.join(map(repr, FORMATS))}")
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
    if "simulation" in t:
        if fmt == FORMAT:
            raise _fail("simulation", f"the [simulation] section needs format = {FORMAT_SIMULATION!r}")
        if model is None:
            raise _fail("simulation", "the [simulation] section flies the [model]; give the model")
        vehicle = replace(vehicle, simulation=Simulation.from_dict(
            t["simulation"], "simulation", outputs=model.outputs, channels=model.controlled,
            effectors=vehicle.effector_names, n=len(model.states),
            limits=tuple((float(lo), float(hi)) for lo, hi in zip(problem.umin, problem.umax, strict=True)),
            rate_limits=tuple((float(lo), float(hi)) for lo, hi in zip(problem.rate_min, problem.rate_max, strict=True))))
    if "schedule" in t:
        if fmt != FORMAT_SCHEDULE:
            raise _fail("schedule", f"the [schedule] section needs format = {FORMAT_SCHEDULE!r}")
        vehicle = replace(vehicle, schedule=Schedule.from_dict(t["schedule"], "schedule", k, m))
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
    from .. import registry
    from ..exceptions import UnknownMethodError
    from ..options import validate

    table = _table(value, "methods")
    out: dict[str, dict[str, Any]] = {}
    for method, options in table.items():
        path = _child("methods", method)
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
