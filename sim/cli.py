"""``alloc sim SCENARIO`` / ``alloc sim --vehicle NAME|FILE``: run a closed-loop scenario, print its
summary, write JSON, CSV and PNG.

``--vehicle`` takes what every ``alloc`` command takes (:func:`alloc.vehicles.get_vehicle`):
a scenario's name, or a catalogue vehicle whose name or alias is a scenario's (``harv`` flies
``harv_latdir``).  Any other vehicle -- a user's file -- is refused in one line naming what is
missing: a file without a ``[model]`` has no plant to fly; a file with one would need the
seed's section 4.3 design applied to it, which the simulator does not do yet.  The
scenario's vehicle's ``[methods.<method>]`` defaults (ICE's daisy groups) reach the allocator
(:func:`sim.scenarios.mimo.run_mimo`).

Registered as the entry point ``sim`` of the group ``alloc.commands`` (``pyproject.toml``).

Exit codes: 0 the run stayed bounded; 1 the run diverged (see :mod:`sim.result`);
2 invalid arguments (one line on stderr, checked before the run where they can be).
Outputs are written only where asked, and never over an existing file unless ``--force``.
"""

from __future__ import annotations

import json
import shlex
from pathlib import Path
from typing import Any, Optional

import typer

from alloc.exceptions import AllocError
from alloc.cli import VEHICLE_HELP, finite, load_vehicle_option, output_file, parse_options
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
#: Longest run (simulated seconds): 90 times the seed's longest; the 2 kHz loop records 200 rows/s.
MAX_DURATION = 3600.0
#: Longest pilot time delay (s), far beyond the seed's 0.2-0.3 s.
MAX_PILOT_DELAY = 10.0


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
    raise typer.Exit()


def scenario_of_vehicle(source: str) -> str:
    """The scenario ``--vehicle source`` flies, or a one-line usage error saying why there is none."""
    if source in scenarios():
        return source
    from alloc import vehicles

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
    raise typer.BadParameter(
        f"vehicle {vehicle.name}: alloc sim flies the seed's scenarios only ({', '.join(scenarios())}); closing the "
        "loop on a vehicle file's [model] (the seed's section 4.3 design) is not built yet", param_hint="--vehicle")


