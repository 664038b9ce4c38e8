"""A vehicle file's own closed loop (its ``[simulation]`` section) as a MIMO scenario.

:mod:`alloc.vehicle_file.simulation` reads and checks the section; this module turns it into
the simulator's objects -- a :class:`sim.scenarios.mimo.MimoScenario` whose plant is a
:class:`sim.model.PlantModel` -- and :func:`sim.scenarios.mimo.run_mimo` flies it, the runner
of the seed's scenarios.  The scenarios ``ice`` and ``harv_latdir`` are this function's loops of
``alloc/data/vehicles/ice.toml`` and ``harv.toml`` (their modules add only flight conditions and
extra options), so ``alloc sim --vehicle ice`` flies the scenario ``ice`` bit for bit
(tests/sim/test_user_vehicle.py).

Design options: ``observer`` and ``hedge`` (as the seed's scenarios), and
``<group>_hedge`` for every hedge group of the file (HARV's ``cross_hedge``).  Input
option: ``<pilot name>_command``, one of the pilot's named commands (HARV's
``phi_command = "filtered_steps"``).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from alloc.exceptions import ProblemError
from alloc.vehicle_file import LinearModel, Vehicle as FileVehicle
from alloc.vehicle_file.simulation import Command, FailureSpec, Simulation
from sim.blocks import ActuatorFailure, ActuatorSpec, HedgeTerm, sum_of_sines
from sim.model import Failure, FlightCondition, LoopShapedDesign, Pilot, SMCDesign, PlantModel
from sim.scenarios.mimo import MimoScenario
from sim import world

__all__ = ["file_scenario", "loop_of", "actuator_of", "command_signal", "filtered_steps", "flight_of_model"]


def filtered_steps(t: np.ndarray, times: tuple[float, ...], levels: tuple[float, ...],
                   tf: tuple[Any, Any]) -> np.ndarray:
    """``levels`` switched on at ``times`` (zero before the first), through the filter ``tf`` (zero state)."""
    from scipy import signal

    t = np.asarray(t, dtype=float)
    steps = np.zeros_like(t)
    for when, level in zip(times, levels, strict=True):
        steps[t >= when] = level
    if t.size < 2:
        return np.zeros_like(t)
    _, y, _ = signal.lsim(signal.lti(*tf), steps, t)
    return np.asarray(y, dtype=float)


def command_signal(command: Command) -> Any:
    """``t -> signal`` of a file's command: the seed's sum of sines (Eq 4.13) or filtered steps."""
    if command.filter is None:
        xi, phase_step = command.xi, command.phase_step
        return lambda t: sum_of_sines(t, xi, phase_step=phase_step)
    times, levels, tf = command.times, command.levels, command.filter.pair()
    return lambda t: filtered_steps(t, times, levels, tf)


def actuator_of(e: Any, index: int, lo: float, hi: float, static_bandwidth: float) -> ActuatorSpec:
    """The simulator's actuator of file effector ``e`` (``effectors[index]``) between ``lo`` and ``hi``."""
    rate = math.inf if e.rate_max is None else float(e.rate_max)
    if e.rate_min is not None and -e.rate_min != rate:
        raise ProblemError(f"effectors[{index}].rate_min: the simulator's actuators have a symmetric rate limit; "
                           f"got {e.rate_min:g} and rate_max {rate:g}", field=f"effectors[{index}].rate_min")
    d = e.dynamics
    if d is not None and d.delay > 0.0:
        raise ProblemError(f"effectors[{index}].dynamics.delay: a nominal actuator delay is not modelled by the loop "
                           "(a delay is injected only by a failure); remove it or fold it into the dynamics",
                           field=f"effectors[{index}].dynamics.delay")
    if d is None or (d.bandwidth is None and d.time_constant is None and d.wn is None and d.poles is None):
        return ActuatorSpec.first_order(e.name, static_bandwidth, lo, hi, rate)
    if d.bandwidth is not None:
        return ActuatorSpec.first_order(e.name, d.bandwidth, lo, hi, rate)
    if d.time_constant is not None:
        return ActuatorSpec.first_order(e.name, 1.0 / d.time_constant, lo, hi, rate)
    if d.wn is not None:
        return ActuatorSpec.second_order(e.name, d.wn, d.zeta, lo, hi, rate)
    return ActuatorSpec.two_real_poles(e.name, d.poles[0], d.poles[1], lo, hi, rate)


