"""The one runner of the MIMO scenarios (ICE, F-18/HARV lon and lat-dir).

A MIMO scenario is data: a :class:`MimoScenario` (vehicle, reference models,
SMC and loop-shaped designs, failures, pilot, direct commands, divergence
bound).  :func:`run_mimo` turns it and the run options into a
:class:`sim.settings.LoopSpec` and flies it.  Adding a scenario is one module that
builds a ``MimoScenario`` and registers a ``run(**options)`` that calls
``run_mimo(SCENARIO, **options)`` with :func:`mimo_scenario`.
"""

from __future__ import annotations

import inspect
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, fields, replace
from typing import Any

import numpy as np

from alloc import vehicles
from sim import criteria, failure_catalogue
from sim.allocation import STATIC
from sim.engine import simulate
from sim.model import TF, Failure, LoopShapedDesign, Pilot, SMCDesign, PlantModel
from sim.pilot import pilot_parameters
from sim.result import SimResult
from sim.scenarios.registry import Scenario, register_scenario
from sim.settings import LoopSpec, RunSettings

__all__ = ["MimoScenario", "run_mimo", "mimo_spec", "mimo_scenario"]


@dataclass(frozen=True)
class MimoScenario:
    """What differs between the MIMO scenarios.

    Attributes
    ----------
    name : str
        Registered scenario name.
    vehicle : callable
        ``() -> PlantModel``.
    references : sequence of TF
        Reference model per channel.
    smc_design : callable
        ``(**design_options) -> SMCDesign``; its keyword names are the scenario's design options.
    loop_shaped_design : callable
        ``() -> LoopShapedDesign`` (the seed's baseline).
    failure : callable
        ``(name, time or None) -> Failure``; ``time`` None means the seed's failure time.
    pilot : callable
        ``(pilot parameters, **input_options) -> Pilot`` for the scenario's pilot channel, or a
        tuple of pilots (the first the one the parameters set; e.g. the ICE alpha pilot option).
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
    failures : mapping
        The failures ``failure`` builds by name -> description (the seed's composite ones).
    catalogue_effectors : tuple of str
        The effectors (by name) of the failure catalogue's ``<kind>1`` (the first) and
        ``<kind>2`` (both) (:mod:`sim.failure_catalogue`); none: no catalogue names.
    failure_time : float or None
        When a catalogue or grammar failure happens unless told (s); None: half the default duration.
    """

    name: str
    vehicle: Callable[[], PlantModel]
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
    failures: Mapping[str, str] = field(default_factory=dict)
    catalogue_effectors: tuple[str, ...] = ()
    failure_time: float | None = None

    def catalogue(self) -> dict[str, str]:
        """Catalogue name -> grammar text on this scenario's vehicle (read when asked: registered kinds count)."""
        return failure_catalogue.catalogue(self.vehicle(), self.catalogue_effectors)

    def resolve_failure(self, name: str, time: float | None) -> Failure:
        """The failure ``name`` names: the scenario's own, a catalogue name or grammar text
        (:func:`sim.failure_catalogue.resolve`); ``time`` None: the failure's own or :attr:`failure_time`."""
        default = 0.5 * self.default_duration if self.failure_time is None else self.failure_time
        return failure_catalogue.resolve(name, time, named=self.failure, own=self.failures, vehicle=self.vehicle(),
                                         catalogued=self.catalogue(), default_time=default)

    def check_failure(self, name: object) -> None:
        """ProblemError (field ``failure``, saying what is taken) unless :meth:`resolve_failure` takes ``name``."""
        if isinstance(name, str) and name in self.failures:
            return  # no vehicle built for the common case
        failure_catalogue.check(name, own=self.failures, vehicle=self.vehicle(), catalogued=self.catalogue())


def run_mimo(
    scenario: MimoScenario,
    *,
    progress: bool = False,
    step_times: list | None = None,
    **options: Any,
) -> SimResult:
    """Fly ``scenario`` with these run options: the :class:`sim.settings.RunSettings` fields
    (the signature lists them; their meaning, defaults and ranges are the fields') plus the
    scenario's design and input options.

    ``controller`` is ``"smc"`` (the seed's observer-based SMC with hedging; its
    design options, e.g. ``observer``, ``hedge``, pass through) or ``"loopshape"``
    (the seed's loop-shaped baseline).  ``pilot`` names a pilot model of
    :mod:`sim.pilot`; ``pilot_gain`` / ``pilot_delay`` override its values.
    ``result.settings`` records every setting as flown (:meth:`RunSettings.record`: the
    scenario's method, failure time and duration filled in).

    Raises
    ------
    SettingError
        A setting out of its type, choices or range (before anything is built).
    TypeError
        An option that is neither a setting nor one of the scenario's.
    """
    spec, flown = mimo_spec(scenario, **options)
    criteria.use_scenario(scenario)  # its runs are judged by the criteria built from this object
    result = simulate(spec, progress=progress, step_times=step_times)
    world = {"world": result.settings["world"]} if "world" in result.settings else {}  # the drawn world (sim.world)
    result.settings = {**flown.record(), "pilots": result.settings["pilots"], **world}
    return result


