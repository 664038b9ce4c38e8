"""Fly a user's vehicle file in the closed loop: ``alloc sim --vehicle FILE``.

A vehicle file with a ``[model]`` section (:mod:`alloc.vehicle_file`) carries everything the
loop needs; this module assembles it:

* **actuators** from each effector's ``dynamics`` (``bandwidth`` or ``time_constant``: first
  order; ``wn``/``zeta`` or ``poles``: second order), its limits and rate limit.  An effector
  without dynamics gets a first-order lag of ``static_bandwidth`` (1000 rad/s, two orders
  above the bundled vehicles' actuators).  A nominal actuator ``delay`` is refused: the loop
  models a delay only as a failure.
* **trim**: the axes' operating point (``axes[i].trim``, a hovering multicopter's thrust) is
  met by ``u0``, the default method's allocation of it; the loop flies deviations
  ``du = u - u0`` (the linear model's input), and every recorded position and limit is
  shifted back, so outputs are in the file's units around the file's numbers.
* **controller** by the seed's section 4.3 procedure (:func:`sim.autodesign.auto_design`),
  its report in ``result.settings["design"]``; ``controller="loopshape"`` flies its linear
  baseline instead.
* **commands**: the seed's sum of sines (Table 4-2, Eq 4.13) into every channel's reference
  model, channel ``i`` phase-shifted by ``i pi / 4`` (ICE's roll channel: ``pi / 4``), scaled so
  its peak pseudo-command is ``command_fraction`` of ``rho``.  No pilot model: a user's
  vehicle names no attitude the pilot would fly.
* **failures** by name in the library's grammar (:mod:`alloc.failure_grammar`),
  ``<kind>:<effector>[@<value>[:<value>]]`` (several joined by ``+``), any kind of the
  failure-kind table (:mod:`alloc.health`) or a per-actuator simulator-only one, the values
  filling the kind's parameters in order.  ``float:motor1`` is a rotor loss
  (no thrust, no moment); ``effectiveness:motor1@0.5`` half of it; ``jam:elevon_l@5`` a
  surface stuck at 5 (file units; without a value, where it is at the failure);
  ``hardover:x`` runs to ``max``; ``limits:x@lo:hi``; ``bandwidth:x@wn`` (never told).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, fields, replace
from typing import Any

import numpy as np

from alloc.exceptions import ProblemError
from alloc.failure_grammar import GRAMMAR, parse_failure
from sim.autodesign import AutoDesign, auto_design, design_options, weighted_pinv
from sim.file_scenario import actuator_of, file_scenario, flight_of_model
from sim.blocks import DEFAULT_DT, SUM_OF_SINES_TABLE_4_2, ActuatorFailure, sum_of_sines
from sim.engine import simulate
from sim.model import Failure, PlantModel
from sim.settings import LoopSpec
from sim.result import SimResult
from sim.settings import RunSettings

__all__ = ["FlightModel", "VehicleScenario", "flight_model", "vehicle_failure", "fly", "DEFAULT_DURATION",
           "DEFAULT_FAILURE_TIME", "FAILURE_SYNTAX"]

#: simulated seconds of a run unless told (the failure halfway)
DEFAULT_DURATION = 20.0
DEFAULT_FAILURE_TIME = 10.0
#: how a failure is named on a user's vehicle: the library's grammar (:mod:`alloc.failure_grammar`)
FAILURE_SYNTAX = GRAMMAR
#: divergence bound on a controlled output, x its command peak
OUTPUT_BOUND_FACTOR = 20.0


@dataclass(frozen=True)
class FlightModel:
    """A vehicle file made ready to fly: the loop's vehicle (deviations from trim), design, commands.

    ``trim_u`` is ``u0`` (file units); ``command_scale`` the sum-of-sines ``xi`` per channel.
    """

    source: Any
    vehicle: PlantModel
    trim_u: np.ndarray
    design: AutoDesign
    command_scale: np.ndarray
    output_bound: np.ndarray
    units: dict[str, Any]

    def commands(self, t: np.ndarray) -> np.ndarray:
        """Direct commands into the reference models, one column per channel."""
        return np.column_stack([sum_of_sines(t, xi, phase_step=i * np.pi / 4)
                                for i, xi in enumerate(self.command_scale)])

    def failure(self, name: str, time: float) -> Failure:
        """:func:`vehicle_failure` of this model."""
        return vehicle_failure(self, name, time)


def _trim(file_vehicle: Any) -> np.ndarray:
    """``u0`` meeting the axes' trim (zero when every trim is zero)."""
    trim = file_vehicle.trim
    if not np.any(trim):
        return np.zeros(file_vehicle.m)
    import alloc
    from alloc.registry import DEFAULT_METHOD

    res = alloc.make_allocator(file_vehicle.problem(), DEFAULT_METHOD)(trim)
    if res.status != alloc.Status.EXACT:
        raise ProblemError(f"axes[].trim: the effectors cannot meet the trim {trim.tolist()} "
                           f"(best {res.v_achieved.tolist()})", field="axes")
    return np.asarray(res.u, dtype=float)


