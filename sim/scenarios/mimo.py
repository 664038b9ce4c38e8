"""The one runner of the MIMO scenarios (ICE, F-18/HARV lon and lat-dir).

A MIMO scenario is data: a :class:`MimoScenario` (vehicle, reference models,
SMC and loop-shaped designs, failures, pilot, direct commands, divergence
bound).  :func:`run_mimo` turns it and the run options into a
:class:`sim.settings.LoopSpec` and flies it.  Adding a scenario is one module that
builds a ``MimoScenario`` and registers a ``run(**options)`` that calls
``run_mimo(SCENARIO, **options)`` with :func:`mimo_scenario`.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from alloc import vehicles
from sim.allocation import STATIC
from sim.blocks import DEFAULT_DT
from sim.engine import simulate
from sim.model import TF, Failure, LoopShapedDesign, Pilot, SMCDesign, Vehicle
from sim.settings import LoopSpec
from sim.pilot import pilot_parameters
from sim.result import SimResult
from sim.scenarios import Scenario, register_scenario

__all__ = ["MimoScenario", "run_mimo", "mimo_scenario"]


@dataclass(frozen=True)
class MimoScenario:
    """What differs between the MIMO scenarios.

    Attributes
    ----------
    name : str
        Registered scenario name.
    vehicle : callable
        ``() -> Vehicle``.
    references : sequence of TF
        Reference model per channel.
    smc_design : callable
        ``(**design_options) -> SMCDesign``; its keyword names are the scenario's design options.
    loop_shaped_design : callable
        ``() -> LoopShapedDesign`` (the seed's baseline).
    failure : callable
        ``(name, time or None) -> Failure``; ``time`` None means the seed's failure time.
    pilot : callable
        ``(pilot parameters, **input_options) -> Pilot`` for the scenario's pilot channel.
    pilot_element : (num, den)
        What the pilot flies, stick to attitude (sets the crossover pilot, :mod:`sim.pilot`).
    commands : callable
        ``(t grid) -> (N, k)`` direct commands into the reference models.
    output_bound : ndarray
        Divergence bound per channel (:mod:`sim.result`).
    default_duration : float
    default_method : str
    design_options, input_options : tuple of str
        Extra run options forwarded to ``smc_design`` and to ``pilot``.
    catalogue_vehicle : str or None
        The :mod:`alloc.vehicles` entry whose ``[methods.<name>]`` defaults (ICE's daisy
        groups) the allocator gets under the run's ``method_options``.
    """

    name: str
    vehicle: Callable[[], Vehicle]
    references: Sequence[TF]
    smc_design: Callable[..., SMCDesign]
    loop_shaped_design: Callable[[], LoopShapedDesign]
    failure: Callable[[str, float | None], Failure]
    pilot: Callable[..., Pilot]
    pilot_element: TF
    commands: Callable[[np.ndarray], np.ndarray]
    output_bound: np.ndarray
    default_duration: float
    default_method: str
    design_options: tuple[str, ...] = ("observer", "hedge")
    input_options: tuple[str, ...] = ()
    catalogue_vehicle: str | None = None


def run_mimo(
    scenario: MimoScenario,
    *,
    method: str | None = None,
    failure: str | Failure | None = None,
    duration: float | None = None,
    seed: int = 0,
    dt: float = DEFAULT_DT,
    allocator_knows_failure: bool = False,
    progress: bool = False,
    controller: str = "smc",
    actuators: bool = True,
    noise: bool = True,
    failure_time: float | None = None,
    pilot: str = "standin",
    pilot_gain: float | None = None,
    pilot_delay: float | None = None,
    record_every: int = 10,
    method_options: dict | None = None,
    frame_period: float | None = None,
    rate_aware: bool = True,
    u_prev_source: str = "command",
    preferred: str = "mid",
    rate_horizon: str = "actuator",
    rate_window: str = "binding",
    anti_windup: str = "auto",
    boundary_layer: str = "frame",
    step_times: list | None = None,
    **options: Any,
) -> SimResult:
    """Fly ``scenario`` with these run options (see :class:`sim.settings.LoopSpec` for their meaning).

    ``controller`` is ``"smc"`` (the seed's observer-based SMC with hedging; its
    design options, e.g. ``observer``, ``hedge``, pass through) or ``"loopshape"``
    (the seed's loop-shaped baseline).  ``pilot`` names a pilot model of
    :mod:`sim.pilot`; ``pilot_gain`` / ``pilot_delay`` override its values.
    """
    unknown = set(options) - set(scenario.design_options) - set(scenario.input_options)
    if unknown:
        known = sorted(scenario.design_options + scenario.input_options)
        raise TypeError(f"{scenario.name}: unknown option(s) {sorted(unknown)}; scenario options: {known}")
    duration = scenario.default_duration if duration is None else float(duration)
    # a failure by the scenario's name, or any sim.model.Failure (e.g. the benchmark's catalogue)
    fail = failure if isinstance(failure, Failure) or failure is None else scenario.failure(failure, failure_time)
    if controller == "smc":
        design: SMCDesign | LoopShapedDesign = scenario.smc_design(
            **{k: v for k, v in options.items() if k in scenario.design_options})
    elif controller == "loopshape":
        design = scenario.loop_shaped_design()
    else:
        raise ValueError(f"controller={controller!r}; expected 'smc' or 'loopshape'")
    method = scenario.default_method if method is None else method
    if method != STATIC:  # the seed's printed matrix takes no options
        method_options = vehicles.method_options(scenario.catalogue_vehicle, method, method_options)
    n = int(round(duration / dt)) + 1
    stick = scenario.pilot(
        pilot_parameters(pilot, scenario.pilot_element, gain=pilot_gain, delay=pilot_delay),
        **{k: v for k, v in options.items() if k in scenario.input_options},
    )
    spec = LoopSpec(
        scenario=scenario.name, vehicle=scenario.vehicle(), references=scenario.references, controller=design,
        commands=scenario.commands(np.arange(n) * dt), pilots=(stick,), failure=fail,
        method=method, method_options=method_options,
        allocator_knows_failure=allocator_knows_failure, actuators=actuators, noise=noise, duration=duration,
        dt=dt, seed=seed, output_bound=scenario.output_bound, record_every=record_every,
        frame_period=frame_period, rate_aware=rate_aware, u_prev_source=u_prev_source, preferred=preferred,
        rate_horizon=rate_horizon, rate_window=rate_window, anti_windup=anti_windup,
        boundary_layer=boundary_layer,
    )
    return simulate(spec, progress=progress, step_times=step_times)


def mimo_scenario(
    scenario: MimoScenario, *, description: str, failures: Mapping[str, str]
) -> Callable[[Callable[..., SimResult]], Scenario]:
    """Register ``run(**options)`` (which calls :func:`run_mimo` on ``scenario``) as ``scenario.name``.

    The registry's default duration and method are the scenario's.  ``run``
    is marked ``accepts_failure_objects``: :func:`run_mimo` takes a
    :class:`sim.model.Failure` as well as a failure name (the benchmark
    catalogue hands its failures over that way).
    """

    def decorate(run: Callable[..., SimResult]) -> Scenario:
        run.accepts_failure_objects = True  # type: ignore[attr-defined]
        return register_scenario(
            scenario.name, description=description, failures=dict(failures),
            default_duration=scenario.default_duration, default_method=scenario.default_method,
        )(run)

    return decorate