def mimo_spec(scenario: MimoScenario, **options: Any) -> tuple[LoopSpec, RunSettings]:
    """The :class:`sim.settings.LoopSpec` :func:`run_mimo` flies for these options, and the settings as flown.

    Raises as :func:`run_mimo` does (before anything is built).
    """
    settings, extra = RunSettings.split(options)
    unknown = set(extra) - set(scenario.design_options) - set(scenario.input_options)
    if unknown:
        known = sorted(scenario.design_options + scenario.input_options)
        raise TypeError(f"{scenario.name}: unknown option(s) {sorted(unknown)}; scenario options: {known}")
    duration = scenario.default_duration if settings.duration is None else settings.duration
    failure = settings.failure
    # a failure by the scenario's name, or any sim.model.Failure (e.g. the benchmark's catalogue)
    fail = failure if isinstance(failure, Failure) or failure is None else scenario.resolve_failure(
        failure, settings.failure_time)
    if settings.controller == "smc":
        design: SMCDesign | LoopShapedDesign = scenario.smc_design(
            **{k: v for k, v in extra.items() if k in scenario.design_options})
    else:
        design = scenario.loop_shaped_design()
    method = scenario.default_method if settings.method is None else settings.method
    method_options = settings.method_options
    if method != STATIC:  # the seed's printed matrix takes no options
        method_options = vehicles.method_options(scenario.catalogue_vehicle, method, method_options)
    flown = replace(settings, method=method, method_options=method_options, duration=duration,
                    failure_time=None if fail is None else fail.time)
    n = int(round(duration / flown.dt)) + 1
    sticks = scenario.pilot(
        pilot_parameters(flown.pilot, scenario.pilot_element, gain=flown.pilot_gain, delay=flown.pilot_delay),
        **{k: v for k, v in extra.items() if k in scenario.input_options},
    )
    spec = LoopSpec(
        scenario=scenario.name, vehicle=scenario.vehicle(), references=scenario.references, controller=design,
        commands=scenario.commands(np.arange(n) * flown.dt),
        pilots=sticks if isinstance(sticks, tuple) else (sticks,), failure=fail, method=method,
        duration=duration, output_bound=scenario.output_bound, **flown.loop_settings(),
    )
    return spec, flown


def _signature() -> inspect.Signature:
    """``run_mimo``'s signature as :func:`inspect.signature` shows it: every setting by name."""
    keyword = inspect.Parameter.KEYWORD_ONLY
    own = inspect.signature(run_mimo).parameters
    settings = [inspect.Parameter(f.name, keyword, default=f.default, annotation=f.type) for f in fields(RunSettings)]
    return inspect.Signature([own["scenario"], *settings, own["progress"], own["step_times"], own["options"]],
                             return_annotation=SimResult)


run_mimo.__signature__ = _signature()  # type: ignore[attr-defined]


def mimo_scenario(
    scenario: MimoScenario, *, description: str, failures: Mapping[str, str] | None = None
) -> Callable[[Callable[..., SimResult]], Scenario]:
    """Register ``run(**options)`` (which calls :func:`run_mimo` on ``scenario``) as ``scenario.name``.

    The registry's default duration and method are the scenario's, its named failures
    ``failures`` (default the scenario's).  ``run`` is marked ``accepts_failure_objects``:
    :func:`run_mimo` takes a :class:`sim.model.Failure` as well as a failure name; and it
    carries ``catalogue()`` (catalogue name -> grammar text) and ``check_failure(name)``, so
    that ``alloc sim`` takes and lists catalogue names and the grammar (:mod:`sim.failure_catalogue`).
    """

    def decorate(run: Callable[..., SimResult]) -> Scenario:
        run.accepts_failure_objects = True  # type: ignore[attr-defined]
        run.catalogue = scenario.catalogue  # type: ignore[attr-defined]
        run.check_failure = scenario.check_failure  # type: ignore[attr-defined]
        criteria.use_scenario(scenario)  # its criteria table exists before any run (docs, sweeps)
        return register_scenario(
            scenario.name, description=description, failures=dict(scenario.failures if failures is None else failures),
            default_duration=scenario.default_duration, default_method=scenario.default_method,
        )(run)

    return decorate
