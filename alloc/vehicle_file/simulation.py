"""The ``[simulation]`` section (format ``alloc-vehicle/1.1``): a vehicle's own closed-loop design.

A vehicle file with a ``[model]`` flies the seed's section 4.3 design computed from the
model (:mod:`sim.autodesign`).  An aircraft whose designer published the loop -- the seed's
ICE (section 4.7) and F-18/HARV lat-dir (section 4.6) -- carries it instead, as data, so that
the file flies exactly that loop::

    [simulation]
    scenario = "ice"                # the name runs are recorded under (default: the vehicle's)
    duration = 40.0                 # default run length, s
    method = "pinv"                 # default allocator
    measured = ["vel", ...]         # model outputs fed to the observers (default: all)
    noise = [0.1414, ...]           # sensor-noise gain per measured output
    output_bound = [45.0, 200.0, 30.0]   # divergence bound per channel (model.controlled)
    references = [{ num = [100.0], den = [1.0, 20.0, 100.0] }, ...]   # reference model per channel
    commands = [{ sines = { xi = 5.0 } }, {}, {}]   # direct command per channel ({}: none)

    [simulation.allocation]         # what the loop's allocator is given (may differ from the
    B = [[...]]                     # file's effectiveness: the seed's design removes the spoilers
    weights = [2.0, 2.0, 1.0, ...]  # from the pitch channel and weights the elevons)
    static = [[...]]                # the seed's printed distribution matrix (m x channels)
    demand_map = [[...]]            # pseudo-commands -> allocator demands (default identity)

    [simulation.smc]                # seed Eqs 3.5-3.18: one entry per channel
    rho = [...]; eps = [...]; K0 = [...]; Km1 = [...]; hedge_gain = [...]
    observer_poles = [[...], ...]
    hedge = [{ out = "alphaw", inp = "alphaw", a_f = 10.0, a_h = 4.0, b_h = 4.0 }, ...]

    [simulation.loopshape]          # the linear baseline, one compensator per channel
    compensators = [{ num = [...], den = [...] }, ...]

    [simulation.pilot]              # a compensatory pilot on one channel
    name = "phi"; channel = "ps"; attitude = { phi = 1.0 }; integrate = false
    element = { num = [...], den = [...] }      # stick to attitude (the crossover rule's plant)
    commands = { sines = { sines = { xi = 10.0, phase_step = 0.785... } } }   # by name, first the default

    [simulation.failures.seed]      # named failures: plant matrices after the failure, delay, effectors
    time = 20.0; A = [[...]]; B = [[...]]; D = [[...]]; delay = 0.05
    actuators = [{ effector = "de3", kind = "limits", lo = -15.0, hi = 15.0 }, ...]

A command is a sum of sines (``sines = {xi, phase_step}``: seed Table 4-2, Eq 4.13) or a
filtered step sequence (``steps = {times, levels, filter = {num, den}}``).  Hedge paths may
carry a ``group``: the run option ``<group>_hedge = false`` drops that group (HARV's
``cross_hedge``).  Everything is validated here, with the field's path; :mod:`sim.user_vehicle`
turns it into the simulator's objects.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from ..domain import MAX_EFFECTORS
from .fields import Matrix, _fail, _keys, _list, _matrix, _names, _positive, _real, _reals, _table, _text

#: the most named failures a ``[simulation.failures]`` table may hold, counted before any is read
#: (41,000 of them, a 0.9 MB JSON file, took 0.5 s to read; the bundled HARV carries 3)
MAX_FAILURES = 64

__all__ = ["TransferFunction", "Command", "HedgePath", "SlidingMode", "PilotSpec", "FailureSpec",
           "AllocationSpec", "Simulation"]


def _bool(value: Any, path: str) -> bool:
    if not isinstance(value, bool):
        raise _fail(path, f"expected true or false, got {type(value).__name__}")
    return value


@dataclass(frozen=True)
class TransferFunction:
    """``num(s) / den(s)``, coefficients in descending powers of ``s``."""

    num: tuple[float, ...]
    den: tuple[float, ...]

    @classmethod
    def from_dict(cls, data: Any, path: str) -> TransferFunction:
        t = _table(data, path)
        _keys(t, path, ("num", "den"), required=("num", "den"))
        num = _reals(t["num"], f"{path}.num")
        den = _reals(t["den"], f"{path}.den")
        if not num:
            raise _fail(f"{path}.num", "at least one coefficient required")
        if not den or den[0] == 0.0:
            raise _fail(f"{path}.den", "the leading coefficient must be non-zero")
        if len(num) > len(den):
            raise _fail(f"{path}.num", f"improper: {len(num)} coefficients over a denominator of {len(den)}")
        return cls(num, den)

    def to_dict(self) -> dict[str, Any]:
        return {"num": list(self.num), "den": list(self.den)}

    def pair(self) -> tuple[list[float], list[float]]:
        return list(self.num), list(self.den)


@dataclass(frozen=True)
class Command:
    """A command signal: a sum of sines (``xi``, ``phase_step``) or filtered steps."""

    xi: float | None = None
    phase_step: float = 0.0
    times: tuple[float, ...] = ()
    levels: tuple[float, ...] = ()
    filter: TransferFunction | None = None

    @classmethod
    def from_dict(cls, data: Any, path: str) -> Command:
        t = _table(data, path)
        _keys(t, path, ("sines", "steps"))
        if len(t) != 1:
            raise _fail(path, "give one of sines = {xi, phase_step} or steps = {times, levels, filter}")
        if "sines" in t:
            s = _table(t["sines"], f"{path}.sines")
            _keys(s, f"{path}.sines", ("xi", "phase_step"), required=("xi",))
            return cls(xi=_real(s["xi"], f"{path}.sines.xi"),
                       phase_step=_real(s.get("phase_step", 0.0), f"{path}.sines.phase_step"))
        s = _table(t["steps"], f"{path}.steps")
        where = f"{path}.steps"
        _keys(s, where, ("times", "levels", "filter"), required=("times", "levels", "filter"))
        times = _reals(s["times"], f"{where}.times")
        levels = _reals(s["levels"], f"{where}.levels", len(times))
        if any(b <= a for a, b in zip(times, times[1:])):
            raise _fail(f"{where}.times", "must increase")
        return cls(times=times, levels=levels, filter=TransferFunction.from_dict(s["filter"], f"{where}.filter"))

    def to_dict(self) -> dict[str, Any]:
        if self.filter is None:
            return {"sines": {"xi": self.xi, "phase_step": self.phase_step}}
        return {"steps": {"times": list(self.times), "levels": list(self.levels), "filter": self.filter.to_dict()}}


@dataclass(frozen=True)
class HedgePath:
    """One simplified hedge path (seed Eqs 3.17-3.18): into channel ``out`` from pseudo-command ``inp``."""

    out: str
    inp: str
    a_f: float
    a_h: float
    b_h: float
    gain: float = 1.0
    group: str = ""

    FIELDS = ("out", "inp", "a_f", "a_h", "b_h", "gain", "group")

    @classmethod
    def from_dict(cls, data: Any, path: str, channels: tuple[str, ...]) -> HedgePath:
        t = _table(data, path)
        _keys(t, path, cls.FIELDS, required=("out", "inp", "a_f", "a_h", "b_h"))
        ends = {}
        for end in ("out", "inp"):
            name = _text(t[end], f"{path}.{end}")
            if name not in channels:
                raise _fail(f"{path}.{end}", f"unknown channel {name!r}; channels: {', '.join(channels)}")
            ends[end] = name
        group = _text(t.get("group", ""), f"{path}.group")
        if group and not group.isidentifier():
            raise _fail(f"{path}.group", f"a group is a word (it names the run option <group>_hedge), got {group!r}")
        return cls(ends["out"], ends["inp"], _real(t["a_f"], f"{path}.a_f"), _real(t["a_h"], f"{path}.a_h"),
                   _real(t["b_h"], f"{path}.b_h"), _real(t.get("gain", 1.0), f"{path}.gain"), group)

    def to_dict(self) -> dict[str, Any]:
        out = {f: getattr(self, f) for f in self.FIELDS[:6]}
        if self.group:
            out["group"] = self.group
        return out


@dataclass(frozen=True)
class SlidingMode:
    """The sliding-mode design, per channel (seed Eqs 3.5-3.18)."""

    rho: tuple[float, ...]
    eps: tuple[float, ...]
    K0: tuple[float, ...]
    Km1: tuple[float, ...]
    observer_poles: tuple[tuple[float, ...], ...] | None = None
    hedge: tuple[HedgePath, ...] = ()
    hedge_gain: tuple[float, ...] | None = None

    FIELDS = ("rho", "eps", "K0", "Km1", "observer_poles", "hedge", "hedge_gain")

    @classmethod
    def from_dict(cls, data: Any, path: str, channels: tuple[str, ...]) -> SlidingMode:
        t = _table(data, path)
        k = len(channels)
        _keys(t, path, cls.FIELDS, required=("rho", "eps", "K0", "Km1"))
        kw: dict[str, Any] = {f: tuple(_positive(x, f"{path}.{f}[{i}]") for i, x in
                                       enumerate(_list(t[f], f"{path}.{f}", k))) for f in ("rho", "eps", "K0")}
        kw["Km1"] = _reals(t["Km1"], f"{path}.Km1", k)
        if "observer_poles" in t:
            rows = _list(t["observer_poles"], f"{path}.observer_poles", k)
            poles = tuple(_reals(r, f"{path}.observer_poles[{i}]") for i, r in enumerate(rows))
            for i, row in enumerate(poles):
                if not row or any(p >= 0.0 for p in row):
                    raise _fail(f"{path}.observer_poles[{i}]", "stable real poles (< 0), at least one")
            kw["observer_poles"] = poles
        if "hedge" in t:
            kw["hedge"] = tuple(HedgePath.from_dict(h, f"{path}.hedge[{i}]", channels)
                                for i, h in enumerate(_list(t["hedge"], f"{path}.hedge")))
        if "hedge_gain" in t:
            kw["hedge_gain"] = _reals(t["hedge_gain"], f"{path}.hedge_gain", k)
        return cls(**kw)

    @property
    def hedge_groups(self) -> tuple[str, ...]:
        return tuple(dict.fromkeys(h.group for h in self.hedge if h.group))

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {f: list(getattr(self, f)) for f in ("rho", "eps", "K0", "Km1")}
        if self.observer_poles is not None:
            out["observer_poles"] = [list(r) for r in self.observer_poles]
        if self.hedge:
            out["hedge"] = [h.to_dict() for h in self.hedge]
        if self.hedge_gain is not None:
            out["hedge_gain"] = list(self.hedge_gain)
        return out


@dataclass(frozen=True)
class PilotSpec:
    """A compensatory pilot flying ``channel``: attitude ``name = sum(weight * output)`` (integrated
    if ``integrate``) against one of its named attitude ``commands`` (the first by default)."""

    name: str
    channel: str
    attitude: tuple[tuple[str, float], ...]
    element: TransferFunction
    commands: tuple[tuple[str, Command], ...]
    integrate: bool = False

    FIELDS = ("name", "channel", "attitude", "integrate", "element", "commands")

    @classmethod
    def from_dict(cls, data: Any, path: str, channels: tuple[str, ...], outputs: tuple[str, ...]) -> PilotSpec:
        t = _table(data, path)
        _keys(t, path, cls.FIELDS, required=("name", "channel", "attitude", "element", "commands"))
        name = _text(t["name"], f"{path}.name")
        if not name.isidentifier():
            raise _fail(f"{path}.name", f"a word (it names the run option <name>_command), got {name!r}")
        channel = _text(t["channel"], f"{path}.channel")
        if channel not in channels:
            raise _fail(f"{path}.channel", f"unknown channel {channel!r}; channels: {', '.join(channels)}")
        att = _table(t["attitude"], f"{path}.attitude")
        if not att:
            raise _fail(f"{path}.attitude", "at least one output")
        for output in att:
            if output not in outputs:
                raise _fail(f"{path}.attitude.{output}", f"unknown output; outputs: {', '.join(outputs)}")
        attitude = tuple((output, _real(w, f"{path}.attitude.{output}")) for output, w in att.items())
        cmds = _table(t["commands"], f"{path}.commands")
        if not cmds:
            raise _fail(f"{path}.commands", "at least one named command")
        commands = tuple((_text(label, f"{path}.commands"), Command.from_dict(c, f"{path}.commands.{label}"))
                         for label, c in cmds.items())
        return cls(name, channel, attitude, TransferFunction.from_dict(t["element"], f"{path}.element"), commands,
                   _bool(t.get("integrate", False), f"{path}.integrate"))

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.name, "channel": self.channel, "attitude": dict(self.attitude), "integrate": self.integrate,
                "element": self.element.to_dict(), "commands": {n: c.to_dict() for n, c in self.commands}}


@dataclass(frozen=True)
class FailureSpec:
    """A named failure at ``time``: the plant after it (``A``, ``B``, ``D``), a delay, effector failures."""

    time: float
    description: str = ""
    A: Matrix | None = None
    B: Matrix | None = None
    D: Matrix | None = None
    delay: float | tuple[float, ...] | None = None
    actuators: tuple[tuple[str, str, tuple[tuple[str, float], ...]], ...] = ()

    FIELDS = ("time", "description", "A", "B", "D", "delay", "actuators")

    @classmethod
    def from_dict(cls, data: Any, path: str, n: int, m: int, p: int, effectors: tuple[str, ...],
                  limits: tuple[tuple[float, float], ...], rate_limits: tuple[tuple[float, float], ...]) -> FailureSpec:
        from ..exceptions import ProblemError
        from ..health import SIMULATOR_ONLY, FailureKind, check_parameters

        t = _table(data, path)
        _keys(t, path, cls.FIELDS, required=("time",))
        time = _real(t["time"], f"{path}.time")
        if time < 0.0:
            raise _fail(f"{path}.time", f"must be >= 0, got {time:g}")
        kw: dict[str, Any] = {"time": time, "description": _text(t.get("description", ""), f"{path}.description")}
        for f, rows, cols in (("A", n, n), ("B", n, m), ("D", p, m)):
            if f in t:
                kw[f] = _matrix(t[f], f"{path}.{f}", rows, cols)
        if "delay" in t:
            d = t["delay"]
            delays = (_real(d, f"{path}.delay"),) if not isinstance(d, list) else _reals(d, f"{path}.delay", m)
            for i, x in enumerate(delays):
                if x < 0.0:
                    raise _fail(f"{path}.delay" + (f"[{i}]" if isinstance(d, list) else ""), f"must be >= 0, got {x:g}")
            kw["delay"] = delays if isinstance(d, list) else delays[0]
        kinds = {str(k): k.spec for k in FailureKind} | {k: s for k, s in SIMULATOR_ONLY.items() if s.per_actuator}
        acts = []
        for i, a in enumerate(_list(t.get("actuators", []), f"{path}.actuators", high=MAX_EFFECTORS)):
            where = f"{path}.actuators[{i}]"
            at = _table(a, where)
            _keys(at, where, ("effector", "kind", *sorted({q for s in kinds.values() for q in s.params})),
                  required=("effector", "kind"))
            effector = _text(at["effector"], f"{where}.effector")
            if effector not in effectors:
                raise _fail(f"{where}.effector", f"unknown effector {effector!r}")
            kind = _text(at["kind"], f"{where}.kind")
            if kind not in kinds:
                raise _fail(f"{where}.kind", f"unknown kind {kind!r}; one of {', '.join(kinds)}")
            params = []
            for q in at:
                if q in ("effector", "kind"):
                    continue
                if q not in kinds[kind].params:
                    raise _fail(f"{where}.{q}", f"a {kind!r} failure takes {', '.join(kinds[kind].params) or 'nothing'}")
                params.append((q, _real(at[q], f"{where}.{q}")))
            j = effectors.index(effector)
            try:  # each parameter in its range, against the effector's limits (the failure-kind table's check)
                check_parameters(kind, dict(params), effector=effector, limits=limits[j], rate_limits=rate_limits[j])
            except ProblemError as exc:
                raise _fail(f"{where}.{exc.field}" if exc.field in dict(params) else where, str(exc)) from None
            acts.append((effector, kind, tuple(params)))
        kw["actuators"] = tuple(acts)
        return cls(**kw)

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"time": self.time}
        if self.description:
            out["description"] = self.description
        for f in ("A", "B", "D"):
            if getattr(self, f) is not None:
                out[f] = [list(r) for r in getattr(self, f)]
        if self.delay is not None:
            out["delay"] = list(self.delay) if isinstance(self.delay, tuple) else self.delay
        if self.actuators:
            out["actuators"] = [{"effector": e, "kind": k, **dict(ps)} for e, k, ps in self.actuators]
        return out


@dataclass(frozen=True)
class AllocationSpec:
    """What the loop's allocator is given: ``B`` (channels x effectors), diagonal ``weights``,
    the seed's ``static`` distribution (effectors x channels) and the ``demand_map``."""

    B: Matrix
    static: Matrix
    weights: tuple[float, ...] | None = None
    demand_map: Matrix | None = None

    FIELDS = ("B", "weights", "static", "demand_map")

    @classmethod
    def from_dict(cls, data: Any, path: str, k: int, m: int) -> AllocationSpec:
        t = _table(data, path)
        _keys(t, path, cls.FIELDS, required=("B", "static"))
        kw: dict[str, Any] = {"B": _matrix(t["B"], f"{path}.B", k, m), "static": _matrix(t["static"], f"{path}.static", m, k)}
        if "weights" in t:
            kw["weights"] = tuple(_positive(x, f"{path}.weights[{i}]") for i, x in
                                  enumerate(_list(t["weights"], f"{path}.weights", m)))
        if "demand_map" in t:
            kw["demand_map"] = _matrix(t["demand_map"], f"{path}.demand_map", k, k)
        return cls(**kw)

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"B": [list(r) for r in self.B]}
        if self.weights is not None:
            out["weights"] = list(self.weights)
        out["static"] = [list(r) for r in self.static]
        if self.demand_map is not None:
            out["demand_map"] = [list(r) for r in self.demand_map]
        return out


