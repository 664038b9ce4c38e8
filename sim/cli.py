"""``alloc sim SCENARIO``: run a closed-loop scenario, print its summary, write JSON and PNG.

Registered by the lead in ``alloc/cli.py`` with ``app.command("sim")(sim_command)``.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Optional

import typer

from sim.scenarios import get_scenario, scenarios

__all__ = ["sim_command"]

#: Runs longer than this many simulated seconds show a progress bar.
PROGRESS_AFTER = 2.0


def sim_command(
    scenario: str = typer.Argument(..., help=f"scenario name: {', '.join(scenarios())}"),
    method: Optional[str] = typer.Option(None, "--method", help="allocation method (alloc methods) or 'static'"),
    failure: Optional[str] = typer.Option(None, "--failure", help="failure name (see the scenario's failures)"),
    duration: Optional[float] = typer.Option(None, "--duration", help="simulated seconds"),
    seed: int = typer.Option(0, "--seed", help="noise seed"),
    json_path: Optional[Path] = typer.Option(None, "--json", help="write the JSON summary here"),
    plot_path: Optional[Path] = typer.Option(None, "--plot", help="write a PNG plot here"),
    allocator_knows_failure: bool = typer.Option(
        False, "--allocator-knows-failure", help="tell the allocator the failed effectors' new limits"
    ),
) -> None:
    """Run SCENARIO in closed loop and print its JSON summary."""
    try:
        run = get_scenario(scenario)
    except KeyError as exc:
        raise typer.BadParameter(str(exc.args[0]), param_hint="SCENARIO") from None
    if failure is not None and failure not in run.failures:
        raise typer.BadParameter(f"unknown failure {failure!r}; known: {sorted(run.failures)}", param_hint="--failure")
    kwargs = dict(failure=failure, duration=duration, seed=seed, allocator_knows_failure=allocator_knows_failure)
    if method is not None:
        kwargs["method"] = method
    simulated = run.default_duration if duration is None else duration
    result = run(progress=simulated > PROGRESS_AFTER, **kwargs)
    summary = result.summary()
    typer.echo(json.dumps(summary, indent=2))
    if json_path is not None:
        result.to_json(json_path)
    if plot_path is not None:
        from sim.plots import plot_result

        plot_result(result, plot_path)
    if result.diverged:
        typer.echo(f"diverged at t = {result.duration:.3f} s", err=True)
