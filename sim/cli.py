"""``alloc sim SCENARIO`` / ``alloc sim --vehicle NAME|FILE``: run a closed-loop scenario, print its
summary, write JSON, CSV and PNG.

``--failure`` takes a scenario's own failures by name (ICE ``seed``, HARV ``failure1``), the
failure catalogue's names where the scenario has one (``jam1``, ``effectiveness2``:
:mod:`sim.failure_catalogue`, what the comparison sweep flies) and any text of the library's
failure grammar naming the vehicle's effectors (``jam:elevon_l@5+float:lef_l``,
:mod:`alloc.failure_grammar`); ``--list`` shows each scenario's.  The classic scenarios
(pendulum, F-16, DC-8) have no allocator and no effector to fail: their own failures only.

``--vehicle`` takes what every ``alloc`` command takes (:func:`alloc.vehicles.get_vehicle`):
a scenario's name, or a catalogue vehicle whose name or alias is a scenario's (``harv`` flies
``harv_latdir``).  Any other vehicle -- a user's file -- with a ``[model]`` flies that model
with the seed's section 4.3 design applied to it (:class:`sim.user_vehicle.VehicleScenario`;
``--design key=value`` overrides a choice); a file
without one is refused in one line (no plant to fly).  The scenario's vehicle's ``[methods.<method>]`` defaults (ICE's daisy groups) reach the allocator
(:func:`sim.scenarios.mimo.run_mimo`).

``--plant rotorpy`` flies a multirotor vehicle file with a ``[body]`` on RotorPy's nonlinear physics
instead of its linear model (:mod:`sim.plants`); ``--plant jsbsim:f22`` flies JSBSim's F-22 (its own
vehicle file unless ``--vehicle`` names one); ``--plant linear`` is the default, recorded.

Registered as the entry point ``sim`` of the group ``alloc.commands`` (``pyproject.toml``).

Exit codes: 0 the run stayed bounded; 1 the run diverged (see :mod:`sim.result`);
2 invalid arguments (one line on stderr, checked before the run where they can be).
Outputs are written only where asked, and never over an existing file unless ``--force``.
"""

from __future__ import annotations

import json
import shlex
from dataclasses import fields
from pathlib import Path
from typing import Any

import typer

from alloc.exceptions import AllocError
from alloc.failure_grammar import GRAMMAR as FAILURE_GRAMMAR
from alloc.cli import VEHICLE_HELP, load_vehicle_option, output_file, parse_options
from sim.cli_settings import flag_of, setting_words, with_setting_options
from sim.settings import RunSettings
from sim.scenarios import get_scenario, scenarios

__all__ = ["sim_command", "EXIT_DIVERGED", "NO_FAILURE"]

#: Runs longer than this many simulated seconds show a progress bar.
PROGRESS_AFTER = 2.0
#: Exit code of a diverged run.
EXIT_DIVERGED = 1
#: Exit code of invalid arguments (typer's usage error).
EXIT_USAGE = 2
#: ``--failure`` value of a nominal run, for scenarios that inject a failure by default.
NO_FAILURE = "none"


def list_scenarios(value: bool) -> None:
    """``--list``: every scenario with its defaults and failures, then exit."""
    if not value:
        return
    for name in scenarios():
        run = get_scenario(name)
        typer.echo(f"{name}: {run.description}")
        typer.echo(f"  default duration {run.default_duration:g} s, method {run.default_method or '(no allocator)'}, "
                   f"failure {run.default_failure or NO_FAILURE}")
        for failure, text in run.failures.items():
            typer.echo(f"  --failure {failure}: {text}")
        for failure, text in (run.catalogue() if hasattr(run, "catalogue") else {}).items():
            typer.echo(f"  --failure {failure}: catalogue, {text}")
        if hasattr(run, "check_failure"):
            typer.echo(f"  --failure {FAILURE_GRAMMAR}")
    raise typer.Exit()