@dataclass(frozen=True)
class Simulation:
    """A vehicle's own closed-loop design (the module docstring lists the fields)."""

    duration: float
    method: str
    output_bound: tuple[float, ...]
    references: tuple[TransferFunction, ...]
    allocation: AllocationSpec
    smc: SlidingMode
    noise: tuple[float, ...]
    measured: tuple[str, ...] = ()
    commands: tuple[Command | None, ...] = ()
    loopshape: tuple[TransferFunction, ...] | None = None
    pilot: PilotSpec | None = None
    failures: Mapping[str, FailureSpec] = field(default_factory=dict)
    #: the name runs are recorded under (default: the vehicle's)
    scenario: str = ""

    FIELDS = ("scenario", "duration", "method", "measured", "noise", "output_bound", "references", "commands", "allocation",
              "smc", "loopshape", "pilot", "failures")

    @classmethod
    def from_dict(cls, data: Any, path: str, *, outputs: tuple[str, ...], channels: tuple[str, ...],
                  effectors: tuple[str, ...], n: int, limits: tuple[tuple[float, float], ...] = (),
                  rate_limits: tuple[tuple[float, float], ...] = ()) -> Simulation:
        from .. import registry
        from ..exceptions import UnknownMethodError

        t = _table(data, path)
        _keys(t, path, cls.FIELDS, required=("duration", "method", "noise", "output_bound", "references",
                                              "allocation", "smc"))
        if not channels:
            raise _fail("model.controlled", "required by [simulation]: the channels, one per controlled output")
        k, m, p = len(channels), len(effectors), len(outputs)
        kw: dict[str, Any] = {"duration": _positive(t["duration"], f"{path}.duration")}
        if "scenario" in t:
            kw["scenario"] = _text(t["scenario"], f"{path}.scenario", name=True)
        method = _text(t["method"], f"{path}.method")
        try:
            registry.get_method(method)
        except UnknownMethodError as exc:
            raise _fail(f"{path}.method", str(exc).removeprefix("method: ")) from None
        kw["method"] = method
        measured = _names(t["measured"], f"{path}.measured") if "measured" in t else tuple(outputs)
        for i, name in enumerate(measured):
            if name not in outputs:
                raise _fail(f"{path}.measured[{i}]", f"unknown output {name!r}; outputs: {', '.join(outputs)}")
        kw["measured"] = measured
        kw["noise"] = tuple(_real(x, f"{path}.noise[{i}]") for i, x in
                            enumerate(_list(t["noise"], f"{path}.noise", len(measured))))
        kw["output_bound"] = tuple(_positive(x, f"{path}.output_bound[{i}]") for i, x in
                                   enumerate(_list(t["output_bound"], f"{path}.output_bound", k)))
        kw["references"] = tuple(TransferFunction.from_dict(r, f"{path}.references[{i}]")
                                 for i, r in enumerate(_list(t["references"], f"{path}.references", k)))
        if "commands" in t:
            cmds = _list(t["commands"], f"{path}.commands", k)
            kw["commands"] = tuple(None if _table(c, f"{path}.commands[{i}]") == {} else
                                   Command.from_dict(c, f"{path}.commands[{i}]") for i, c in enumerate(cmds))
        kw["allocation"] = AllocationSpec.from_dict(t["allocation"], f"{path}.allocation", k, m)
        kw["smc"] = SlidingMode.from_dict(t["smc"], f"{path}.smc", channels)
        if "loopshape" in t:
            ls = _table(t["loopshape"], f"{path}.loopshape")
            _keys(ls, f"{path}.loopshape", ("compensators",), required=("compensators",))
            kw["loopshape"] = tuple(TransferFunction.from_dict(c, f"{path}.loopshape.compensators[{i}]") for i, c in
                                    enumerate(_list(ls["compensators"], f"{path}.loopshape.compensators", k)))
        if "pilot" in t:
            kw["pilot"] = PilotSpec.from_dict(t["pilot"], f"{path}.pilot", channels, outputs)
        if "failures" in t:
            fs = _table(t["failures"], f"{path}.failures")
            if len(fs) > MAX_FAILURES:
                raise _fail(f"{path}.failures", f"expected at most {MAX_FAILURES} failures, got {len(fs)}")
            kw["failures"] = {_text(name, f"{path}.failures", name=True):
                              FailureSpec.from_dict(f, f"{path}.failures.{name}", n, m, p, effectors, limits,
                                                    rate_limits)
                              for name, f in fs.items()}
        return cls(**kw)

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"scenario": self.scenario} if self.scenario else {}
        out |= {"duration": self.duration, "method": self.method, "measured": list(self.measured),
                               "noise": list(self.noise), "output_bound": list(self.output_bound),
                               "references": [r.to_dict() for r in self.references]}
        if self.commands:
            out["commands"] = [{} if c is None else c.to_dict() for c in self.commands]
        out["allocation"] = self.allocation.to_dict()
        out["smc"] = self.smc.to_dict()
        if self.loopshape is not None:
            out["loopshape"] = {"compensators": [c.to_dict() for c in self.loopshape]}
        if self.pilot is not None:
            out["pilot"] = self.pilot.to_dict()
        if self.failures:
            out["failures"] = {name: f.to_dict() for name, f in self.failures.items()}
        return out