def sim_command(
    scenario: Optional[str] = typer.Argument(None, help=f"scenario name: {', '.join(scenarios())} (see --list); "
                                             "or give --vehicle"),
    vehicle: Optional[str] = typer.Option(None, "--vehicle", metavar="NAME|FILE",
                                          help=f"{VEHICLE_HELP}: flies the scenario of that name (harv: harv_latdir); "
                                          "instead of SCENARIO"),
    method: Optional[str] = typer.Option(
        None, "--method", help="allocation method (see `alloc methods`) or 'static'; default: the scenario's "
        "(the seed's choice: pinv for ice, ganging for the HARV)"),
    option: list[str] = typer.Option(
        [], "--option", "-o", help="method option key=value (value parsed as JSON, else text; see `alloc methods`), "
        "over the vehicle's [methods.<method>] defaults; repeatable"),
    failure: Optional[str] = typer.Option(
        None, "--failure", help="failure name (see --list); default: the scenario's own "
        f"(harv_latdir_failure2: failure2), else none; '{NO_FAILURE}' for a nominal run"),
    failure_time: Optional[float] = typer.Option(
        None, "--failure-time", parser=finite(0.0, unit=" s"),
        help="failure time in seconds, >= 0 and before the end of the run; default: the seed's"),
    duration: Optional[float] = typer.Option(
        None, "--duration", parser=finite(0.0, MAX_DURATION, low_open=True, unit=" s"),
        help=f"simulated seconds, 0 < duration <= {MAX_DURATION:g}; default: the scenario's (ice 40 s)"),
    seed: int = typer.Option(0, "--seed", min=0, max=2**32 - 1, help="noise seed (0 to 2^32 - 1)"),
    noise: Optional[bool] = typer.Option(None, "--noise/--no-noise", help="sensor noise (default: on, seed gains)"),
    controller: Optional[str] = typer.Option(None, "--controller", help="'smc' (default); 'loopshape' (ice, HARV) "
                                             "or 'lqr' (pendulum)"),
    pilot: Optional[str] = typer.Option(None, "--pilot", help="pilot model: 'standin' (default) or 'crossover'"),
    pilot_gain: Optional[float] = typer.Option(None, "--pilot-gain", parser=finite(0.0),
                                               help="override the pilot model's gain (>= 0)"),
    pilot_delay: Optional[float] = typer.Option(
        None, "--pilot-delay", parser=finite(0.0, MAX_PILOT_DELAY, unit=" s"),
        help=f"override the pilot's time delay in seconds (0 to {MAX_PILOT_DELAY:g})"),
    frame_rate: Optional[float] = typer.Option(
        None, "--frame-rate", parser=finite(0.0, low_open=True, unit=" Hz"),
        help="flight-control frame rate in Hz (its period a multiple of the 0.5 ms step); default: 2000, "
             "the integration rate"),
    rate_aware: Optional[bool] = typer.Option(
        None, "--rate-aware/--rate-blind", help="allocator gets u_prev and dt = frame period (seed Eq 1.28; default on)"
    ),
    rate_window: Optional[str] = typer.Option(
        None, "--rate-window", help="Eq 1.28 box: 'binding' (default, only where the answer breaks a rate limit) or 'always'"
    ),
    anti_windup: Optional[str] = typer.Option(
        None, "--anti-windup", help="hold the SMC integral while the allocator falls short: 'auto' (default), 'on', 'off'"
    ),
    boundary_layer: Optional[str] = typer.Option(
        None, "--boundary-layer",
        help="SMC boundary layer at the frame rate: 'frame' (default, eps * max(1, T / 0.5 ms)) or 'fixed' (seed eps)",
    ),
    u_prev: Optional[str] = typer.Option(None, "--u-prev", help="'command' (default, the seed's) or 'position'"),
    preferred: Optional[str] = typer.Option(
        None, "--preferred", help="one-sided effectors' preferred position: 'mid' (default) or 'zero' (seed up = 0)"
    ),
    told: bool = typer.Option(
        False, "--told/--blind", "--allocator-knows-failure",
        help="tell the allocator the failed effectors' new limits (default: blind)",
    ),
    json_path: Optional[Path] = typer.Option(None, "--json", help="write the JSON summary to this new file"),
    csv_path: Optional[Path] = typer.Option(None, "--csv", help="write the time histories to this new file (CSV)"),
    parquet_path: Optional[Path] = typer.Option(
        None, "--parquet", help="write the time histories to this new file (Parquet, full precision; needs pyarrow)"
    ),
    plot_path: Optional[Path] = typer.Option(None, "--plot", help="write a PNG plot to this new file"),
    force: bool = typer.Option(False, "--force", help="overwrite output files that exist"),
    list_: bool = typer.Option(False, "--list", callback=list_scenarios, is_eager=True, expose_value=False,
                               help="list the scenarios, their defaults and failures, and exit"),
) -> None:
    """Run SCENARIO in closed loop and print its JSON summary (exit 1 if it diverged).

    Units: seconds; effector positions in degrees; outputs in the seed's units.

    A vehicle file (--vehicle FILE) is refused in one line: the closed loop flies the seed's scenarios only.

    Nothing is written unless asked (--json, --csv, --parquet, --plot); an existing file is refused unless --force.

    Invalid arguments: exit 2 and one line on stderr.
    """
    if (scenario is None) == (vehicle is None):
        raise typer.BadParameter("give a SCENARIO or --vehicle NAME|FILE (one of them)", param_hint="SCENARIO/--vehicle")
    scenario = scenario_of_vehicle(vehicle) if vehicle is not None else scenario
    try:
        run = get_scenario(scenario)
    except KeyError as exc:
        raise typer.BadParameter(str(exc.args[0]), param_hint="SCENARIO") from None
    if failure is None:
        failure = run.default_failure
    elif failure == NO_FAILURE:
        failure = None
    elif failure not in run.failures:
        known = sorted(run.failures) + [NO_FAILURE]
        raise typer.BadParameter(f"unknown failure {failure!r} for {scenario}; known: {known}", param_hint="--failure")
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
    kwargs: dict[str, Any] = dict(failure=failure, duration=duration, seed=seed, allocator_knows_failure=told)
    if option:
        kwargs["method_options"] = parse_options(option)
    optional = dict(
        method=method, failure_time=failure_time, noise=noise, controller=controller, pilot=pilot,
        pilot_gain=pilot_gain, pilot_delay=pilot_delay, rate_aware=rate_aware, u_prev_source=u_prev,
        preferred=preferred, frame_period=None if frame_rate is None else 1.0 / frame_rate,
        boundary_layer=boundary_layer, rate_window=rate_window, anti_windup=anti_windup,
    )
    kwargs.update({k: v for k, v in optional.items() if v is not None})
    try:
        result = run(progress=simulated > PROGRESS_AFTER, **kwargs)
    except AllocError as exc:  # the method and its options (the vehicle's defaults among them)
        raise typer.BadParameter(str(exc), param_hint="--method") from None
    except TypeError as exc:
        raise typer.BadParameter(f"scenario {scenario!r} does not take this option: {exc}") from None
    except (ValueError, KeyError) as exc:
        raise typer.BadParameter(str(exc.args[0] if isinstance(exc, KeyError) and exc.args else exc)) from None
    if failure is not None and not result.diverged and (result.failure_time is None
                                                         or result.failure_time >= result.duration):
        at = "" if result.failure_time is None else f" at t = {result.failure_time:g} s"
        raise typer.BadParameter(f"the run ended at t = {result.duration:g} s, before the failure{at}: nothing was "
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


def command_line(scenario: str, **options: Any) -> str:
    """The ``alloc sim`` command that reproduces a run with these scenario options (for tables)."""
    flags = {"method": "--method", "failure": "--failure", "failure_time": "--failure-time",
             "duration": "--duration", "seed": "--seed", "controller": "--controller", "pilot": "--pilot",
             "pilot_gain": "--pilot-gain", "pilot_delay": "--pilot-delay", "u_prev_source": "--u-prev",
             "preferred": "--preferred",
             "boundary_layer": "--boundary-layer", "rate_window": "--rate-window", "anti_windup": "--anti-windup"}
    words = ["alloc", "sim", scenario]
    if "failure" in options and options["failure"] is None and get_scenario(scenario).default_failure is not None:
        options = {**options, "failure": NO_FAILURE}  # nominal, where the scenario's default injects one
    for key, value in options.items():
        if value is None:
            continue
        if key in flags:
            words += [flags[key], str(value)]
        elif key == "noise":
            words.append("--noise" if value else "--no-noise")
        elif key == "rate_aware":
            words.append("--rate-aware" if value else "--rate-blind")
        elif key == "allocator_knows_failure":
            words.append("--told" if value else "--blind")
        elif key == "frame_period":
            words += ["--frame-rate", f"{1.0 / value:g}"]
        else:
            raise TypeError(f"command_line: no flag for option {key!r}")
    return shlex.join(words)