def check_failure(run: Any, scenario: str, failure: str) -> None:
    """A one-line usage error naming ``--failure`` unless ``run`` takes ``failure``: its own failures,
    its catalogue names and the failure grammar where it has effectors to fail (``check_failure``)."""
    if hasattr(run, "check_failure"):
        try:
            run.check_failure(failure)
        except AllocError as exc:
            raise typer.BadParameter(f"unknown failure {failure!r} for {scenario}: {exc}; or {NO_FAILURE}",
                                     param_hint="--failure") from None
    elif failure not in run.failures:  # a classic scenario (no effector to fail), harv_latdir_failure2 (Fig 4-81)
        known = [*run.failures, NO_FAILURE]
        raise typer.BadParameter(f"unknown failure {failure!r} for {scenario}: it takes its own failures only; "
                                 f"known: {known}", param_hint="--failure")


def scenario_of_vehicle(source: str) -> Any:
    """What ``--vehicle source`` flies: a scenario's name, or a vehicle file's
    :class:`sim.user_vehicle.VehicleScenario`; a one-line usage error when there is nothing to fly."""
    if source in scenarios():
        return source
    from alloc import vehicles
    from sim.user_vehicle import VehicleScenario

    vehicle = load_vehicle_option(source)
    try:
        entry = vehicles.lookup(source)  # a catalogue name wins over a file of that name, as in get_vehicle
    except AllocError:  # a file
        entry = None
    if entry is not None:
        flown = [n for n in (entry.name, *entry.aliases) if n in scenarios()]
        if flown:
            return flown[0]
    if vehicle.model is None:
        raise typer.BadParameter(
            f"vehicle {vehicle.name}: no [model] section; alloc sim needs a linear model (the [model] table of the "
            "vehicle format: states, outputs, A, B, C, D, controlled; see alloc/vehicle_file.py)", param_hint="--vehicle")
    return VehicleScenario(vehicle)