def _command_peak(design: AutoDesign, A: np.ndarray, B: np.ndarray, C_ctl: np.ndarray, allocation: np.ndarray) -> np.ndarray:
    """Peak pseudo-command per unit ``xi`` of the sum of sines: ``sum_j |A_j| |R(j w_j)| / |P_ii(j w_j)|``.

    ``P(s) = C_ctl (sI - A)^-1 B allocation demand_map`` is what each channel's output does per
    unit pseudo-command; following ``r = R cmd`` takes ``u_c = r / P_ii`` per sine.
    """
    n, k = A.shape[0], C_ctl.shape[0]
    path = B @ allocation @ design.demand_map
    peak = np.zeros(k)
    for amp, w in SUM_OF_SINES_TABLE_4_2:
        P = C_ctl @ np.linalg.solve(1j * w * np.eye(n) - A, path)
        for i, (num, den) in enumerate(design.references):
            R = np.polyval(num, 1j * w) / np.polyval(den, 1j * w)
            peak[i] += abs(amp) * abs(R) / max(abs(P[i, i]), np.finfo(float).tiny)
    return peak


def flight_model(source: Any, *, design: Mapping[str, Any] | None = None,
                 frame_period: float = DEFAULT_DT) -> FlightModel:
    """The :class:`FlightModel` of a vehicle (file path, catalogue name or :class:`alloc.vehicle_file.Vehicle`).

    ``design`` overrides :data:`sim.autodesign.DESIGN_OPTIONS` by name.
    """
    from alloc import vehicles

    fv = vehicles.get_vehicle(source)
    if fv.model is None:
        raise ProblemError(f"model: vehicle {fv.name!r} has no [model] section; the closed loop needs its linear "
                           "model (states, outputs, A, B, C, D, controlled)", field="model")
    model = fv.model
    if not model.controlled:
        raise ProblemError(f"model.controlled: vehicle {fv.name!r} names no controlled outputs (one per axis)",
                           field="model.controlled")
    A, B, C, D = model.arrays()
    u0 = _trim(fv)
    lo = np.array([e.min for e in fv.effectors]) - u0
    hi = np.array([e.max for e in fv.effectors]) - u0
    static_bw = design_options(design)["static_bandwidth"]
    actuators = tuple(actuator_of(e, i, lo[i], hi[i], static_bw) for i, e in enumerate(fv.effectors))
    controlled = tuple(model.outputs.index(c) for c in model.controlled)
    measured = tuple(range(len(model.outputs)))
    B_axes = np.array(fv.B, dtype=float)
    problem = fv.problem()
    Wu = None
    if problem.Wu is not None:  # the loop's vehicle and the design take the diagonal weights
        Wu = np.asarray(problem.Wu, dtype=float)
        Wu = np.diag(Wu).copy() if Wu.ndim == 2 else Wu
    ad = auto_design(A, B, C, D, controlled=controlled, measured=measured, output_names=model.outputs,
                     B_axes=B_axes, umin=lo, umax=hi, actuators=actuators, Wu=Wu, frame_period=frame_period,
                     options=design)
    opt = ad.report["options"]
    allocation = weighted_pinv(B_axes, Wu)
    peak = _command_peak(ad, A, B, C[list(controlled)], allocation)
    xi = opt["command_fraction"] * ad.smc.rho / peak
    command_peak = xi * sum(abs(a) for a, _ in SUM_OF_SINES_TABLE_4_2)
    gains = np.zeros(len(model.outputs))
    gains[list(controlled)] = opt["noise_fraction"] * command_peak
    vehicle = PlantModel(
        name=fv.name, A=A, B=B, C=C, D=D, output_names=tuple(model.outputs), actuators=actuators,
        controlled=controlled, measured=measured, noise_gains=gains, B_alloc=B_axes,
        # no seed matrix for a user's aircraft: ``static`` is the unconstrained (weighted) pseudo-inverse
        Bk_seed=allocation @ ad.demand_map, demand_map=ad.demand_map, Wu=Wu, names=fv.effector_names,
        flight=flight_of_model(A, tuple(model.states), file_units(fv)["outputs"]),
    )
    ad.report["commands"] = {
        "signal": "seed Table 4-2 sum of sines (Eq 4.13) into each reference model, channel i phase i pi/4",
        "xi": xi.tolist(), "peak": command_peak.tolist(),
        "rule": f"peak pseudo-command = {opt['command_fraction']:g} x rho (linear plant, weighted pseudo-inverse)",
        "pilot": None,
    }
    ad.report["noise"] = {"gains": gains.tolist(), "rule": f"{opt['noise_fraction']:g} x command peak on the "
                          "controlled outputs (seed: 0.1414 on ICE's 5-10 deg commands), 0 elsewhere"}
    ad.report["trim"] = {"u0": u0.tolist(), "axes": fv.trim.tolist(),
                         "rule": "default method's allocation of the axes' trim; the loop flies u - u0"}
    ad.report["actuators"] = [{"name": a.name, "order": a.order, "wn": a.wn, "rate": a.rate} for a in actuators]
    units = file_units(fv)
    return FlightModel(source=fv, vehicle=vehicle, trim_u=u0, design=ad, command_scale=xi,
                       output_bound=OUTPUT_BOUND_FACTOR * command_peak, units=units)


