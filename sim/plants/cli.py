"""Command line of the third-party plants: ``python -m sim.plants.cli linearise|fly jsbsim:f22``.

Written as a typer app so that it can be carried by the ``alloc`` command as an entry point of
``alloc.commands`` (``alloc plant linearise jsbsim:f22 --out FILE``, ``alloc plant fly jsbsim:f22``)
without touching :mod:`sim.cli`.  ``fly`` runs :func:`sim.plants.jsbsim_loop.fly` and prints a
JSON summary; a failure is named as on a user's vehicle,
``<kind>:<effector>[@<value>[:<value>]]``, the values filling the kind's parameters in the order
of its row of :data:`alloc.health.FAILURE_KINDS` (positions in degrees from trim).
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import typer

from alloc.exceptions import AllocError

__all__ = ["app", "parse_failure", "PLANTS"]

#: the plants this command knows
PLANTS = ("jsbsim:f22",)
FAILURE_SYNTAX = "<kind>:<effector>[@<value>[:<value>]], e.g. jam:stab_l@0, hardover:stab_r, effectiveness:tvc@0.3"

app = typer.Typer(help="Third-party nonlinear plants (the [plants] extra): linearise one, fly one.",
                  no_args_is_help=True, add_completion=False)


def _plant_name(plant: str) -> str:
    if plant not in PLANTS:
        raise AllocError(f"plant: {plant!r} is not available; plants: {', '.join(PLANTS)}", field="plant")
    return plant


def parse_failure(text: str, effectors: tuple[str, ...]) -> tuple[str, str, dict[str, float]]:
    """``(effector, kind, params)`` of a failure named by :data:`FAILURE_SYNTAX`; AllocError naming ``failure``."""
    from alloc.health import FailureKind

    kind, sep, rest = text.partition(":")
    if not sep or kind not in {k.value for k in FailureKind}:
        raise AllocError(f"failure: {text!r}: expected {FAILURE_SYNTAX}; kinds: "
                         f"{', '.join(k.value for k in FailureKind)}", field="failure")
    effector, at, values = rest.partition("@")
    if effector not in effectors:
        raise AllocError(f"failure: {text!r}: unknown effector {effector!r}; effectors: {', '.join(effectors)}",
                         field="failure")
    names = list(FailureKind(kind).spec.params)
    parts = values.split(":") if at else []
    if len(parts) > len(names):
        raise AllocError(f"failure: {text!r}: {kind} takes {', '.join(names) or 'no value'}", field="failure")
    params: dict[str, float] = {}
    for name, part in zip(names, parts, strict=False):
        try:
            params[name] = float(part)
        except ValueError:
            raise AllocError(f"failure: {text!r}: {name} {part!r} is not a number", field="failure") from None
        if not math.isfinite(params[name]):
            raise AllocError(f"failure: {text!r}: {name} must be finite", field="failure")
    return effector, kind, params


@app.command("linearise")
def linearise_command(plant: str = typer.Argument("jsbsim:f22", help="plant to linearise"),
                      out: Path = typer.Option(..., "--out", help="vehicle file (TOML) to write"),
                      mach: float = typer.Option(0.7, help="trim Mach number"),
                      altitude_ft: float = typer.Option(20000.0, help="trim altitude, ft")) -> None:
    """Trim the plant, measure A and B by finite differences, write the vehicle file."""
    from sim.plants.jsbsim_linear import linearise, write_vehicle
    from sim.plants.jsbsim_model import TrimCondition

    _plant_name(plant)
    path = write_vehicle(linearise(TrimCondition(mach=mach, altitude_ft=altitude_ft)), out)
    typer.echo(f"wrote {path}")


@app.command("fly")
def fly_command(plant: str = typer.Argument("jsbsim:f22", help="plant to fly"),
                duration: float = typer.Option(20.0, help="simulated seconds"),
                method: str = typer.Option("qp", help="allocation method (alloc methods)"),
                failure: str | None = typer.Option(None, help=FAILURE_SYNTAX),
                failure_time: float = typer.Option(5.0, help="s"),
                blind: bool = typer.Option(False, help="do not tell the allocator of the failure")) -> None:
    """Fly the plant in the closed loop (seed section 4.3 SMC on its linearisation) and print a summary."""
    from sim.plants.jsbsim import JSBSimPlant
    from sim.plants.jsbsim_loop import fly

    _plant_name(plant)
    parsed = None if failure is None else parse_failure(failure, JSBSimPlant.effectors)
    f = fly(duration=duration, method=method, failure=parsed, failure_time=failure_time, told=not blind)
    summary: dict[str, Any] = {
        "plant": plant, "method": method, "failure": failure, "told": not blind, "diverged": f.diverged,
        "end_time_s": float(f.t[-1]), "real_time_factor": round(f.real_time_factor, 1),
        "peak_deviation": {n: round(f.peak(n), 4) for n in f.output_names},
        "rms_rate_error_deg_s": {c: round(f.rms_error(c), 4) for c in ("q", "p", "r")},
        "allocator_status": sorted(set(f.status)),
    }
    typer.echo(json.dumps(summary, indent=2))
    if f.diverged:
        raise typer.Exit(code=1)


if __name__ == "__main__":
    app()