@with_setting_options
def sim_command(
    scenario: str | None = typer.Argument(None, help=f"scenario name: {', '.join(scenarios())} (see --list); "
                                             "or give --vehicle"),
    vehicle: str | None = typer.Option(None, "--vehicle", metavar="NAME|FILE",
                                          help=f"{VEHICLE_HELP}: flies the scenario of that name (harv: harv_latdir); "
                                          "instead of SCENARIO"),
    design: list[str] = typer.Option(
        [], "--design", help="vehicle file only: override a choice of the seed's section 4.3 design, key=value "
        "(see sim/autodesign.py DESIGN_OPTIONS; the JSON summary's settings.design reports every choice); repeatable"),
    json_path: Path | None = typer.Option(None, "--json", help="write the JSON summary to this new file"),
    csv_path: Path | None = typer.Option(None, "--csv", help="write the time histories to this new file (CSV)"),
    parquet_path: Path | None = typer.Option(
        None, "--parquet", help="write the time histories to this new file (Parquet, full precision; needs pyarrow)"
    ),
    plot_path: Path | None = typer.Option(None, "--plot", help="write a PNG plot to this new file"),
    plant: str | None = typer.Option(
        None, "--plant", metavar="NAME", help="the plant flown: linear (default: the vehicle's linear model in the "
        "compiled engine), rotorpy (RotorPy's nonlinear multirotor, a vehicle file with [body]) or jsbsim:f22 "
        "(JSBSim's F-22; no --vehicle needed); sim/plants"),
    forward_speed: float | None = typer.Option(
        None, "--forward-speed", metavar="M/S", help="--plant rotorpy only: ground speed due north held by the "
        "cascade's velocity loop, reached from the hover on a 1 m/s^2 ramp (0: hold the hover's zero speed); "
        "default: no velocity loop (a level hover that drifts)"),
    schedule: list[str] = typer.Option(
        [], "--schedule", metavar="NAME=START:END", help="a scheduled vehicle file's variable moving linearly from "
        "START at t = 0 to END at the run's end (tilt=0:45); the linear plant and the allocator follow B(x) "
        "(sim/plants/scheduled.py); repeatable"),
    schedule_allocator: str = typer.Option(
        "follow", "--schedule-allocator", help="with --schedule: the allocator rebuilt on B(x) every frame (follow) "
        "or kept at the nominal B (frozen)"),
    force: bool = typer.Option(False, "--force", help="overwrite output files that exist"),
    list_: bool = typer.Option(False, "--list", callback=list_scenarios, is_eager=True, expose_value=False,
                               help="list the scenarios, their defaults and failures, and exit"),
    settings: dict[str, Any] | None = None,
) -> None:
    """Run SCENARIO in closed loop and print its JSON summary (exit 1 if it diverged).

    Units: seconds; effector positions in degrees; outputs in the seed's units.

    A vehicle file with a [model] (--vehicle FILE) flies the seed's section 4.3 design of its model (units: the file's).

    Nothing is written unless asked (--json, --csv, --parquet, --plot); an existing file is refused unless --force.

    Invalid arguments: exit 2 and one line on stderr.

    The run settings' options (--method ... --record-every) are those of sim.settings.RunSettings.
    """
    settings = dict(settings or {})
    failure, duration, failure_time = (settings.get(k) for k in ("failure", "duration", "failure_time"))
    spec = None if plant is None else _plant_spec(plant)
    if scenario is None and vehicle is None and spec is not None and spec.own_vehicle is not None:
        vehicle = spec.own_vehicle()  # a third-party aircraft flies its own linearisation's design
    if (scenario is None) == (vehicle is None):
        raise typer.BadParameter("give a SCENARIO or --vehicle NAME|FILE (one of them)", param_hint="SCENARIO/--vehicle")
    flown = scenario_of_vehicle(vehicle) if vehicle is not None else scenario
    if isinstance(flown, str):
        scenario = flown
        try:
            run = get_scenario(scenario)
        except KeyError as exc:
            raise typer.BadParameter(str(exc.args[0]), param_hint="SCENARIO") from None
    else:  # a vehicle file's model, the seed's section 4.3 design (sim.user_vehicle)
        run, scenario = flown, flown.name
    if forward_speed is not None and (spec is None or not spec.velocity_loop):
        raise typer.BadParameter(f"--plant {plant or 'linear'} flies no velocity loop (a plant with one: --plant "
                                 "rotorpy)", param_hint="--forward-speed")
    runner = run if plant is None else _plant_run(plant, flown, scenario, run, forward_speed)
    if schedule:
        runner = _schedule_run(schedule, schedule_allocator, plant, flown, scenario)
    if design and isinstance(flown, str):
        raise typer.BadParameter(f"{scenario} flies the seed's own design; --design is for a vehicle file's "
                                 "auto-design", param_hint="--design")
    if "failure" not in settings:
        failure = run.default_failure
    elif failure == NO_FAILURE:
        failure = None
    else:
        check_failure(run, scenario, failure)
    simulated = run.default_duration if duration is None else duration
    if failure_time is not None:
        if failure is None:
            raise typer.BadParameter(f"{scenario} injects no failure in this run; name one with --failure",
                                     param_hint="--failure-time")
        if failure_time >= simulated:
            raise typer.BadParameter(f"{failure_time:g} s is not before the end of the run ({simulated:g} s): "
                                     "the failure would never happen", param_hint="--failure-time")
    taken: dict[Path, str] = {}
    for path, hint in ((json_path, "--json"), (csv_path, "--csv"), (parquet_path, "--parquet"), (plot_path, "--plot")):
        output_file(path, force, hint, taken=taken)
    kwargs: dict[str, Any] = {**settings, "failure": failure}
    if design:
        kwargs["design"] = parse_options(design)
    try:
        result = runner(progress=simulated > PROGRESS_AFTER, **kwargs)
    except AllocError as exc:  # a setting (sim.settings.SettingError), the method and its options
        hint = flag_of(exc.field) if exc.field in _SETTING_NAMES else "--method"
        if plant not in (None, "linear") and exc.field not in _SETTING_NAMES:  # what the plant cannot fly
            hint = "--forward-speed" if exc.field == "forward_speed" else "--plant"
        raise typer.BadParameter(str(exc), param_hint=hint) from None
    except TypeError as exc:
        raise typer.BadParameter(f"scenario {scenario!r} does not take this option: {exc}") from None
    except (ValueError, KeyError) as exc:
        raise typer.BadParameter(str(exc.args[0] if isinstance(exc, KeyError) and exc.args else exc)) from None
    # against the run's end, not its last recorded sample (--record-every N records every N-th step)
    if failure is not None and not result.diverged and (result.failure_time is None
                                                         or result.failure_time >= simulated):
        at = "" if result.failure_time is None else f" at t = {result.failure_time:g} s"
        raise typer.BadParameter(f"the run ended at t = {simulated:g} s, before the failure{at}: nothing was "
                                 "injected; pass a longer --duration or an earlier --failure-time",
                                 param_hint="--duration")
    summary = result.summary()
    typer.echo(json.dumps(summary, indent=2))
    if json_path is not None:
        result.to_json(json_path)
    if csv_path is not None:
        result.to_csv(csv_path)
    if parquet_path is not None:
        result.to_parquet(parquet_path)
    if plot_path is not None:
        from sim.plots import plot_result

        plot_result(result, plot_path)
    if result.diverged:
        typer.echo(f"diverged at t = {result.duration:.3f} s", err=True)
        raise typer.Exit(EXIT_DIVERGED)