def vehicle_failure(fm: FlightModel, name: str, time: float) -> Failure:
    """The :class:`sim.model.Failure` named ``name`` (:data:`FAILURE_SYNTAX`, :mod:`alloc.failure_grammar`) at ``time``.

    The values after ``@`` fill the kind's parameters in the order of its row in
    :data:`alloc.health.FAILURE_KINDS` (``limits:x@lo:hi``); a parameter left out takes the
    row's default (a jam without a position holds the position at the instant of failure).
    Positions are in the file's units, checked against the file's limits.
    """
    from alloc.health import PARAMETERS, Range

    effectors = fm.source.effectors
    names = list(fm.vehicle.effector_names)
    parts = parse_failure(name, names, limits=[(e.min, e.max) for e in effectors])
    failures = []
    for part in parts:
        i = names.index(part.effector)
        params = {}
        for param, x in part.params.items():
            known = PARAMETERS.get(param)
            # the loop flies deviations from trim
            params[param] = x - fm.trim_u[i] if known is not None and known.range == Range.POSITION else x
        try:
            failures.append(ActuatorFailure(i, part.kind, **params))
        except ProblemError as exc:
            raise ProblemError(f"failure: {part.text()!r}: {exc}", field="failure") from None
    return Failure(name=name, time=float(time), description=f"{name} at t = {time:g} s", actuators=tuple(failures))


