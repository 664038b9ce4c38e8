"""``alloc sim SCENARIO``: run a closed-loop scenario, print its summary, write JSON, CSV and PNG.

Registered by the lead in ``alloc/cli.py`` with ``app.command("sim")(sim_command)``.

Exit codes: 0 the run stayed bounded; 1 the run diverged (see :mod:`sim.result`);
2 bad arguments (typer's usage error).
"""

from __future__ import annotations

import json
import shlex
from pathlib import Path
from typing import Any, Optional

import typer

from sim.scenarios import get_scenario, scenarios

__all__ = ["sim_command", "EXIT_DIVERGED"]

#: Runs longer than this many simulated seconds show a progress bar.
PROGRESS_AFTER = 2.0
#: Exit code of a diverged run.
EXIT_DIVERGED = 1


def sim_command(
    scenario: str = typer.Argument(..., help=f"scenario name: {', '.join(scenarios())}"),
    method: Optional[str] = typer.Option(None, "--method", help="allocation method (alloc methods) or 'static'"),
    failure: Optional[str] = typer.Option(None, "--failure", help="failure name (see the scenario's failures)"),
    failure_time: Optional[float] = typer.Option(None, "--failure-time", help="failure time (s); default: the seed's"),
    duration: Optional[float] = typer.Option(None, "--duration", help="simulated seconds"),
    seed: int = typer.Option(0, "--seed", help="noise seed"),
    noise: Optional[bool] = typer.Option(None, "--noise/--no-noise", help="sensor noise (default: on, seed gains)"),
    controller: Optional[str] = typer.Option(None, "--controller", help="'smc' (default) or 'loopshape'"),
    pilot: Optional[str] = typer.Option(None, "--pilot", help="pilot model: 'standin' (default) or 'crossover'"),
    pilot_gain: Optional[float] = typer.Option(None, "--pilot-gain", help="override the pilot model's gain"),
    pilot_delay: Optional[float] = typer.Option(None, "--pilot-delay", help="override the pilot's time delay (s)"),
    frame_rate: Optional[float] = typer.Option(
        None, "--frame-rate", help="flight-control frame rate (Hz); default: the 2 kHz integration rate"
    ),
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
    json_path: Optional[Path] = typer.Option(None, "--json", help="write the JSON summary here"),
    csv_path: Optional[Path] = typer.Option(None, "--csv", help="write the time histories here (CSV)"),
    parquet_path: Optional[Path] = typer.Option(
        None, "--parquet", help="write the time histories here (Parquet, full precision; needs pyarrow)"
    ),
    plot_path: Optional[Path] = typer.Option(None, "--plot", help="write a PNG plot here"),
) -> None:
    """Run SCENARIO in closed loop and print its JSON summary (exit 1 if it diverged)."""
    try:
        run = get_scenario(scenario)
    except KeyError as exc:
        raise typer.BadParameter(str(exc.args[0]), param_hint="SCENARIO") from None
    if failure is not None and failure not in run.failures:
        raise typer.BadParameter(f"unknown failure {failure!r}; known: {sorted(run.failures)}", param_hint="--failure")
    if frame_rate is not None and frame_rate <= 0:
        raise typer.BadParameter(f"must be positive, got {frame_rate!r}", param_hint="--frame-rate")
    kwargs: dict[str, Any] = dict(failure=failure, duration=duration, seed=seed, allocator_knows_failure=told)
    optional = dict(
        method=method, failure_time=failure_time, noise=noise, controller=controller, pilot=pilot,
        pilot_gain=pilot_gain, pilot_delay=pilot_delay, rate_aware=rate_aware, u_prev_source=u_prev,
        preferred=preferred, frame_period=None if frame_rate is None else 1.0 / frame_rate,
        boundary_layer=boundary_layer, rate_window=rate_window, anti_windup=anti_windup,
    )
    kwargs.update({k: v for k, v in optional.items() if v is not None})
    simulated = run.default_duration if duration is None else duration
    try:
        result = run(progress=simulated > PROGRESS_AFTER, **kwargs)
    except TypeError as exc:
        raise typer.BadParameter(f"scenario {scenario!r} does not take this option: {exc}") from None
    except (ValueError, KeyError) as exc:
        raise typer.BadParameter(str(exc)) from None
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
