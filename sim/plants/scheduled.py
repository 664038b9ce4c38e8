"""``alloc sim --vehicle FILE --schedule NAME=START:END``: a scheduled vehicle flown along its schedule.

A vehicle file's ``[schedule]`` declares its effectiveness as a function of named variables
(:mod:`alloc.vehicle_file.schedule`: ``B(x) = B + sum_t (f_t(x) - f_t(nominal)) B_t``).  Here the
variables move over the run, each linearly from ``START`` at t = 0 to ``END`` at the run's end
(:class:`SchedulePath`), and both the plant and the allocator follow them:

* the plant (:class:`ScheduledLinearPlant`) is the vehicle's linear model whose input matrix is
  ``M B(x)``: ``M = B_model pinv(B)`` maps the axes' effectiveness into the model's state derivatives
  (for a model derived from a ``[body]``, ``M`` is the inertia and mass rows exactly).  The trim command
  ``u0`` moves with the schedule too: the plant sees ``M (B(x) - B) u0`` on top (a tilted rotor's trim
  thrust no longer holds the weight; the controller's integrals take it up).  Each step is the exact
  zero-order hold of ``A`` with ``B(x)`` held over the step (``Gamma = int_0^h exp(A s) ds``, once);
  ``B(x)`` is evaluated at every step;
* the allocator is rebuilt on ``B(x)`` once per flight-control frame (``follow``), or keeps the nominal
  ``B`` (``frozen``: what a vehicle file without the schedule flies) -- the comparison the schedule is for.

The controller is the engine's (:class:`sim.plant_control.EngineController`, the seed's section 4.3 design
at the nominal point, its sum-of-sines commands) in the Python plant loop (:func:`sim.plant_loop.fly_plant`),
which reproduces the compiled engine to the bit on a constant ``B``.  The frame is ``frame_period``, by
default :data:`SCHEDULE_FRAME` (the allocator's rebuild is the cost per frame); the plant steps at ``dt``.
Health ``blind`` or ``told``.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import scipy.linalg

from alloc.exceptions import ProblemError
from sim.plant import LinearPlant, _whole_steps, command_of
from sim.settings import RunSettings, SettingError

__all__ = [
    "ALLOCATOR_MODES",
    "SCHEDULE_FRAME",
    "SchedulePath",
    "ScheduledLinearPlant",
    "fly_scheduled",
    "parse_schedule",
]

#: s: the flight-control frame of a scheduled run unless --frame-rate says otherwise (250 Hz)
SCHEDULE_FRAME = 0.004
#: how the allocator treats the schedule: rebuilt on B(x) every frame, or kept at the nominal B
ALLOCATOR_MODES = ("follow", "frozen")
#: largest relative residual of B_model = M B accepted (the model's B must be a map of the axes')
MAP_RTOL = 1e-9
_PATH = re.compile(r"^([A-Za-z_][A-Za-z0-9_]*)=([^:]+):([^:]+)$")


@dataclass(frozen=True)
class SchedulePath:
    """Scheduling variables moving linearly over ``[0, duration]`` s: ``ends[name] = (start, end)``."""

    ends: dict[str, tuple[float, float]]
    duration: float

    def at(self, t: float) -> dict[str, float]:
        s = min(max(t / self.duration, 0.0), 1.0) if self.duration > 0 else 1.0
        return {n: a + (b - a) * s for n, (a, b) in self.ends.items()}


def parse_schedule(texts: list[str], fv: Any) -> dict[str, tuple[float, float]]:
    """``["tilt=0:45", ...]`` as ``{"tilt": (0.0, 45.0)}``, each end inside the variable's declared range;
    SettingError naming ``schedule`` (the vehicle's variables listed) otherwise."""
    if fv.schedule is None:
        raise SettingError(f"schedule: vehicle {fv.name!r} declares no [schedule]; --schedule moves a scheduled "
                           "vehicle's variables", field="schedule")
    variables = {v.name: v for v in fv.schedule.variables}
    out: dict[str, tuple[float, float]] = {}
    for text in texts:
        m = _PATH.match(text.strip())
        if m is None:
            raise SettingError(f"schedule: {text!r}: expected NAME=START:END, e.g. tilt=0:45", field="schedule")
        name, a, b = m.group(1), m.group(2), m.group(3)
        if name not in variables:
            raise SettingError(f"schedule: {text!r}: unknown variable {name!r}; declared: {', '.join(variables)}",
                               field="schedule")
        if name in out:
            raise SettingError(f"schedule: {name!r} given twice", field="schedule")
        try:
            ends = (float(a), float(b))
        except ValueError:
            raise SettingError(f"schedule: {text!r}: START and END must be numbers", field="schedule") from None
        v = variables[name]
        for x in ends:
            if not v.min <= x <= v.max:  # NaN fails too
                raise SettingError(f"schedule: {text!r}: {name} must stay in [{v.min:g}, {v.max:g}] {v.unit}",
                                   field="schedule")
        out[name] = ends
    return out


class ScheduledLinearPlant(LinearPlant):
    """:class:`sim.plant.LinearPlant` whose ``B`` follows a :class:`SchedulePath` (module docstring)."""

    def __init__(self, vehicle: Any, dt_step: float, *, fv: Any, path: SchedulePath, trim_u: np.ndarray,
                 actuators: bool = True) -> None:
        super().__init__(vehicle, dt_step, actuators=actuators)
        self.name = "linear-scheduled"
        self.path = path
        self.evaluator = fv.scheduled()
        B_axes0 = np.asarray(vehicle.B_alloc, dtype=float)
        B_model = np.asarray(vehicle.B, dtype=float)
        self.M = B_model @ np.linalg.pinv(B_axes0)
        residual = np.max(np.abs(self.M @ B_axes0 - B_model), initial=0.0)
        if not residual <= MAP_RTOL * max(1.0, float(np.max(np.abs(B_model)))):
            raise ProblemError(f"schedule: vehicle {fv.name!r}'s model B is not a map of its axes' B (residual "
                               f"{residual:.3g}); the schedule cannot move the model", field="schedule")
        n = vehicle.A.shape[0]
        E = scipy.linalg.expm(np.block([[vehicle.A, np.eye(n)], [np.zeros((n, 2 * n))]]) * self.dt_step)
        self.Ad, self.Gamma = E[:n, :n], E[:n, n:]  # exact ZOH of A; Gamma maps a held x' term
        self.u0 = np.asarray(trim_u, dtype=float)
        self.B0 = B_axes0
        self.source = (f"linear model of {vehicle.name}, B(x) of its [schedule] along {path.ends} over "
                       f"{path.duration:g} s (sim.plants.scheduled, exact ZOH at {dt_step:g} s)")
        self.time = 0.0

    def reset(self, *, seed: int) -> np.ndarray:
        self.time = 0.0
        return super().reset(seed=seed)

    def B_axes(self, t: float) -> np.ndarray:
        """``B(x(t))`` (axes x effectors), a copy."""
        return self.evaluator.evaluate(self.path.at(t)).copy()

    def step(self, u_cmd: np.ndarray, dt: float) -> np.ndarray:
        u = command_of(u_cmd, len(self.effectors))
        p, bank = self._plant, self._bank
        for _ in range(_whole_steps(dt, self.dt_step)):
            B = self.evaluator.evaluate(self.path.at(self.time))
            eff = bank.effectiveness
            xdot_in = self.M @ (B @ (eff * bank.pos) + (B - self.B0) @ self.u0)
            p.x = self.Ad @ p.x + self.Gamma @ xdot_in
            if self.actuators:
                bank.step(u)
            else:
                bank.pos = np.clip(np.where(bank.jammed, bank.jam_pos, u), bank.lo, bank.hi)
            self.time += self.dt_step
        return self._outputs()

    def sensed(self) -> np.ndarray:
        B = self.evaluator.evaluate(self.path.at(self.time))
        bank = self._bank
        return self.M @ (B @ (bank.effectiveness * bank.pos) + (B - self.B0) @ self.u0)

    def describe(self) -> dict[str, Any]:
        return {**super().describe(), "schedule": {k: list(v) for k, v in self.path.ends.items()},
                "schedule_duration": self.path.duration}


def fly_scheduled(source: Any, schedule: list[str], settings: RunSettings | None = None, *,
                  allocator: str = "follow", progress: bool = False, **options: Any) -> Any:
    """Fly vehicle ``source`` along ``schedule`` (``["tilt=0:45"]``, module docstring); a SimResult."""
    from alloc import vehicles
    from alloc.registry import DEFAULT_METHOD
    from sim.plant_control import EngineController
    from sim.plant_loop import fly_plant
    from sim.plants import flown_settings
    from sim.settings import LoopSpec
    from sim.user_vehicle import DEFAULT_DURATION, DEFAULT_FAILURE_TIME, flight_model

    if allocator not in ALLOCATOR_MODES:
        raise SettingError(f"schedule_allocator: {allocator!r}; expected one of {', '.join(ALLOCATOR_MODES)}",
                           field="schedule_allocator")
    flown = flown_settings(settings, options, "--schedule")
    if flown.health_mode == "detected":
        raise SettingError("health: a scheduled run flies blind or told (the detector's model is the nominal one)",
                           field="health")
    fv = vehicles.get_vehicle(source)
    ends = parse_schedule(schedule, fv)
    frame = SCHEDULE_FRAME if flown.frame_period is None else float(flown.frame_period)
    flown = replace(flown, frame_period=frame)
    fm = flight_model(fv)
    method = DEFAULT_METHOD if flown.method is None else flown.method
    method_options = vehicles.method_options(fm.source, method, flown.method_options)
    duration = DEFAULT_DURATION if flown.duration is None else float(flown.duration)
    failure = flown.failure
    if isinstance(failure, str):
        failure = fm.failure(failure, DEFAULT_FAILURE_TIME if flown.failure_time is None else flown.failure_time)
    dt = flown.dt
    n = round(duration / dt) + 1
    spec = LoopSpec(scenario=fm.vehicle.name, vehicle=fm.vehicle, references=fm.design.references,
                    controller=fm.design.smc, commands=fm.commands(np.arange(n) * dt), pilots=(), failure=failure,
                    method=method, duration=duration, output_bound=fm.output_bound, **flown.loop_settings())
    path = SchedulePath(ends, duration)
    plant = ScheduledLinearPlant(fm.vehicle, dt, fv=fv, path=path, trim_u=fm.trim_u, actuators=flown.actuators)
    vehicle_at = None
    if allocator == "follow":
        def vehicle_at(t: float) -> Any:
            return replace(fm.vehicle, B_alloc=plant.B_axes(t))
    timing: dict[str, float] = {}
    result = fly_plant(
        plant, EngineController(spec), fm.vehicle, method=method, method_options=method_options, duration=duration,
        dt=dt, frame_steps=spec.frame_steps(), failure=failure, health=flown.health_mode,
        output_bound=fm.output_bound, record_every=flown.record_every, seed=flown.seed, timing=timing,
        alloc_options={"rate_aware": flown.rate_aware, "preferred": flown.preferred,
                       "rate_horizon": flown.rate_horizon, "rate_window": flown.rate_window},
        u_prev_source=flown.u_prev_source, scenario=fm.vehicle.name, vehicle_at=vehicle_at)
    record = {**flown.record(), **result.settings}
    record.update(duration=duration, method=method, failure=None if failure is None else failure.name,
                  failure_time=None if failure is None else failure.time, noise=False,
                  schedule={k: list(v) for k, v in ends.items()}, schedule_allocator=allocator,
                  design=fm.design.report, units=fm.units, trim_u=fm.trim_u.tolist(),
                  real_time_factor=timing["simulated_s"] / max(timing["wall_s"], 1e-9), timing=timing)
    result.settings = record
    return result