def fly(source: Any, settings: RunSettings | None = None, *, design: Mapping[str, Any] | None = None,
        progress: bool = False, **options: Any) -> SimResult:
    """Fly a vehicle file: its own loop (``[simulation]``) or its model with the auto-designed controller.

    ``settings`` are the run's :class:`sim.settings.RunSettings`; keyword ``options`` that name a
    setting override them one by one (``fly("hexa-x", method="qp", failure="float:motor1")``).
    A file with a ``[simulation]`` section flies it through :func:`sim.scenarios.mimo.run_mimo`
    (:func:`sim.file_scenario.file_scenario`), the runner of the seed's scenarios, taking that
    section's design and input options as well (``observer``, ``hedge``, ``cross_hedge``,
    ``phi_command``); ``design`` is refused (there is nothing to auto-design).  Any other file
    with a ``[model]`` is designed by :func:`sim.autodesign.auto_design` (``design`` overrides
    its choices) and flown without a pilot: the pilot settings are refused.  Defaults: the
    default method, :data:`DEFAULT_DURATION` s, a failure named by :data:`FAILURE_SYNTAX` at
    :data:`DEFAULT_FAILURE_TIME` s.

    Positions and limits in the result are in the file's units (trim added back);
    ``result.settings`` records the settings as flown, ``units`` (the file's) and, auto-designed,
    ``design`` (the section 4.3 report), ``controller`` and ``trim_u``.

    Raises
    ------
    SettingError
        a setting out of its type or range; TypeError an option that is no setting of this run.
    """
    from alloc import vehicles

    fv = vehicles.get_vehicle(source)
    given, extra = RunSettings.split(options)
    flown = given if settings is None else replace(settings, **{k: options[k] for k in options if k not in extra})
    if settings is not None and not isinstance(settings, RunSettings):
        raise TypeError(f"settings: expected sim.settings.RunSettings, got {type(settings).__name__}")
    if fv.simulation is not None:
        if design:
            raise TypeError(f"design: vehicle {fv.name!r} flies its own [simulation] design; nothing to auto-design")
        from sim.scenarios.mimo import run_mimo

        scenario = file_scenario(fv, static_bandwidth=design_options(None)["static_bandwidth"])
        result = run_mimo(scenario, progress=progress, **_fields(flown), **extra)
        result.settings["units"] = file_units(fv)
        return result
    if extra:
        raise TypeError(f"{sorted(extra)[0]}: not a run setting (sim.settings.RunSettings) of a vehicle file's "
                        "auto-designed loop")
    pilot_given = [n for n in ("pilot_gain", "pilot_delay") if getattr(flown, n) is not None]
    if flown.pilot != "standin" or pilot_given:
        raise TypeError(f"{(pilot_given or ['pilot'])[0]}: a vehicle file's auto-designed run has no pilot model "
                        "(direct commands into the reference models)")
    return _fly_designed(fv, flown, design=design, progress=progress)


def _fields(settings: RunSettings) -> dict[str, Any]:
    return {f.name: getattr(settings, f.name) for f in fields(RunSettings)}


def file_units(fv: Any) -> dict[str, Any]:
    """The file's units, as plots and tables label a run (``result.settings["units"]``)."""
    model = fv.model
    out_units = dict(zip(model.outputs, model.units, strict=True)) if model is not None and model.units else {}
    channels = {} if model is None else {c: out_units.get(c, "") for c in model.controlled}
    return {"channels": channels, "outputs": out_units, "effectors": {e.name: e.unit for e in fv.effectors},
            "axes": {a.name: a.unit for a in fv.axes}}


def _fly_designed(fv: Any, settings: RunSettings, *, design: Mapping[str, Any] | None, progress: bool) -> SimResult:
    from alloc import vehicles
    from alloc.registry import DEFAULT_METHOD
    from sim.allocation import STATIC

    # designed at the seed's 0.5 ms frame, as the seed's scenarios were: the loop's boundary-layer
    # rule (sim.settings.boundary_layer_at) adapts eps to a slower frame_period, once
    fm = flight_model(fv, design=design)
    method = DEFAULT_METHOD if settings.method is None else settings.method
    method_options = settings.method_options
    if method != STATIC:
        method_options = vehicles.method_options(fm.source, method, method_options)
    duration = DEFAULT_DURATION if settings.duration is None else float(settings.duration)
    failure = settings.failure
    if isinstance(failure, str):
        failure = fm.failure(failure, DEFAULT_FAILURE_TIME if settings.failure_time is None else settings.failure_time)
    if settings.controller not in ("smc", "loopshape"):
        raise ProblemError(f"controller: {settings.controller!r}; expected 'smc' or 'loopshape'", field="controller")
    law: Any = fm.design.smc if settings.controller == "smc" else fm.design.baseline
    flown = replace(settings, method=method, method_options=method_options, duration=duration,
                    failure_time=None if failure is None else failure.time)
    n = int(round(duration / flown.dt)) + 1
    spec = LoopSpec(
        scenario=fm.vehicle.name, vehicle=fm.vehicle, references=fm.design.references, controller=law,
        commands=fm.commands(np.arange(n) * flown.dt), pilots=(), failure=failure, method=method,
        duration=duration, output_bound=fm.output_bound, **flown.loop_settings(),
    )
    result = simulate(spec, progress=progress)
    _to_file_units(result, fm.trim_u)
    result.settings = {**result.settings, **flown.record(), "controller": settings.controller,
                       "design": fm.design.report, "units": fm.units, "trim_u": fm.trim_u.tolist()}
    return result