def _schedule_run(schedule: list[str], allocator: str, plant: str | None, flown: Any, scenario: str) -> Any:
    """The runner of ``--schedule`` (:func:`sim.plants.scheduled.fly_scheduled`); usage errors name the flag."""
    from sim.plants.scheduled import ALLOCATOR_MODES, fly_scheduled, parse_schedule

    if plant is not None and not _plant_spec(plant).follows_schedule:
        raise typer.BadParameter(f"--plant {plant} does not follow a schedule; the linear plant does",
                                 param_hint="--schedule")
    if isinstance(flown, str):
        raise typer.BadParameter(f"{scenario} flies its own model; --schedule moves a vehicle file's [schedule]",
                                 param_hint="--schedule")
    if allocator not in ALLOCATOR_MODES:
        raise typer.BadParameter(f"{allocator!r}; expected one of {', '.join(ALLOCATOR_MODES)}",
                                 param_hint="--schedule-allocator")
    try:
        parse_schedule(schedule, flown.vehicle)  # checked before the run
    except AllocError as exc:
        raise typer.BadParameter(str(exc), param_hint="--schedule") from None

    def scheduled(progress: bool = False, **options: Any) -> Any:
        return fly_scheduled(flown.vehicle, schedule, allocator=allocator, progress=progress, **options)

    return scheduled


def _plant_spec(plant: str) -> Any:
    """The registered plant ``--plant`` names (:func:`sim.plants.plant_spec`); a one-line usage error
    naming ``--plant`` and the plants otherwise."""
    from sim.plants import plant_spec

    try:
        return plant_spec(plant)
    except AllocError as exc:
        raise typer.BadParameter(str(exc), param_hint="--plant") from None


def _plant_run(plant: str, flown: Any, scenario: str, run: Any, forward_speed: float | None = None) -> Any:
    """The runner of ``--plant``: the scenario's own for ``linear`` (its result records the plant), else
    :func:`sim.plants.fly_on_plant` on the vehicle file; a one-line usage error naming ``--plant``."""
    from sim.plants import fly_on_plant

    if _plant_spec(plant).flies_scenarios:
        def linear(**options: Any) -> Any:
            result = run(**options)
            result.settings["plant"] = {"name": "linear", "source": "the vehicle's linear model, compiled engine"}
            return result
        return linear
    if isinstance(flown, str):
        raise typer.BadParameter(f"{scenario} flies its linear model (a seed scenario); --plant {plant} flies a "
                                 "multirotor vehicle file with a [body] (--vehicle FILE)", param_hint="--plant")

    def on_plant(progress: bool = False, **options: Any) -> Any:
        speed = {} if forward_speed is None else {"forward_speed": forward_speed}
        return fly_on_plant(flown.vehicle, plant, progress=progress, **speed, **options)

    return on_plant


#: every run setting's name (an error naming one is reported against its option)
_SETTING_NAMES = frozenset(f.name for f in fields(RunSettings))


def command_line(scenario: str, **options: Any) -> str:
    """The ``alloc sim`` command that reproduces a run with these scenario options (for tables)."""
    words = ["alloc", "sim", scenario]
    if "failure" in options and options["failure"] is None and get_scenario(scenario).default_failure is not None:
        options = {**options, "failure": NO_FAILURE}  # nominal, where the scenario's default injects one
    return shlex.join(words + setting_words(options))