def _array(x: Any) -> np.ndarray | None:
    return None if x is None else np.array(x, dtype=float)


def _failure(spec: FailureSpec, name: str, time: float | None, effectors: tuple[str, ...]) -> Failure:
    delay = spec.delay
    return Failure(
        name=name, time=spec.time if time is None else float(time), description=spec.description,
        A=_array(spec.A), B=_array(spec.B), D=_array(spec.D),
        actuators=tuple(ActuatorFailure(effectors.index(e), kind, **dict(params)) for e, kind, params in spec.actuators),
        delay=np.array(delay, dtype=float) if isinstance(delay, tuple) else delay,
    )


def loop_of(fv: FileVehicle) -> tuple[LinearModel, Simulation]:
    """A vehicle file's ``[model]`` and ``[simulation]`` (ProblemError naming ``simulation`` without them)."""
    if fv.simulation is None or fv.model is None:
        raise ProblemError(f"simulation: vehicle {fv.name!r} has no [simulation] section", field="simulation")
    return fv.model, fv.simulation


def file_scenario(fv: FileVehicle, *, static_bandwidth: float = 1000.0) -> MimoScenario:
    """The :class:`MimoScenario` of a vehicle file with a ``[simulation]`` section.

    ``static_bandwidth``: the first-order lag of an effector without ``dynamics``
    (:func:`actuator_of`).
    """
    model, sim = loop_of(fv)
    A, B, C, D = model.arrays()
    outputs, channels = tuple(model.outputs), tuple(model.controlled)
    effectors = fv.effector_names
    k = len(channels)
    actuators = tuple(actuator_of(e, i, e.min, e.max, static_bandwidth) for i, e in enumerate(fv.effectors))
    alloc = sim.allocation

    def vehicle() -> PlantModel:
        return PlantModel(
            name=fv.name, A=A.copy(), B=B.copy(), C=C.copy(), D=D.copy(), output_names=outputs,
            actuators=actuators, controlled=tuple(outputs.index(c) for c in channels),
            measured=tuple(outputs.index(x) for x in sim.measured), noise_gains=np.array(sim.noise, dtype=float),
            B_alloc=np.array(alloc.B, dtype=float), Bk_seed=np.array(alloc.static, dtype=float),
            demand_map=np.eye(k) if alloc.demand_map is None else np.array(alloc.demand_map, dtype=float),
            Wu=_array(alloc.weights), names=effectors,
            flight=flight_of_model(A, tuple(model.states), dict(zip(model.outputs, model.units or (), strict=False))),
        )

    smc = sim.smc
    groups = smc.hedge_groups

    def smc_design(*, observer: bool = True, hedge: bool = True, **group_on: bool) -> SMCDesign:
        kept = tuple(HedgeTerm(channels.index(h.out), channels.index(h.inp), a_f=h.a_f, a_h=h.a_h, b_h=h.b_h,
                               gain=h.gain)
                     for h in smc.hedge if not h.group or group_on.get(f"{h.group}_hedge", True))
        return SMCDesign(
            rho=np.array(smc.rho), eps=np.array(smc.eps), K0=np.array(smc.K0), Km1=np.array(smc.Km1),
            observer_poles=smc.observer_poles if observer else None, hedge_terms=kept if hedge else (),
            hedge_gain=_array(smc.hedge_gain),
        )

    def loop_shaped_design() -> LoopShapedDesign:
        if sim.loopshape is None:
            raise ProblemError(f"simulation.loopshape: vehicle {fv.name!r} gives no loop-shaped baseline",
                               field="simulation.loopshape")
        return LoopShapedDesign(compensators=tuple(c.pair() for c in sim.loopshape))

    def failure(name: str, time: float | None) -> Failure:
        if name not in sim.failures:
            raise KeyError(f"unknown {fv.name} failure {name!r}; known: {sorted(sim.failures)}")
        return _failure(sim.failures[name], name, time, effectors)

    pilot_spec = sim.pilot
    input_options: tuple[str, ...] = ()
    if pilot_spec is not None:
        command_option = f"{pilot_spec.name}_command"
        input_options = (command_option,)
        named = dict(pilot_spec.commands)
        row = np.zeros(len(outputs))
        for output, weight in pilot_spec.attitude:
            row[outputs.index(output)] = weight

        def pilot(params: dict[str, Any], **choice: str) -> Pilot:
            chosen = choice.get(command_option, pilot_spec.commands[0][0])
            if chosen not in named:
                raise ValueError(f"{command_option}: {chosen!r}; expected one of {', '.join(map(repr, named))}")
            return Pilot(channel=channels.index(pilot_spec.channel), row=row.copy(), integrate=pilot_spec.integrate,
                         name=pilot_spec.name, **params, attitude_command=command_signal(named[chosen]))
        element = pilot_spec.element.pair()
    else:
        def pilot(params: dict[str, Any], **choice: str) -> Pilot:
            raise ProblemError(f"simulation.pilot: vehicle {fv.name!r} has no pilot", field="simulation.pilot")
        element = ([1.0], [1.0, 0.0])

    signals = [(i, command_signal(c)) for i, c in enumerate(sim.commands) if c is not None]

    def commands(t: np.ndarray) -> np.ndarray:
        out = np.zeros((t.size, k))
        for i, signal_of in signals:
            out[:, i] = signal_of(t)
        return out

    return MimoScenario(
        name=sim.scenario or fv.name, vehicle=vehicle, references=tuple(r.pair() for r in sim.references), smc_design=smc_design,
        loop_shaped_design=loop_shaped_design, failure=failure, pilot=pilot, pilot_element=element,
        commands=commands, output_bound=np.array(sim.output_bound, dtype=float), default_duration=sim.duration,
        default_method=sim.method, design_options=("observer", "hedge", *(f"{g}_hedge" for g in groups)),
        input_options=input_options, catalogue_vehicle=fv,  # type: ignore[arg-type]  # its [methods] defaults
        failures={name: f.description or name for name, f in sim.failures.items()},
    )