def _to_file_units(result: SimResult, u0: np.ndarray) -> None:
    """Positions and limits around the file's numbers: ``u = du + u0``."""
    if not np.any(u0):
        return
    if result.effectors is not None:
        result.effectors = result.effectors + u0
    if result.effector_limits is not None:
        result.effector_limits = tuple(np.asarray(x) + u0 for x in result.effector_limits)


class VehicleScenario:
    """A vehicle file as a scenario of :func:`sim.scenarios.get_scenario`'s shape (``alloc sim --vehicle FILE``).

    A file with a ``[simulation]`` section is its scenario: its failures by name, its default
    duration and method, its pilot.  Any other file: ``failures`` lists a rotor loss
    (``float``) and a jam at the failure instant for every effector, as examples; any name of
    :data:`FAILURE_SYNTAX` is accepted (:meth:`check_failure`), and the pilot settings are
    refused (a vehicle file's model names no pilot).  Calling it flies :func:`fly`.
    """

    accepts_failure_objects = True
    default_failure = None

    def __init__(self, source: Any) -> None:
        from alloc import registry, vehicles

        self.vehicle = vehicles.get_vehicle(source)
        if self.vehicle.model is None:
            raise ProblemError(f"model: vehicle {self.vehicle.name!r} has no [model] section; alloc sim needs its "
                               "linear model (states, outputs, A, B, C, D, controlled)", field="model")
        sim = self.vehicle.simulation
        self.name = self.vehicle.name if sim is None else (sim.scenario or self.vehicle.name)
        self.failures = {}
        if sim is not None:
            self.description = (f"{self.vehicle.name}: vehicle file, {len(self.vehicle.model.controlled)} channels x "
                                f"{self.vehicle.m} effectors, its own [simulation] design")
            self.default_duration = sim.duration
            self.default_method = sim.method
            for name, f in sim.failures.items():
                self.failures[name] = f"t = {f.time:g} s: {f.description}" if f.description else f"t = {f.time:g} s"
            return
        self.description = (f"{self.vehicle.name}: vehicle file, {self.vehicle.k} axes x {self.vehicle.m} effectors, "
                            "seed section 4.3 design (sim.autodesign)")
        self.default_duration = DEFAULT_DURATION
        self.default_method = registry.DEFAULT_METHOD
        for e in self.vehicle.effectors:
            self.failures[f"float:{e.name}"] = f"{e.name} floats: no control power (a rotor loss)"
            self.failures[f"jam:{e.name}@<position>"] = f"{e.name} held at <position> ({e.unit})"

    def check_failure(self, name: object) -> None:
        """ProblemError (field ``failure``, saying what is taken) unless ``name`` is a failure of this
        vehicle: the file's own by name, or a text of :data:`FAILURE_SYNTAX` naming its effectors."""
        if isinstance(name, str) and name in self.failures:
            return
        if self.vehicle.simulation is not None:
            from sim.file_scenario import file_scenario

            file_scenario(self.vehicle).check_failure(name)
            return
        try:
            parse_failure(name, self.vehicle.effector_names,
                          limits=[(e.min, e.max) for e in self.vehicle.effectors])
        except ProblemError as exc:
            examples = ", ".join(list(self.failures)[:4])
            raise ProblemError(f"{exc}; e.g. {examples}", field="failure") from None

    def accepts_failure(self, name: str) -> bool:
        """Whether :meth:`check_failure` takes ``name``."""
        try:
            self.check_failure(name)
        except ProblemError:
            return False
        return True

    def __call__(self, **options: Any) -> SimResult:
        return fly(self.vehicle, **options)