def flight_of_model(A: np.ndarray, states: tuple[str, ...], units: dict[str, str]) -> FlightCondition | None:
    """The flight condition of a vehicle file's model, or None when there is none to state.

    A model whose ``A`` is a seed scenario's (ICE, HARV lat-dir, HARV lon) flies at that
    scenario's condition; a hover model (states among attitudes, ``p q r`` and ``w``, no
    aerodynamic damping) gets the hover mapping (:data:`sim.world.HOVER_HEAVE_DAMPING`); ``units`` are the
    states' (where a state is also an output of the same name).
    """
    from sim.seed_flight import flight_of_seed_model  # deferred: it reads the bundled files

    A = np.asarray(A, dtype=float)
    seed = flight_of_seed_model(A)
    if seed is not None:
        return seed
    names = {n: i for i, n in enumerate(states)}
    rates = [(names[c], c) for c in "pqr" if c in names]
    if {"u", "v", "alpha", "beta"} & set(names) or not rates:
        return None
    hover: list[tuple[int, str, float]] = []
    # the dynamic rows (rates, heave): zero in the air-relative columns = no aerodynamic damping
    dynamic = [i for i, _ in rates] + ([names["w"]] if "w" in names else [])
    if np.any(A[np.ix_(dynamic, dynamic)]):
        return None
    for i, c in rates:
        scale = world.RATE_UNITS.get(units.get(c, ""), None)
        if scale is None:
            return None
        if c != "r":
            hover.append((i, c, world.HOVER_RATE_DAMPING * scale))
    if "w" in names:
        scale = world.SPEED_UNITS.get(units.get("w", ""), None)
        if scale is None:
            return None
        hover.append((names["w"], "w", world.HOVER_HEAVE_DAMPING * scale))
    return FlightCondition(altitude=world.HOVER_ALTITUDE, speed=0.0, span=world.HOVER_SPAN, gust_states=(), hover=tuple(hover),
                           source="ours: hover, the gust through stated rotor damping (sim.world HOVER_*)")
